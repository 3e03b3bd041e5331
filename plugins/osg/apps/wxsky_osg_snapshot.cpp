/* wxsky-osg-snapshot: a scene rendered by OpenSceneGraph with the wxsky plugin, offscreen.
 *
 *   wxsky-osg-snapshot [--control ADDR] [--shm NAME] [--time ISO8601] [--lat DEG --lon DEG]
 *       [--alt-m M] [--heading-deg D] [--pitch-deg D] [--roll-deg D] [--fov-deg D]
 *       [--size WxH] --out FILE.png [--frame enu|geocentric] [--scene FILE] [--sky FILE.wxsky] [--up-m M] [--no-sky]
 *       [--timeout-s S] [--bench N] [--watch-s S]
 *
 * wxsky-host-snapshot's arguments, and the scene: --scene FILE (any model OSG reads; none: an
 * empty scene) in the daemon's frame (x east, y north, z up metres about its site; z = 0 at
 * --up-m above sea level); --frame geocentric puts the camera in earth-centred WGS84 metres at
 * --lat, --lon instead (a whole-earth scene's, FlightGear's) and the node in that frame, with
 * no scene. --roll-deg rolls the camera (right wing down). The daemon's clock is held at --time while the picture is made and
 * its camera put where the arguments say (as wxsky-host-snapshot does: set_camera with
 * lat_deg, lon_deg, alt_m); the OSG camera is then placed there, and the sky node, loaded
 * through osgDB from --sky (default: a .wxsky file made from --control and --shm), sends it
 * and draws. The PNG is taken from the frame drawn once the node's layers are for that camera
 * and the ring has settled. --no-sky renders the scene alone (cleared to transparent black,
 * so the PNG's alpha marks the scene's pixels); --bare-out FILE.png also writes that picture
 * for the very camera of the PNG. --shadows draws the scene with a terrain shader lit
 * through the node's cloud-shadow map (SkyNode::shadowStateSet). --bench N then times N frames with the node
 * and N without (one JSON line each: the host's frame, the draw finished with glFinish).
 * --watch-s S is a host's loop instead: the daemon is not driven (no clock, no camera from
 * this program: the node sends the OSG camera the arguments give, in the scene's frame), the
 * scene drawn for S seconds with a status line of the node every 0.25 s; --out then optional.
 *
 * Headless: a surfaceless EGL context (compatibility profile, as OSG's GL2 build draws) and a
 * framebuffer object OSG draws into (osgViewer's embedded window). The plugin is found in
 * this program's own directory. Prints "camera: {...}" (the camera the node sent) and "wrote
 * FILE (WxH), frame N", with "asked: {...}" before it (the daemon's camera as the arguments
 * set it); otherwise one line "wxsky-osg-snapshot: error: ..." and exit 1 (2: no
 * headless GL context; 64: bad arguments). */
#define GL_GLEXT_PROTOTYPES 1
#include <osgwxsky/SkyNode>

#include <osg/CoordinateSystemNode>
#include <osg/GL>
#include <osg/Program>
#include <osg/Shader>
#include <osgDB/ReadFile>
#include <osgDB/Registry>
#include <osgViewer/Viewer>
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glext.h>

#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "wxsky_host.h"
extern "C" {
#include "png_write.h"
}

#define PROG "wxsky-osg-snapshot"
#define USAGE                                                                                  \
    "usage: " PROG " [--control ADDR] [--shm NAME] [--time ISO8601] [--lat DEG --lon DEG] "    \
    "[--alt-m M] [--heading-deg D] [--pitch-deg D] [--roll-deg D] [--fov-deg D] [--size WxH] "  \
    "--out FILE.png [--frame enu|geocentric] " \
    "[--scene FILE] [--sky FILE.wxsky] [--up-m M] [--no-sky] [--bare-out FILE.png] "           \
    "[--shadows] "                                                                              \
    "[--timeout-s S] [--bench N] "                                                              \
    "[--watch-s S]"

