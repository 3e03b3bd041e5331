// The `.wxsky` file: `key = value` lines, `#` comments, every key at most once.
#include <osgwxsky/SkyNode>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace osgwxsky {

namespace {

const char *const KNOWN =
    "control, shm, frame, up_m, camera, background_bin, near_bin, near_depth, node_mask";

std::string trim(const std::string &s) {
    size_t a = s.find_first_not_of(" \t\r");
    if (a == std::string::npos)
        return "";
    size_t b = s.find_last_not_of(" \t\r");
    return s.substr(a, b - a + 1);
}

// A piece of the input quoted in a message: printable ASCII only, at most `max` bytes (a
// message goes to the application's log, and must not carry a terminal's escapes or a newline).
std::string quote(const std::string &v, size_t max) {
    std::string out;
    for (size_t i = 0; i < v.size() && out.size() < max; ++i) {
        unsigned char ch = static_cast<unsigned char>(v[i]);
        out += (ch >= 0x20 && ch < 0x7f) ? static_cast<char>(ch) : '?';
    }
    return out;
}

bool number(const std::string &v, double lo, double hi, double &out) {
    if (v.empty())
        return false;
    char *end = nullptr;
    errno = 0;
    double d = std::strtod(v.c_str(), &end);
    if (errno || *end || !std::isfinite(d) || d < lo || d > hi)
        return false;
    out = d;
    return true;
}

// The shapes the host kit's connect accepts (§2.1); the host part is checked there.
bool address(const std::string &v) {
    if (v.rfind("unix:", 0) == 0)
        return v.size() > 5 && v.size() <= 5 + 107;
    if (v.rfind("tcp:", 0) == 0) {
        size_t colon = v.rfind(':');
        if (colon <= 4 || colon + 1 >= v.size())
            return false;
        double port;
        return number(v.substr(colon + 1), 1, 65535, port) && port == std::floor(port);
    }
    return false;
}

bool shm_name(const std::string &v) {
    std::string n = v[0] == '/' ? v.substr(1) : v;
    if (n.empty() || n.size() > 200)
        return false;
    for (char ch : n)
        if (!(std::isalnum(static_cast<unsigned char>(ch)) || ch == '-' || ch == '_' || ch == '.'))
            return false;
    return true;
}

} // namespace

bool parseSettings(const std::string &text, const std::string &file, Settings &out,
                   std::string &error) {
    Settings s;
    s.file = file;
    std::istringstream in(text);
    std::string line, seen = ",";
    int n = 0;
    auto bad = [&](const std::string &what) {
        error = file + ":" + std::to_string(n) + ": " + what;
        return false;
    };
    while (std::getline(in, line)) {
        ++n;
        size_t hash = line.find('#');
        if (hash != std::string::npos)
            line = line.substr(0, hash);
        line = trim(line);
        if (line.empty())
            continue;
        size_t eq = line.find('=');
        if (eq == std::string::npos)
            return bad("'" + quote(line, 60) + "' is not 'key = value'");
        std::string key = trim(line.substr(0, eq)), v = trim(line.substr(eq + 1));
        if (seen.find("," + key + ",") != std::string::npos)
            return bad("key '" + quote(key, 60) + "' is given twice");
        seen += key + ",";
        double d;
        if (key == "control") {
            if (!address(v))
                return bad("control '" + quote(v, 120) +
                           "' is not an address: unix:PATH or tcp:HOST:PORT (protocol section 2.1)");
            s.control = v;
        } else if (key == "shm") {
            if (v.empty() || !shm_name(v))
                return bad("shm '" + quote(v, 120) +
                           "' is not a segment name (letters, digits, - _ .)");
            s.shm = v;
        } else if (key == "frame") {
            if (v == "enu")
                s.frame = Frame::Enu;
            else if (v == "geocentric")
                s.frame = Frame::Geocentric;
            else
                return bad("frame '" + quote(v, 60) + "' is not enu or geocentric");
        } else if (key == "up_m") {
            if (!number(v, -1000.0, 100000.0, d))
                return bad("up_m '" + quote(v, 60) + "' is not a number -1000..100000");
            s.up_m = d;
        } else if (key == "camera") {
            s.camera = v;
        } else if (key == "background_bin" || key == "near_bin") {
            if (!number(v, -1000, 1000, d) || d != std::floor(d))
                return bad(quote(key, 60) + " '" + quote(v, 60) + "' is not an integer -1000..1000");
            (key == "near_bin" ? s.near_bin : s.background_bin) = static_cast<int>(d);
        } else if (key == "node_mask") {
            char *end = nullptr;
            errno = 0;
            unsigned long m = v.empty() ? 0 : std::strtoul(v.c_str(), &end, 0);
            if (v.empty() || errno || *end || m > 0xffffffffUL || v[0] == '-')
                return bad("node_mask '" + quote(v, 60) +
                           "' is not a 32-bit mask (decimal, or hex as 0x800)");
            s.node_mask = static_cast<unsigned>(m);
        } else if (key == "near_depth") {
            if (v == "true" || v == "on" || v == "1")
                s.near_depth = true;
            else if (v == "false" || v == "off" || v == "0")
                s.near_depth = false;
            else
                return bad("near_depth '" + quote(v, 60) + "' is not true or false");
        } else {
            return bad("unknown key '" + quote(key, 60) + "' (known: " + KNOWN + ")");
        }
    }
    out = s;
    error.clear();
    return true;
}

} // namespace osgwxsky
