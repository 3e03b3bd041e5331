// The node's connection to the daemon, on a thread of its own: connects and reconnects,
// names the segment, sends the latest camera and keeps what the stream says the drawing needs
// (each frame's near_distance_m, the daemon's site). Nothing here touches GL.
#ifndef OSGWXSKY_LINK_H
#define OSGWXSKY_LINK_H

#include <osgwxsky/SkyNode>

#include <array>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "wxsky_host.h"

namespace osgwxsky {

// What the draw thread reads of the link (a copy, taken under the link's lock).
struct LinkView {
    bool connected = false;
    std::string shm;          // the segment to open ("" : not known yet)
    uint64_t shm_serial = 0;  // bumps at each connect: reopen the segment then
    bool site_valid = false;  // the daemon's site, from set_camera's answers (Geocentric)
    double site_lat_deg = 0.0, site_lon_deg = 0.0;
    uint64_t cameras_sent = 0;
    std::string error;        // the last problem ("" : none)
};

class Link {
  public:
    explicit Link(const Settings &settings);
    ~Link();
    Link(const Link &) = delete;
    Link &operator=(const Link &) = delete;

    void stop(); // idempotent: joins the thread, closes the connection
    void post(const Camera &camera); // the camera to send (only the latest is sent)
    LinkView view() const;
    // The near layer's distance for daemon frame `frame` (or the newest known when that one
    // is not): NEAR_UNKNOWN when the stream said none (a daemon before near_distance_m),
    // NEAR_EMPTY when the layer holds nothing, NEAR_AT with `out`.
    enum NearKind { NEAR_UNKNOWN, NEAR_EMPTY, NEAR_AT };
    NearKind nearDistance(uint64_t frame, double &out) const;
    void note(const std::string &problem); // a problem the draw side found, logged once

  private:
    void run();
    bool connect();
    void pump();
    void send_camera();
    void handle(const wxsky_message &msg);
    void fail(const std::string &problem); // logs a problem once, keeps it as the last
    void wait(double seconds);

    Settings settings_;
    wxsky_client *client_ = nullptr;
    std::thread thread_;
    mutable std::mutex lock_;
    std::condition_variable wake_;
    bool stop_ = false;
    bool stopped_ = false;
    // under lock_
    LinkView view_;
    Camera pending_;
    bool has_pending_ = false;
    uint64_t pending_serial_ = 0;
    std::string logged_;
    struct Near {
        uint64_t frame = 0;
        double distance_m = -1.0;
        bool known = false;
    };
    std::array<Near, 32> near_{};
    size_t near_next_ = 0;
    // thread-only
    uint64_t sent_serial_ = 0;
    struct Sent {
        uint32_t msgid = 0;
        bool geodetic = false;
        double lat_deg = 0.0, lon_deg = 0.0;
    };
    std::array<Sent, 16> sent_{};
    size_t sent_next_ = 0;
    double next_resend_s_ = 0.0;
};

} // namespace osgwxsky

#endif