namespace {

struct Args {
    std::string control, shm, time_utc, out, scene, sky, bare_out;
    double lat = 0, lon = 0, alt_m = 0, heading = 0, pitch = 0, roll = 0, fov = 0, up_m = 0;
    double timeout_s = 60;
    bool has_lat = false, has_alt = false, has_heading = false, has_pitch = false, has_fov = false;
    bool has_roll = false, geocentric = false;
    bool no_sky = false, shadows = false;
    int bench = 0;
    double watch_s = 0.0;
    uint32_t width = 0, height = 0;
};

struct Failure {
    int code;
    std::string what;
};

double now_s() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

double number(const char *flag, const char *v, double lo, double hi) {
    char *end = nullptr;
    double d = std::strtod(v, &end);
    if (!*v || *end || !std::isfinite(d) || d < lo || d > hi)
        throw Failure{64, std::string(flag) + " " + v + " is not a number in " +
                              std::to_string(lo) + ".." + std::to_string(hi)};
    return d;
}

Args parse(int argc, char **argv) {
    Args a;
    for (int i = 1; i < argc; ++i) {
        std::string f = argv[i];
        if (f == "--no-sky") {
            a.no_sky = true;
            continue;
        }
        if (f == "--shadows") {
            a.shadows = true;
            continue;
        }
        if (i + 1 >= argc)
            throw Failure{64, f + " needs a value\n" USAGE};
        const char *v = argv[++i];
        if (f == "--control") a.control = v;
        else if (f == "--shm") a.shm = v;
        else if (f == "--time") a.time_utc = v;
        else if (f == "--out") a.out = v;
        else if (f == "--scene") a.scene = v;
        else if (f == "--sky") a.sky = v;
        else if (f == "--bare-out") a.bare_out = v;
        else if (f == "--lat") { a.lat = number(argv[i - 1], v, -90, 90); a.has_lat = true; }
        else if (f == "--lon") { a.lon = number(argv[i - 1], v, -180, 180); }
        else if (f == "--alt-m") { a.alt_m = number(argv[i - 1], v, -500, 100000); a.has_alt = true; }
        else if (f == "--heading-deg") { a.heading = number(argv[i - 1], v, -360, 360); a.has_heading = true; }
        else if (f == "--pitch-deg") { a.pitch = number(argv[i - 1], v, -90, 90); a.has_pitch = true; }
        else if (f == "--fov-deg") { a.fov = number(argv[i - 1], v, 1, 170); a.has_fov = true; }
        else if (f == "--roll-deg") { a.roll = number(argv[i - 1], v, -180, 180); a.has_roll = true; }
        else if (f == "--frame") {
            if (std::strcmp(v, "enu") && std::strcmp(v, "geocentric"))
                throw Failure{64, std::string("--frame ") + v + " is not enu or geocentric"};
            a.geocentric = !std::strcmp(v, "geocentric");
        }
        else if (f == "--up-m") a.up_m = number(argv[i - 1], v, -1000, 100000);
        else if (f == "--timeout-s") a.timeout_s = number(argv[i - 1], v, 0.1, 3600);
        else if (f == "--bench") a.bench = (int)number(argv[i - 1], v, 1, 100000);
        else if (f == "--watch-s") a.watch_s = number(argv[i - 1], v, 0.1, 3600);
        else if (f == "--size") {
            unsigned w = 0, h = 0;
            char x = 0;
            if (std::sscanf(v, "%u%c%u", &w, &x, &h) != 3 || x != 'x' || w < 16 || h < 16 ||
                w > 8192 || h > 8192)
                throw Failure{64, std::string("--size ") + v + " is not WxH, each 16..8192"};
            a.width = w;
            a.height = h;
        } else
            throw Failure{64, "unknown argument " + f + "\n" USAGE};
    }
    bool lon_given = false;
    for (int i = 1; i < argc; ++i)
        lon_given |= !std::strcmp(argv[i], "--lon");
    if (a.out.empty() && a.watch_s <= 0.0)
        throw Failure{64, "--out FILE.png is required\n" USAGE};
    if (a.has_lat != lon_given)
        throw Failure{64, "--lat and --lon go together"};
    if (a.shadows && (a.scene.empty() || a.no_sky))
        throw Failure{64, "--shadows needs --scene and the sky"};
    if (a.geocentric && (!a.has_lat || !a.scene.empty()))
        throw Failure{64, "--frame geocentric needs --lat and --lon, and no --scene (the scene's "
                          "frame is the daemon's flat one)"};
    return a;
}

// ---- the daemon, as wxsky-host-snapshot drives it ------------------------------------------

struct Daemon {
    wxsky_client *c = nullptr;
    int timeout_ms = 60000;
    double rate = 1.0;
    bool frozen = false;
    ~Daemon() {
        if (frozen)
            restart_clock();
        wxsky_client_free(c);
    }
    wxsky_message call(const char *method, const wxsky_mp_writer *w) {
        wxsky_message res;
        int st = wxsky_client_call(c, method, w ? w->buf : nullptr, w ? w->len : 0, timeout_ms, &res);
        if (st != WXSKY_OK)
            throw Failure{1, std::string(method) + ": " + wxsky_status_name(st) + ": " +
                                 wxsky_client_error(c)};
        return res;
    }
    void restart_clock() {
        uint8_t buf[64];
        wxsky_mp_writer w;
        wxsky_mp_writer_init(&w, buf, sizeof buf);
        wxsky_mp_write_map(&w, 1);
        wxsky_mp_write_cstr(&w, "rate");
        wxsky_mp_write_double(&w, rate);
        wxsky_message res;
        wxsky_client_call(c, "set_time", buf, w.len, 2000, &res);
        frozen = false;
    }
    bool ring_busy() {
        wxsky_message res = call("scene", nullptr);
        wxsky_mp_reader r;
        uint32_t n;
        int busy = 1;
        wxsky_mp_reader_init(&r, res.body, res.body_len);
        if (wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "ring_busy") != WXSKY_OK ||
            wxsky_mp_read_bool(&r, &busy) != WXSKY_OK)
            throw Failure{1, "scene: no ring_busy in the answer"};
        return busy != 0;
    }
};

