#include "link.h"

#include <osg/Notify>

#include <poll.h>
#include <time.h>

#include <chrono>
#include <cmath>
#include <cstring>

namespace osgwxsky {

namespace {

const double RETRY_S = 1.0;  // between connection attempts while the daemon is away
const int CALL_MS = 2000;    // a blocking call on the link's own thread (scene, subscribe)
const double RESEND_S = 1.0; // the camera again at least this often: a restarted daemon

double now_s() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

std::string str(const char *p, uint32_t n) { return std::string(p, n); }

// The value of `key` in a msgpack map, the reader left on it; false when absent.
bool find(wxsky_mp_reader &r, const char *key) {
    uint32_t n;
    return wxsky_mp_read_map(&r, &n) == WXSKY_OK && wxsky_mp_find_key(&r, n, key) == WXSKY_OK;
}

} // namespace

Link::Link(const Settings &settings) : settings_(settings) {
    client_ = wxsky_client_new(1u << 20, 16); // `frame` notifications and small answers
    if (!client_) {
        fail("out of memory for the client");
        return;
    }
    thread_ = std::thread([this] { run(); });
}

Link::~Link() { stop(); }

void Link::stop() {
    {
        std::lock_guard<std::mutex> g(lock_);
        if (stopped_)
            return;
        stop_ = stopped_ = true;
    }
    wake_.notify_all();
    if (thread_.joinable())
        thread_.join();
    wxsky_client_free(client_);
    client_ = nullptr;
}

namespace {
bool same(const Camera &a, const Camera &b) {
    return a.geodetic == b.geodetic && a.width == b.width && a.height == b.height &&
           a.heading_deg == b.heading_deg && a.pitch_deg == b.pitch_deg &&
           a.roll_deg == b.roll_deg && a.fov_deg == b.fov_deg &&
           (a.geodetic ? a.lat_deg == b.lat_deg && a.lon_deg == b.lon_deg && a.alt_m == b.alt_m
                       : a.position_m[0] == b.position_m[0] && a.position_m[1] == b.position_m[1] &&
                             a.position_m[2] == b.position_m[2]);
}
} // namespace

void Link::post(const Camera &camera) {
    std::lock_guard<std::mutex> g(lock_);
    if (has_pending_ && same(camera, pending_))
        return; // a camera standing still is sent once (and again each RESEND_S)
    pending_ = camera;
    has_pending_ = true;
    ++pending_serial_;
}

LinkView Link::view() const {
    std::lock_guard<std::mutex> g(lock_);
    return view_;
}

Link::NearKind Link::nearDistance(uint64_t frame, double &out) const {
    std::lock_guard<std::mutex> g(lock_);
    const Near *newest = nullptr;
    for (const Near &n : near_) {
        if (!n.known)
            continue;
        if (n.frame == frame) {
            newest = &n;
            break;
        }
        if (!newest || n.frame > newest->frame)
            newest = &n;
    }
    if (!newest)
        return NEAR_UNKNOWN;
    out = newest->distance_m;
    return newest->distance_m >= 0.0 ? NEAR_AT : NEAR_EMPTY;
}

void Link::note(const std::string &problem) { fail(problem); }

void Link::fail(const std::string &problem) {
    std::lock_guard<std::mutex> g(lock_);
    view_.error = problem;
    if (problem != logged_) { // each distinct problem once, not every retry
        logged_ = problem;
        OSG_WARN << "wxsky: " << (settings_.file.empty() ? "SkyNode" : settings_.file) << ": "
                 << problem << std::endl;
    }
}

void Link::wait(double seconds) {
    std::unique_lock<std::mutex> g(lock_);
    wake_.wait_for(g, std::chrono::duration<double>(seconds), [this] { return stop_; });
}

void Link::run() {
    for (;;) {
        {
            std::lock_guard<std::mutex> g(lock_);
            if (stop_)
                break;
        }
        if (wxsky_client_fd(client_) < 0) {
            if (!connect()) {
                wait(RETRY_S);
                continue;
            }
        }
        pump();
    }
    wxsky_client_close(client_);
}

bool Link::connect() {
    const char *address = settings_.control.empty() ? nullptr : settings_.control.c_str();
    int st = wxsky_client_connect(client_, address);
    if (st != WXSKY_OK) {
        fail(std::string("control ") + (address ? address : "(default address)") + ": " +
             wxsky_status_name(st) + ": " + wxsky_client_error(client_));
        return false;
    }
    const char *topics[] = {"frame"};
    uint32_t msgid;
    wxsky_message res;
    if ((st = wxsky_subscribe(client_, topics, 1, &msgid)) != WXSKY_OK ||
        (st = wxsky_client_wait(client_, msgid, CALL_MS, &res)) != WXSKY_OK) {
        fail(std::string("subscribe: ") + wxsky_status_name(st) + ": " +
             wxsky_client_error(client_));
        wxsky_client_close(client_);
        return false;
    }
    std::string shm = settings_.shm;
    if (shm.empty()) {
        if ((st = wxsky_client_call(client_, "scene", nullptr, 0, CALL_MS, &res)) != WXSKY_OK) {
            fail(std::string("scene: ") + wxsky_status_name(st) + ": " +
                 wxsky_client_error(client_));
            wxsky_client_close(client_);
            return false;
        }
        wxsky_mp_reader r;
        const char *p;
        uint32_t n;
        wxsky_mp_reader_init(&r, res.body, res.body_len);
        if (!find(r, "shm_name") || wxsky_mp_read_str(&r, &p, &n) != WXSKY_OK) {
            fail("scene: the answer names no shm_name");
            wxsky_client_close(client_);
            return false;
        }
        shm = str(p, n);
    }
    {
        std::lock_guard<std::mutex> g(lock_);
        view_.connected = true;
        view_.shm = shm;
        ++view_.shm_serial;
        view_.error.clear();
        logged_.clear();
    }
    OSG_NOTICE << "wxsky: " << (settings_.file.empty() ? "SkyNode" : settings_.file)
               << ": connected to " << (address ? address : "the default address")
               << ", segment " << shm << std::endl;
    sent_serial_ = 0; // send the camera again: a restarted daemon has its own
    return true;
}

void Link::send_camera() {
    Camera cam;
    uint64_t serial;
    {
        std::lock_guard<std::mutex> g(lock_);
        if (!has_pending_)
            return;
        cam = pending_;
        serial = pending_serial_;
    }
    double t = now_s();
    if (serial == sent_serial_ && t < next_resend_s_)
        return;
    uint8_t buf[512];
    wxsky_mp_writer w;
    wxsky_mp_writer_init(&w, buf, sizeof buf);
    wxsky_mp_write_map(&w, (cam.geodetic ? 7 : 5) + (cam.width ? 2 : 0));
    if (cam.geodetic) {
        wxsky_mp_write_cstr(&w, "lat_deg");
        wxsky_mp_write_double(&w, cam.lat_deg);
        wxsky_mp_write_cstr(&w, "lon_deg");
        wxsky_mp_write_double(&w, cam.lon_deg);
        wxsky_mp_write_cstr(&w, "alt_m");
        wxsky_mp_write_double(&w, cam.alt_m);
    } else {
        wxsky_mp_write_cstr(&w, "position_m");
        wxsky_mp_write_array(&w, 3);
        for (double v : cam.position_m)
            wxsky_mp_write_double(&w, v);
    }
    wxsky_mp_write_cstr(&w, "heading_deg");
    wxsky_mp_write_double(&w, cam.heading_deg);
    wxsky_mp_write_cstr(&w, "pitch_deg");
    wxsky_mp_write_double(&w, cam.pitch_deg);
    wxsky_mp_write_cstr(&w, "roll_deg");
    wxsky_mp_write_double(&w, cam.roll_deg);
    wxsky_mp_write_cstr(&w, "fov_deg");
    wxsky_mp_write_double(&w, cam.fov_deg);
    if (cam.width) {
        wxsky_mp_write_cstr(&w, "width");
        wxsky_mp_write_uint(&w, cam.width);
        wxsky_mp_write_cstr(&w, "height");
        wxsky_mp_write_uint(&w, cam.height);
    }
    if (w.overflow)
        return;
    uint32_t msgid;
    int st = wxsky_client_request(client_, "set_camera", buf, w.len, &msgid);
    if (st == WXSKY_AGAIN)
        return; // the socket is full: the newest camera goes next time
    if (st != WXSKY_OK) {
        fail(std::string("set_camera: ") + wxsky_status_name(st) + ": " +
             wxsky_client_error(client_));
        return;
    }
    sent_serial_ = serial;
    next_resend_s_ = t + RESEND_S;
    sent_[sent_next_++ % sent_.size()] = Sent{msgid, cam.geodetic, cam.lat_deg, cam.lon_deg};
    std::lock_guard<std::mutex> g(lock_);
    ++view_.cameras_sent;
}

void Link::pump() {
    send_camera();
    pollfd p{wxsky_client_fd(client_), POLLIN, 0};
    if (p.fd >= 0)
        ::poll(&p, 1, 5); // a short wait: a new camera goes out within it
    wxsky_message msg;
    int st;
    while ((st = wxsky_client_poll(client_, &msg)) == WXSKY_OK)
        handle(msg);
    if (st != WXSKY_AGAIN) {
        fail(std::string("the daemon's connection ended: ") + wxsky_status_name(st) + ": " +
             wxsky_client_error(client_));
        wxsky_client_close(client_);
        std::lock_guard<std::mutex> g(lock_);
        view_.connected = false;
    }
}

void Link::handle(const wxsky_message &msg) {
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, msg.body, msg.body_len);
    if (msg.kind == WXSKY_NOTIFICATION) {
        if (str(msg.method, msg.method_len) != "frame")
            return;
        uint32_t n;
        uint64_t frame = 0;
        double d = -1.0;
        bool has_near = false;
        if (wxsky_mp_read_map(&r, &n) != WXSKY_OK)
            return;
        for (uint32_t i = 0; i < n; ++i) {
            const char *k;
            uint32_t kl;
            if (wxsky_mp_read_str(&r, &k, &kl) != WXSKY_OK)
                return;
            std::string key(k, kl);
            if (key == "frame_number") {
                if (wxsky_mp_read_uint(&r, &frame) != WXSKY_OK)
                    return;
            } else if (key == "near_distance_m") {
                has_near = true;
                if (wxsky_mp_peek(&r) == WXSKY_MP_NIL)
                    wxsky_mp_read_nil(&r);
                else if (wxsky_mp_read_double(&r, &d) != WXSKY_OK || !(d >= 0.0))
                    return;
            } else if (wxsky_mp_skip(&r) != WXSKY_OK) {
                return;
            }
        }
        if (!has_near)
            return;
        std::lock_guard<std::mutex> g(lock_);
        near_[near_next_++ % near_.size()] = Near{frame, d, true};
        return;
    }
    if (msg.error) {
        fail("the daemon refused a request: " + str(msg.error, msg.error_len));
        return;
    }
    if (!msg.has_msgid)
        return;
    for (const Sent &s : sent_) {
        if (s.msgid != msg.msgid || !s.geodetic || s.msgid == 0)
            continue;
        // set_camera's answer: the daemon's east, north for the sent latitude and longitude
        // give its site (its flat frame, wxsky/weather/geo.py), which the drawing needs.
        uint32_t n;
        double e, no;
        if (!find(r, "position_m") || wxsky_mp_read_array(&r, &n) != WXSKY_OK || n != 3 ||
            wxsky_mp_read_double(&r, &e) != WXSKY_OK || wxsky_mp_read_double(&r, &no) != WXSKY_OK)
            return;
        double lat = s.lat_deg - no / 110540.0;
        double per_lon = 111320.0 * std::max(1e-6, std::cos(lat * M_PI / 180.0));
        double lon = s.lon_deg - e / per_lon;
        std::lock_guard<std::mutex> g(lock_);
        view_.site_valid = true;
        view_.site_lat_deg = lat;
        view_.site_lon_deg = lon;
        return;
    }
}

} // namespace osgwxsky
