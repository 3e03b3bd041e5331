// The .wxsky parser (osgwxsky::parseSettings) on a stream of inputs, for the fuzz harness
// (tools/fuzz/fuzz_targets.py, target `wxsky-file`): each input on stdin as a 4-byte
// little-endian length then its bytes; for each, one line on stdout: "ok" and the settings,
// or "err" and the parser's one-line message. Ends at the end of its input. Built under the
// sanitizers too (make SANITIZE=1), where any memory or undefined-behaviour error ends it.
#include <osgwxsky/SkyNode>

#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

int main() {
    std::vector<char> buf;
    for (;;) {
        unsigned char len[4];
        if (std::fread(len, 1, 4, stdin) != 4)
            return 0;
        uint32_t n = len[0] | (len[1] << 8) | (len[2] << 16) | ((uint32_t)len[3] << 24);
        if (n > (1u << 20))
            return 2;
        buf.resize(n);
        if (n && std::fread(buf.data(), 1, n, stdin) != n)
            return 2;
        osgwxsky::Settings s;
        std::string error;
        if (osgwxsky::parseSettings(std::string(buf.data(), n), "fuzz.wxsky", s, error)) {
            std::printf("ok frame=%s up_m=%.17g bins=%d,%d mask=%u near_depth=%d control=%zu "
                        "shm=%zu camera=%zu\n",
                        s.frame == osgwxsky::Frame::Enu ? "enu" : "geocentric", s.up_m,
                        s.background_bin, s.near_bin, s.node_mask, s.near_depth ? 1 : 0,
                        s.control.size(), s.shm.size(), s.camera.size());
        } else {
            // one line: a message with a newline in it would break the protocol (and is a bug)
            std::printf("err %zu %s\n", error.size(), error.c_str());
        }
        std::fflush(stdout);
    }
}