double map_double(const wxsky_message &res, const char *key) {
    wxsky_mp_reader r;
    uint32_t n;
    double v;
    wxsky_mp_reader_init(&r, res.body, res.body_len);
    if (wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, key) != WXSKY_OK ||
        wxsky_mp_read_double(&r, &v) != WXSKY_OK)
        throw Failure{1, std::string("no ") + key + " in the answer"};
    return v;
}

// set_camera's answer: the daemon's camera.
osgwxsky::Camera camera_of(const wxsky_message &res) {
    osgwxsky::Camera c;
    wxsky_mp_reader r;
    uint32_t n;
    wxsky_mp_reader_init(&r, res.body, res.body_len);
    if (wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "position_m") != WXSKY_OK ||
        wxsky_mp_read_array(&r, &n) != WXSKY_OK || n != 3)
        throw Failure{1, "set_camera: no position_m in the answer"};
    for (double &v : c.position_m)
        if (wxsky_mp_read_double(&r, &v) != WXSKY_OK)
            throw Failure{1, "set_camera: position_m is not numbers"};
    c.heading_deg = map_double(res, "heading_deg");
    c.pitch_deg = map_double(res, "pitch_deg");
    c.roll_deg = map_double(res, "roll_deg");
    c.fov_deg = map_double(res, "fov_deg");
    c.width = (uint32_t)map_double(res, "width");
    c.height = (uint32_t)map_double(res, "height");
    return c;
}

// ---- headless GL ---------------------------------------------------------------------------

struct Gl {
    EGLDisplay dpy = EGL_NO_DISPLAY;
    EGLContext ctx = EGL_NO_CONTEXT;
    GLuint fbo = 0, color = 0, depth = 0;
    ~Gl() {
        if (dpy != EGL_NO_DISPLAY) {
            eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
            if (ctx != EGL_NO_CONTEXT)
                eglDestroyContext(dpy, ctx);
            eglTerminate(dpy);
            eglReleaseThread();
        }
    }
    void open(uint32_t w, uint32_t h) {
        auto get_platform = (PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
        if (get_platform)
            dpy = get_platform(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
        if (dpy == EGL_NO_DISPLAY)
            dpy = eglGetDisplay(EGL_DEFAULT_DISPLAY);
        EGLint major, minor, n = 0;
        EGLConfig cfg;
        const EGLint cfg_attr[] = {EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_SURFACE_TYPE, 0, EGL_NONE};
        // compatibility profile: OSG's GL2 build draws with the fixed-function pipeline
        const EGLint ctx_attr[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
                                   EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                   EGL_CONTEXT_OPENGL_COMPATIBILITY_PROFILE_BIT, EGL_NONE};
        if (dpy == EGL_NO_DISPLAY || !eglInitialize(dpy, &major, &minor) || !eglBindAPI(EGL_OPENGL_API) ||
            !eglChooseConfig(dpy, cfg_attr, &cfg, 1, &n) || n < 1 ||
            (ctx = eglCreateContext(dpy, cfg, EGL_NO_CONTEXT, ctx_attr)) == EGL_NO_CONTEXT ||
            !eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx))
            throw Failure{2, "no headless EGL context (compatibility profile 3.3): EGL error 0x" +
                                 std::to_string(eglGetError())};
        glGenFramebuffers(1, &fbo);
        glBindFramebuffer(GL_FRAMEBUFFER, fbo);
        glGenRenderbuffers(1, &color);
        glBindRenderbuffer(GL_RENDERBUFFER, color);
        glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, (GLsizei)w, (GLsizei)h);
        glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, color);
        glGenRenderbuffers(1, &depth);
        glBindRenderbuffer(GL_RENDERBUFFER, depth);
        glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, (GLsizei)w, (GLsizei)h);
        glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth);
        if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
            throw Failure{2, "the offscreen framebuffer is not complete"};
    }
    std::vector<uint8_t> read(uint32_t w, uint32_t h) {
        std::vector<uint8_t> px((size_t)w * h * 4), out(px.size());
        glBindFramebuffer(GL_FRAMEBUFFER, fbo);
        glPixelStorei(GL_PACK_ALIGNMENT, 1);
        glReadPixels(0, 0, (GLsizei)w, (GLsizei)h, GL_RGBA, GL_UNSIGNED_BYTE, px.data());
        for (uint32_t y = 0; y < h; ++y) // GL's rows bottom first; the PNG's top first
            std::memcpy(&out[(size_t)y * w * 4], &px[(size_t)(h - 1 - y) * w * 4], (size_t)w * 4);
        return out;
    }
};

// The view matrix of a camera in the scene's frame (wxsky's less --up-m), as
// wxsky/scene/camera.py makes it; OSG's memory layout is GL's column-major one.
osg::Matrixd view_of(const osgwxsky::Camera &c, double up_m) {
    const double d2r = M_PI / 180.0;
    double h = c.heading_deg * d2r, p = c.pitch_deg * d2r, r = c.roll_deg * d2r;
    osg::Vec3d fwd(std::sin(h) * std::cos(p), std::cos(h) * std::cos(p), std::sin(p));
    osg::Vec3d right0(std::cos(h), -std::sin(h), 0.0);
    osg::Vec3d up0 = right0 ^ fwd;
    osg::Vec3d right = right0 * std::cos(r) - up0 * std::sin(r);
    osg::Vec3d up = up0 * std::cos(r) + right0 * std::sin(r);
    osg::Vec3d eye(c.position_m[0], c.position_m[1], c.position_m[2] - up_m);
    const osg::Vec3d rows[3] = {right, up, -fwd};
    double m[16] = {0};
    for (int row = 0; row < 3; ++row) {
        for (int col = 0; col < 3; ++col)
            m[col * 4 + row] = rows[row][col];
        m[12 + row] = -(rows[row] * eye);
    }
    m[15] = 1.0;
    return osg::Matrixd(m);
}

void print_camera(const osgwxsky::Camera &c, double near_m) {
    std::printf("{\"position_m\": [%.6f, %.6f, %.6f], \"heading_deg\": %.9f, \"pitch_deg\": %.9f, "
                "\"roll_deg\": %.9f, \"fov_deg\": %.9f, \"width\": %u, \"height\": %u, "
                "\"near_distance_m\": %.3f}\n",
                c.position_m[0], c.position_m[1], c.position_m[2], c.heading_deg, c.pitch_deg,
                c.roll_deg, c.fov_deg, c.width, c.height, near_m);
}

// The same camera in earth-centred WGS84 metres, at --lat, --lon and the camera's height.
osg::Matrixd geocentric_view_of(const osgwxsky::Camera &c, double lat_deg, double lon_deg) {
    const double d2r = M_PI / 180.0;
    osg::Matrixd local = view_of(c, 0.0); // rows right, up, -forward in ENU
    osg::EllipsoidModel wgs84;
    double lat = lat_deg * d2r, lon = lon_deg * d2r, x, y, z;
    wgs84.convertLatLongHeightToXYZ(lat, lon, c.position_m[2], x, y, z);
    osg::Vec3d e(-std::sin(lon), std::cos(lon), 0.0);
    osg::Vec3d n(-std::sin(lat) * std::cos(lon), -std::sin(lat) * std::sin(lon), std::cos(lat));
    osg::Vec3d u(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat));
    osg::Vec3d eye(x, y, z);
    const double *m = local.ptr();
    double out[16] = {0};
    for (int row = 0; row < 3; ++row) {
        osg::Vec3d r = e * m[0 * 4 + row] + n * m[1 * 4 + row] + u * m[2 * 4 + row];
        for (int col = 0; col < 3; ++col)
            out[col * 4 + row] = r[col];
        out[12 + row] = -(r * eye);
    }
    out[15] = 1.0;
    return osg::Matrixd(out);
}

// --shadows: the scene drawn by a terrain shader lit through the node's cloud-shadow map
// (SkyNode::shadowStateSet, shadowGlsl): its vertex colour x (0.35 + 0.65 T), T the sun's share
// through the clouds at the fragment, the scene's coordinates plus up_m being the daemon's.
void shade_scene(osg::Node &scene, osgwxsky::SkyNode &sky, double up_m) {
    osg::ref_ptr<osg::Program> prog = new osg::Program;
    prog->addShader(new osg::Shader(osg::Shader::VERTEX,
                                    "#version 130\n"
                                    "uniform float up_m;\n"
                                    "out vec3 world;\n"
                                    "out vec4 colour;\n"
                                    "void main() {\n"
                                    "    world = gl_Vertex.xyz + vec3(0.0, 0.0, up_m);\n"
                                    "    colour = gl_Color;\n"
                                    "    gl_Position = ftransform();\n"
                                    "}\n"));
    prog->addShader(new osg::Shader(osg::Shader::FRAGMENT,
                                    std::string("#version 130\n") + osgwxsky::SkyNode::shadowGlsl() +
                                        "in vec3 world;\n"
                                        "in vec4 colour;\n"
                                        "void main() {\n"
                                        "    float t = wxsky_shadow(world);\n"
                                        "    gl_FragColor = vec4(colour.rgb * (0.35 + 0.65 * t), colour.a);\n"
                                        "}\n"));
    osg::StateSet *ss = scene.getOrCreateStateSet();
    ss->merge(*sky.shadowStateSet());
    ss->setAttributeAndModes(prog.get());
    ss->addUniform(new osg::Uniform("up_m", static_cast<float>(up_m)));
}

void stats(const char *what, std::vector<double> v) {
    std::sort(v.begin(), v.end());
    size_t n = v.size();
    double mean = 0;
    for (double x : v)
        mean += x;
    std::printf("{\"what\": \"%s\", \"n\": %zu, \"median_ms\": %.3f, \"p95_ms\": %.3f, \"mean_ms\": %.3f}\n",
                what, n, v[n / 2], v[std::min(n - 1, (size_t)std::ceil(0.95 * n) - 1)], mean / n);
}

int run(const Args &a) {
    double deadline = now_s() + a.timeout_s;
    osgwxsky::Camera cam;
    Daemon d;
    d.timeout_ms = (int)(a.timeout_s * 1000);
    uint32_t w = a.width ? a.width : 1280, h = a.height ? a.height : 720;
    if (!a.no_sky && a.watch_s <= 0.0) {
        d.c = wxsky_client_new(0, 0);
        if (!d.c)
            throw Failure{1, "out of memory"};
        int st = wxsky_client_connect(d.c, a.control.empty() ? nullptr : a.control.c_str());
        if (st != WXSKY_OK)
            throw Failure{1, std::string("control: ") + wxsky_status_name(st) + ": " + wxsky_client_error(d.c)};
        uint8_t buf[512];
        wxsky_mp_writer wr;
        if (!a.time_utc.empty()) {
            d.rate = map_double(d.call("status", nullptr), "clock_rate");
            wxsky_mp_writer_init(&wr, buf, sizeof buf);
            wxsky_mp_write_map(&wr, 2);
            wxsky_mp_write_cstr(&wr, "time_utc");
            wxsky_mp_write_cstr(&wr, a.time_utc.c_str());
            wxsky_mp_write_cstr(&wr, "rate");
            wxsky_mp_write_double(&wr, 0.0);
            d.call("set_time", &wr);
            d.frozen = true;
        }
        wxsky_mp_writer_init(&wr, buf, sizeof buf);
        wxsky_mp_write_map(&wr, 2 * a.has_lat + a.has_alt + a.has_heading + a.has_pitch + a.has_fov +
                                    a.has_roll + 2 * (a.width != 0));
        if (a.has_lat) {
            wxsky_mp_write_cstr(&wr, "lat_deg");
            wxsky_mp_write_double(&wr, a.lat);
            wxsky_mp_write_cstr(&wr, "lon_deg");
            wxsky_mp_write_double(&wr, a.lon);
        }
        if (a.has_alt) {
            wxsky_mp_write_cstr(&wr, "alt_m");
            wxsky_mp_write_double(&wr, a.alt_m);
        }
        if (a.has_heading) {
            wxsky_mp_write_cstr(&wr, "heading_deg");
            wxsky_mp_write_double(&wr, a.heading);
        }
        if (a.has_pitch) {
            wxsky_mp_write_cstr(&wr, "pitch_deg");
            wxsky_mp_write_double(&wr, a.pitch);
        }
        if (a.has_fov) {
            wxsky_mp_write_cstr(&wr, "fov_deg");
            wxsky_mp_write_double(&wr, a.fov);
        }
        if (a.has_roll) {
            wxsky_mp_write_cstr(&wr, "roll_deg");
            wxsky_mp_write_double(&wr, a.roll);
        }
        if (a.width) {
            wxsky_mp_write_cstr(&wr, "width");
            wxsky_mp_write_uint(&wr, a.width);
            wxsky_mp_write_cstr(&wr, "height");
            wxsky_mp_write_uint(&wr, a.height);
        }
        cam = camera_of(d.call("set_camera", &wr));
        w = cam.width;
        h = cam.height;
        std::printf("asked: ");
        print_camera(cam, -1.0);
    } else {
        cam.position_m[2] = a.has_alt ? a.alt_m : 0.0;
        cam.heading_deg = a.heading;
        cam.pitch_deg = a.pitch;
        cam.roll_deg = a.roll;
        cam.fov_deg = a.has_fov ? a.fov : 60.0;
        cam.width = w;
        cam.height = h;
    }

    Gl gl;
    gl.open(w, h);
    osg::ref_ptr<osg::Group> root = new osg::Group;
    if (!a.scene.empty()) {
        osg::ref_ptr<osg::Node> scene = osgDB::readNodeFile(a.scene);
        if (!scene)
            throw Failure{1, "--scene " + a.scene + ": OSG cannot read it"};
        root->addChild(scene);
    }
    osg::ref_ptr<osgwxsky::SkyNode> sky;
    std::string tmp;
    if (!a.no_sky) {
        std::string path = a.sky;
        if (path.empty()) {
            char t[] = "/tmp/wxsky-osg-XXXXXX";
            int fd = mkstemp(t);
            if (fd < 0)
                throw Failure{1, "cannot make a temporary .wxsky file"};
            close(fd);
            tmp = path = std::string(t) + ".wxsky";
            std::rename(t, path.c_str());
            std::ofstream f(path.c_str());
            f << "# made by " PROG "\nframe = " << (a.geocentric ? "geocentric" : "enu")
              << "\nup_m = " << a.up_m << "\n";
            if (!a.control.empty())
                f << "control = " << a.control << "\n";
            if (!a.shm.empty())
                f << "shm = " << a.shm << "\n";
        }
        osg::ref_ptr<osg::Node> node = osgDB::readNodeFile(path);
        if (!tmp.empty())
            std::remove(tmp.c_str());
        sky = dynamic_cast<osgwxsky::SkyNode *>(node.get());
        if (!sky)
            throw Failure{1, path + ": the wxsky plugin gave no sky node (is osgdb_wxsky.so beside this program?)"};
        if (!sky->status().enabled)
            throw Failure{1, sky->status().last_error};
        root->addChild(sky);
        if (a.shadows)
            shade_scene(*root->getChild(0), *sky, a.up_m);
    }

    osgViewer::Viewer viewer;
    viewer.setThreadingModel(osgViewer::Viewer::SingleThreaded);
    osg::ref_ptr<osgViewer::GraphicsWindowEmbedded> win = viewer.setUpViewerAsEmbeddedInWindow(0, 0, (int)w, (int)h);
    win->setDefaultFboId(gl.fbo);
    viewer.setSceneData(root);
    osg::Camera *oc = viewer.getCamera();
    oc->setComputeNearFarMode(osg::CullSettings::DO_NOT_COMPUTE_NEAR_FAR);
    oc->setClearColor(osg::Vec4(0, 0, 0, 0));
    // wxsky's camera model (wxsky/scene/camera.py): near 2 m, far 200 km, horizontal fov
    double tx = std::tan(cam.fov_deg * M_PI / 360.0), ty = tx * h / w, n = 2.0, f = 200000.0;
    oc->setProjectionMatrixAsFrustum(-tx * n, tx * n, -ty * n, ty * n, n, f);
    oc->setViewMatrix(a.geocentric ? geocentric_view_of(cam, a.lat, a.lon) : view_of(cam, a.up_m));
    viewer.realize();

    std::vector<uint8_t> px;
    if (a.watch_s > 0.0) {
        // the host's loop, the daemon left alone: a status line every 0.25 s
        uint64_t host_frames = 0;
        double end = now_s() + a.watch_s, next = 0.0;
        while (now_s() < end) {
            viewer.frame();
            glFinish();
            ++host_frames;
            if (now_s() >= next) {
                next = now_s() + 0.25;
                osgwxsky::Status s = sky ? sky->status() : osgwxsky::Status();
                std::string e;
                for (char ch : s.last_error)
                    if (ch != '"' && ch != '\\')
                        e += ch;
                std::printf("{\"host_frames\": %llu, \"connected\": %s, \"segment_open\": %s, "
                            "\"frames_uploaded\": %llu, \"frames_drawn\": %llu, "
                            "\"last_frame_number\": %llu, \"error\": \"%s\"}\n",
                            (unsigned long long)host_frames, s.connected ? "true" : "false",
                            s.segment_open ? "true" : "false",
                            (unsigned long long)s.frames_uploaded, (unsigned long long)s.frames_drawn,
                            (unsigned long long)s.last_frame_number, e.c_str());
                std::fflush(stdout);
            }
        }
        if (a.out.empty()) {
            viewer.setSceneData(nullptr);
            if (sky)
                sky->close();
            return 0;
        }
        px = gl.read(w, h);
    } else if (a.no_sky) {
        viewer.frame();
        glFinish();
        px = gl.read(w, h);
    } else {
        // frames until the node's layers are for this camera and the ring has settled
        int settled = 0;
        double next_scene = 0.0;
        while (settled < 2) {
            if (now_s() > deadline)
                throw Failure{1, "timed out waiting for a settled frame for the camera: " +
                                     sky->status().last_error};
            viewer.frame();
            osgwxsky::Status s = sky->status();
            // Paced while it waits: a frame drawn as fast as it goes takes a core of a small
            // machine from the daemon, which is building the very ring waited for.
            if (!s.record_matches_camera || !s.frames_uploaded) {
                usleep(20000);
                continue;
            }
            if (settled == 0 && now_s() >= next_scene) {
                next_scene = now_s() + 0.1;
                if (!d.ring_busy())
                    settled = 1;
            } else if (settled >= 1) {
                static uint64_t seen = 0;
                if (s.last_frame_number > seen) { // a frame after the ring settled
                    if (seen)
                        ++settled;
                    seen = s.last_frame_number;
                }
            }
            usleep(settled ? 5000 : 50000);
        }
        glFinish();
        px = gl.read(w, h);
        osgwxsky::Status s = sky->status();
        std::printf("camera: ");
        print_camera(s.camera, s.near_distance_m);
        if (d.frozen)
            d.restart_clock();
    }
    char err[256];
    if (png_write_rgba(a.out.c_str(), px.data(), w, h, err, sizeof err) != 0)
        throw Failure{1, err};
    std::printf("wrote %s (%ux%u), frame %llu\n", a.out.c_str(), w, h,
                (unsigned long long)(sky ? sky->status().last_frame_number : 0));
    if (!a.bare_out.empty() && sky) {
        // the same camera without the node: what the scene alone draws (alpha: its pixels)
        root->removeChild(sky);
        oc->setClearColor(osg::Vec4(0, 0, 0, 0));
        viewer.frame();
        glFinish();
        std::vector<uint8_t> bare = gl.read(w, h);
        if (png_write_rgba(a.bare_out.c_str(), bare.data(), w, h, err, sizeof err) != 0)
            throw Failure{1, err};
        root->addChild(sky);
    }
    if (a.bench > 0 && sky) {
        // Pairs of frames, with the node and without it (its mask 0), each finished with
        // glFinish, the node uploading the newest frame every time: the host's cost per frame
        // of the sky, as the difference within each pair (a busy machine slows both alike).
        sky->setUploadEveryFrame(true);
        std::vector<double> with, without, diff;
        for (int i = 0; i < a.bench + 10; ++i) {
            double t[2];
            for (int on = 1; on >= 0; --on) {
                sky->setNodeMask(on ? 0xffffffffu : 0u);
                double t0 = now_s();
                viewer.frame();
                glFinish();
                t[on] = (now_s() - t0) * 1e3;
            }
            if (i < 10)
                continue; // warm-up (and the daemon being paused by the caller)
            with.push_back(t[1]);
            without.push_back(t[0]);
            diff.push_back(t[1] - t[0]);
        }
        sky->setNodeMask(0xffffffffu);
        sky->setUploadEveryFrame(false);
        stats("frame_with_sky", with);
        stats("frame_without_sky", without);
        stats("sky_upload_and_draw", diff);
    }
    viewer.setSceneData(nullptr);
    if (sky)
        sky->close();
    return 0;
}

} // namespace

int main(int argc, char **argv) {
    if (argc == 2 && (!std::strcmp(argv[1], "--help") || !std::strcmp(argv[1], "-h"))) {
        std::printf("%s\n", USAGE);
        return 0;
    }
    // the plugin beside this program comes first
    char self[4096];
    ssize_t n = readlink("/proc/self/exe", self, sizeof self - 1);
    if (n > 0) {
        self[n] = 0;
        std::string dir(self);
        dir = dir.substr(0, dir.rfind('/'));
        osgDB::Registry::instance()->getLibraryFilePathList().push_front(dir);
    }
    try {
        return run(parse(argc, argv));
    } catch (const Failure &f) {
        std::fprintf(stderr, "%s: error: %s\n", PROG, f.what.c_str());
        return f.code;
    }
}
