// The node and its two drawables: the background (sky and ring) after the opaque scene, and
// the near layers after the transparent one. The per-frame work runs in the first of them
// OSG draws for the node's camera: the camera sent, the newest frame uploaded.
#define GL_GLEXT_PROTOTYPES 1
#include <osgwxsky/SkyNode>

#include <osg/CoordinateSystemNode>
#include <osg/Drawable>
#include <osg/Geode>
#include <osg/GL>
#include <osg/Notify>
#include <osg/RenderInfo>
#include <osg/State>
#include <osg/Texture2D>
#include <osg/Uniform>
#include <GL/glext.h>

#include <time.h>

#include <climits>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>

#include "link.h"
#include "wxsky_host.h"
#include "wxsky_host_gl.h"

namespace osgwxsky {

namespace {

const double REOPEN_S = 1.0; // segment open attempts, and liveness checks, at most this often
const double LOG_EVERY_S = 60.0; // the same problem logged again after this long
const double D2R = M_PI / 180.0;

double now_s() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec * 1e-9;
}

double dot(const osg::Vec3d &a, const osg::Vec3d &b) { return a * b; }

// Heading, pitch, roll of a camera basis in ENU, as wxsky/scene/camera.py defines them
// (heading clockwise from north, pitch nose up, roll right wing down).
void angles(const osg::Vec3d &right, const osg::Vec3d &fwd, Camera &c) {
    double fz = std::max(-1.0, std::min(1.0, fwd.z()));
    double h;
    if (std::fabs(fz) > 0.999999) // straight up or down: the heading from the right axis
        h = std::atan2(-right.y(), right.x());
    else
        h = std::atan2(fwd.x(), fwd.y());
    c.pitch_deg = std::asin(fz) / D2R;
    osg::Vec3d level_right(std::cos(h), -std::sin(h), 0.0);
    osg::Vec3d level_up = level_right ^ fwd;
    c.roll_deg = std::fabs(fz) > 0.999999
                     ? 0.0
                     : std::atan2(-dot(right, level_up), dot(right, level_right)) / D2R;
    h /= D2R;
    c.heading_deg = h < 0.0 ? h + 360.0 : (h >= 360.0 ? h - 360.0 : h);
}

// The state OSG believes in, after the compositor changed it behind its back.
void restore(osg::State &s) {
    glBindVertexArray(0);
    s.setCurrentVertexArrayObject(0);
    glUseProgram(0);
    s.setLastAppliedProgramObject(nullptr);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
    glBindTexture(GL_TEXTURE_2D, 0);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, 0);
    s.setActiveTextureUnit(0);
    glDepthMask(GL_TRUE);
    glDepthFunc(GL_LESS);
    glDisable(GL_BLEND);
    s.dirtyAllModes();
    s.dirtyAllAttributes();
    s.dirtyAllVertexArrays();
}

} // namespace

struct SkyNode::Impl {
    Settings settings;
    bool enabled = false;
    std::unique_ptr<Link> link;

    // the draw thread's
    unsigned context = UINT_MAX;
    bool warned_context = false;
    wxsky_segment *seg = nullptr;
    wxsky_gl_compositor *gl = nullptr;
    bool gl_ready = false;
    bool has_near_depth = false; // the open segment has the `near_depth` layer
    uint64_t seg_serial = 0;
    double next_open_s = 0.0, next_check_s = 0.0;
    bool have_frame = false;
    wxsky_record rec{};
    unsigned osg_frame = UINT_MAX;
    const osg::Camera *camera = nullptr;
    bool drawing = false; // this frame's camera has a frame to draw
    bool upload_every_frame = false; // setUploadEveryFrame
    double view[16]{}, proj[16]{};
    std::map<std::string, double> logged; // message -> when it was last logged

    mutable std::mutex lock; // status
    Status status;

    // the cloud-shadow map's StateSet (shadowStateSet): made once, its uniforms set from
    // each uploaded frame, its texture the compositor's
    osg::ref_ptr<osg::StateSet> shadow_set;
    osg::ref_ptr<osg::Uniform> u_rect, u_sun, u_texels;
    unsigned shadow_texture = 0; // the compositor's GL name (0: none)
    void update_shadow();

    Impl() { std::memset(&rec, 0, sizeof rec); }
    ~Impl() {
        if (link)
            link->stop();
        wxsky_segment_free(seg);
        // GL objects go with their context (releaseGLObjects); without one current,
        // glvnd's calls do nothing and only the memory is freed
        wxsky_gl_free(gl);
    }

    void problem(const std::string &what) {
        double t = now_s();
        auto it = logged.find(what);
        if (it == logged.end() || t - it->second > LOG_EVERY_S) { // each message once a minute
            if (logged.size() > 64)
                logged.clear();
            logged[what] = t;
            OSG_WARN << "wxsky: " << (settings.file.empty() ? "SkyNode" : settings.file)
                     << ": " << what << std::endl;
        }
        std::lock_guard<std::mutex> g(lock);
        status.last_error = what;
    }

    bool begin(osg::RenderInfo &ri);
    bool take_camera(osg::State &state);
    void take_frame();
    void draw_background(osg::State &state);
    void draw_near(osg::State &state);
};

// Whether this camera draws the node this frame; the first call of a frame does its work.
bool SkyNode::Impl::begin(osg::RenderInfo &ri) {
    if (!enabled || !ri.getState())
        return false;
    osg::State &state = *ri.getState();
    unsigned ctx = state.getContextID();
    if (context == UINT_MAX) {
        context = ctx;
    } else if (ctx != context) {
        if (!warned_context) {
            warned_context = true;
            OSG_WARN << "wxsky: " << settings.file
                     << ": drawn on a second graphics context: only the first gets the sky"
                     << std::endl;
        }
        return false;
    }
    const osg::Camera *cam = ri.getCurrentCamera();
    if (!settings.camera.empty() && (!cam || cam->getName() != settings.camera))
        return false;
    unsigned f = state.getFrameStamp() ? state.getFrameStamp()->getFrameNumber() : 0;
    if (f == osg_frame)
        return drawing && cam == camera;
    osg_frame = f;
    camera = cam;
    drawing = false;
    if (!take_camera(state))
        return false;
    take_frame();
    drawing = have_frame;
    {
        std::lock_guard<std::mutex> g(lock);
        if (drawing)
            ++status.frames_drawn;
    }
    return drawing;
}

// The OSG camera as the daemon's, posted to the link; the view for the draws.
bool SkyNode::Impl::take_camera(osg::State &state) {
    const osg::Matrixd &V = state.getInitialViewMatrix();
    const osg::Matrixd &P = state.getProjectionMatrix();
    const osg::Viewport *vp = state.getCurrentViewport();
    const double *p = P.ptr();
    if (!vp || vp->width() < 1 || vp->height() < 1 || p[11] != -1.0 || p[0] <= 0.0) {
        problem("the camera is not a perspective one with a viewport: nothing drawn");
        return false;
    }
    if (std::fabs(p[8]) > 1e-6 || std::fabs(p[9]) > 1e-6)
        problem("off-axis projection (centre at " + std::to_string(-p[8]) + ", " +
                std::to_string(-p[9]) + " of the viewport's half-size)");
    osg::Matrixd inv;
    if (!inv.invert(V))
        return false;
    osg::Vec3d eye = inv.getTrans();
    osg::Vec3d right = osg::Matrixd::transform3x3(osg::Vec3d(1, 0, 0), inv);
    osg::Vec3d up = osg::Matrixd::transform3x3(osg::Vec3d(0, 1, 0), inv);
    osg::Vec3d fwd = osg::Matrixd::transform3x3(osg::Vec3d(0, 0, -1), inv);
    right.normalize();
    up.normalize();
    fwd.normalize();

    Camera c;
    double eye_wx[3];
    LinkView lv = link->view();
    if (settings.frame == Frame::Enu) {
        eye_wx[0] = eye.x();
        eye_wx[1] = eye.y();
        eye_wx[2] = eye.z() + settings.up_m;
    } else {
        osg::EllipsoidModel wgs84;
        double lat, lon, h;
        wgs84.convertXYZToLatLongHeight(eye.x(), eye.y(), eye.z(), lat, lon, h);
        osg::Vec3d e(-std::sin(lon), std::cos(lon), 0.0);
        osg::Vec3d n(-std::sin(lat) * std::cos(lon), -std::sin(lat) * std::sin(lon), std::cos(lat));
        osg::Vec3d u(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat));
        right = osg::Vec3d(dot(right, e), dot(right, n), dot(right, u));
        up = osg::Vec3d(dot(up, e), dot(up, n), dot(up, u));
        fwd = osg::Vec3d(dot(fwd, e), dot(fwd, n), dot(fwd, u));
        c.geodetic = true;
        c.lat_deg = lat / D2R;
        c.lon_deg = lon / D2R;
        c.alt_m = h;
        // the daemon's flat frame about its site (wxsky/weather/geo.py); the eye at the
        // site until the first answer names it
        double east = 0.0, north = 0.0;
        if (lv.site_valid) {
            double dlon = std::remainder(c.lon_deg - lv.site_lon_deg, 360.0);
            east = dlon * 111320.0 * std::cos(lv.site_lat_deg * D2R);
            north = (c.lat_deg - lv.site_lat_deg) * 110540.0;
        }
        eye_wx[0] = east;
        eye_wx[1] = north;
        eye_wx[2] = h;
    }
    for (int i = 0; i < 3; ++i)
        c.position_m[i] = eye_wx[i];
    angles(right, fwd, c);
    // the horizontal field of view of the projection (left and right edges' angles)
    c.fov_deg = (std::atan((1.0 + p[8]) / p[0]) + std::atan((1.0 - p[8]) / p[0])) / D2R;
    c.fov_deg = std::max(1.0, std::min(170.0, c.fov_deg));
    // the viewport's size, scaled down to fit the daemon's layers keeping its shape
    double w = vp->width(), h = vp->height(), scale = 1.0;
    wxsky_layer_info sky;
    int sky_index = seg ? wxsky_segment_find_layer(seg, "sky") : -1;
    // the height from the projection's own shape (tan_y / tan_x = p[0] / p[5]): a viewport
    // whose pixels the projection does not keep square (a window resized under a fixed
    // projection) still gets the camera it is drawn with
    double shape = std::fabs(p[5]) > 0.0 ? p[0] / std::fabs(p[5]) : h / w;
    if (std::fabs(shape - h / w) > 1e-3 * (h / w))
        h = w * shape;
    if (sky_index >= 0 && wxsky_segment_layer(seg, (uint32_t)sky_index, &sky) == WXSKY_OK)
        scale = std::min(1.0, std::min(sky.max_width / w, sky.max_height / h));
    c.width = (uint32_t)std::max(1.0, std::floor(w * scale));
    c.height = (uint32_t)std::max(1.0, std::floor(h * scale));
    link->post(c);

    // the view in the daemon's frame: rows right, up, -forward; the eye at eye_wx
    const osg::Vec3d rows[3] = {right, up, -fwd};
    std::memset(view, 0, sizeof view);
    for (int r = 0; r < 3; ++r) {
        for (int col = 0; col < 3; ++col)
            view[col * 4 + r] = rows[r][col];
        view[12 + r] = -(rows[r][0] * eye_wx[0] + rows[r][1] * eye_wx[1] + rows[r][2] * eye_wx[2]);
    }
    view[15] = 1.0;
    std::memcpy(proj, p, sizeof proj);
    std::lock_guard<std::mutex> g(lock);
    status.camera = c;
    status.camera_valid = true;
    status.cameras_sent = lv.cameras_sent;
    status.connected = lv.connected;
    return true;
}

// Opens (or reopens) the segment when the link names one, and uploads its newest frame.
void SkyNode::Impl::take_frame() {
    double t = now_s();
    LinkView lv = link->view();
    if (seg && wxsky_segment_layer_count(seg) && t >= next_check_s) {
        next_check_s = t + REOPEN_S;
        if (wxsky_segment_check(seg) != WXSKY_OK) { // closed, or another daemon's now
            problem(std::string("the segment went away: ") + wxsky_segment_error(seg) +
                    "; drawing the last layers");
            wxsky_segment_close(seg);
        }
    }
    if (!lv.shm.empty() && (!seg || !wxsky_segment_layer_count(seg) ||
                            lv.shm_serial != seg_serial) && t >= next_open_s) {
        next_open_s = t + REOPEN_S;
        if (!seg)
            seg = wxsky_segment_new();
        int st = seg ? wxsky_segment_open(seg, lv.shm.c_str()) : WXSKY_ESYS;
        if (st == WXSKY_OK) {
            seg_serial = lv.shm_serial;
            gl_ready = false; // a new segment may have other capacities, and its own numbers
            have_frame = false;
            rec.frame_number = 0;
            if (!gl)
                gl = wxsky_gl_new();
            if (gl && (st = wxsky_gl_init(gl, seg)) == WXSKY_OK) {
                gl_ready = true;
                has_near_depth = wxsky_segment_find_layer(seg, "near_depth") >= 0;
                std::lock_guard<std::mutex> g(lock);
                status.last_error.clear(); // back: what went wrong before is over
            } else {
                problem(std::string("GL compositor: ") + wxsky_status_name(st) + ": " +
                        (gl ? wxsky_gl_error(gl) : "out of memory"));
                wxsky_segment_close(seg);
            }
        } else if (st != WXSKY_STARTING) {
            problem("segment " + lv.shm + ": " + wxsky_status_name(st) + ": " +
                    (seg ? wxsky_segment_error(seg) : "out of memory"));
        }
    }
    bool open = seg && wxsky_segment_layer_count(seg) && gl_ready;
    {
        std::lock_guard<std::mutex> g(lock);
        status.segment_open = open;
    }
    if (!open)
        return;
    uint64_t latest = wxsky_segment_latest_frame(seg);
    if (have_frame && latest <= rec.frame_number && !upload_every_frame)
        return;
    for (int attempt = 0; attempt < 2; ++attempt) {
        wxsky_frame_view fv;
        wxsky_record r;
        char err[WXSKY_ERROR_MAX];
        int st = wxsky_frame_begin(seg, &fv);
        if (st == WXSKY_AGAIN)
            return; // being written: the last layers this frame
        if (st != WXSKY_OK) {
            problem(std::string("frame: ") + wxsky_status_name(st) + ": " + wxsky_segment_error(seg));
            return;
        }
        st = wxsky_record_decode(fv.meta, fv.meta_length, &r, err, sizeof err);
        int up = st == WXSKY_OK ? wxsky_gl_upload_view(gl, &fv, &r) : st;
        if (wxsky_frame_end(seg, &fv) != WXSKY_OK) { // torn: the textures too; again
            wxsky_gl_invalidate(gl);
            continue;
        }
        if (st != WXSKY_OK) {
            problem(std::string("frame record: ") + err);
            return;
        }
        if (up != WXSKY_OK) {
            problem(std::string("upload: ") + wxsky_gl_error(gl));
            return;
        }
        rec = r;
        have_frame = true;
        update_shadow();
        std::lock_guard<std::mutex> g(lock);
        ++status.frames_uploaded;
        status.last_frame_number = r.frame_number;
        const Camera &c = status.camera;
        status.record_matches_camera =
            std::fabs(r.heading_deg - c.heading_deg) < 1e-9 &&
            std::fabs(r.pitch_deg - c.pitch_deg) < 1e-9 && std::fabs(r.roll_deg - c.roll_deg) < 1e-9 &&
            std::fabs(r.fov_deg - c.fov_deg) < 1e-9 && r.width_px == c.width &&
            r.height_px == c.height &&
            (c.geodetic ? std::fabs(r.position_m[2] - c.alt_m) < 1e-6
                        : std::fabs(r.position_m[0] - c.position_m[0]) < 1e-6 &&
                              std::fabs(r.position_m[1] - c.position_m[1]) < 1e-6 &&
                              std::fabs(r.position_m[2] - c.position_m[2]) < 1e-6);
        return;
    }
}

void SkyNode::Impl::update_shadow() {
    if (!shadow_set)
        return;
    wxsky_gl_shadow_params sp;
    if (wxsky_gl_shadow(gl, &sp) != WXSKY_OK)
        return;
    shadow_texture = sp.texture;
    u_rect->set(osg::Vec4f(sp.rect[0], sp.rect[1], sp.rect[2], sp.rect[3]));
    u_sun->set(osg::Vec4f(sp.sun[0], sp.sun[1], sp.sun[2], sp.sun[3]));
    u_texels->set(osg::Vec4f(sp.texels[0], sp.texels[1], sp.texels[2], sp.texels[3]));
}

void SkyNode::Impl::draw_background(osg::State &state) {
    int st = wxsky_gl_draw_background(gl, view, proj);
    restore(state);
    if (st != WXSKY_OK)
        problem(std::string("draw: ") + wxsky_gl_error(gl));
}

void SkyNode::Impl::draw_near(osg::State &state) {
    double d = -1.0;
    Link::NearKind kind = link->nearDistance(rec.frame_number, d);
    int st = WXSKY_OK;
    bool layer = has_near_depth;
    if (!settings.near_depth || (kind == Link::NEAR_UNKNOWN && !layer))
        st = wxsky_gl_draw_near(gl); // over everything, as protocol §0 draws it
    else if (kind == Link::NEAR_AT || layer)
        // each pixel at its cloud's depth where the daemon draws `near_depth`, else (and
        // for what that layer holds no depth for) at the nearest the stream says
        st = wxsky_gl_draw_near_at(gl, kind == Link::NEAR_AT ? d : 0.0);
    if (st == WXSKY_OK)
        st = wxsky_gl_draw_near_front(gl);
    restore(state);
    {
        std::lock_guard<std::mutex> g(lock);
        status.near_distance_m = kind == Link::NEAR_AT ? d : -1.0;
    }
    if (st != WXSKY_OK)
        problem(std::string("draw: ") + wxsky_gl_error(gl));
}

namespace {

// The compositor's shadow-map texture as an OSG texture attribute: binding it binds the
// compositor's GL texture (0 before the first map; the uniforms then say `present` 0).
class ShadowTexture : public osg::Texture2D {
  public:
    ShadowTexture() = default;
    explicit ShadowTexture(std::shared_ptr<SkyNode::Impl> impl) : impl_(std::move(impl)) {
        setDataVariance(osg::Object::DYNAMIC);
    }
    ShadowTexture(const ShadowTexture &o, const osg::CopyOp &op = osg::CopyOp::SHALLOW_COPY)
        : osg::Texture2D(o, op), impl_(o.impl_) {}
    META_StateAttribute(osgwxsky, ShadowTexture, TEXTURE)
    int compare(const osg::StateAttribute &sa) const override {
        COMPARE_StateAttribute_Types(ShadowTexture, sa)
        return impl_ == rhs.impl_ ? 0 : (impl_.get() < rhs.impl_.get() ? -1 : 1);
    }
    void apply(osg::State &) const override {
        glBindTexture(GL_TEXTURE_2D, impl_ ? impl_->shadow_texture : 0);
    }

  private:
    std::shared_ptr<SkyNode::Impl> impl_;
};

class Layer : public osg::Drawable {
  public:
    enum Which { Background, Near };
    Layer() = default;
    Layer(std::shared_ptr<SkyNode::Impl> impl, Which which) : impl_(std::move(impl)), which_(which) {
        setUseDisplayList(false);
        setUseVertexBufferObjects(false);
        setSupportsDisplayList(false);
        setDataVariance(osg::Object::DYNAMIC);
        setCullingActive(false);
    }
    Layer(const Layer &o, const osg::CopyOp &op = osg::CopyOp::SHALLOW_COPY)
        : osg::Drawable(o, op), impl_(o.impl_), which_(o.which_) {}
    META_Object(osgwxsky, Layer)

    // no bounds: the node neither culls nor moves the host's near and far planes
    osg::BoundingBox computeBoundingBox() const override { return osg::BoundingBox(); }
    osg::BoundingSphere computeBound() const override { return osg::BoundingSphere(); }

    void drawImplementation(osg::RenderInfo &ri) const override {
        if (!impl_ || !impl_->begin(ri))
            return;
        if (which_ == Background)
            impl_->draw_background(*ri.getState());
        else
            impl_->draw_near(*ri.getState());
    }

    void releaseGLObjects(osg::State *state) const override {
        osg::Drawable::releaseGLObjects(state);
        if (impl_ && impl_->gl && (!state || state->getContextID() == impl_->context)) {
            wxsky_gl_free(impl_->gl); // the context is current here
            impl_->gl = nullptr;
            impl_->gl_ready = false;
            impl_->have_frame = false;
        }
    }

  private:
    std::shared_ptr<SkyNode::Impl> impl_;
    Which which_ = Background;
};

} // namespace

SkyNode::SkyNode() : _impl(std::make_shared<Impl>()) {}

SkyNode::SkyNode(const Settings &settings) : SkyNode() {
    _impl->settings = settings;
    _impl->enabled = true;
    _impl->status.enabled = true;
    _impl->link.reset(new Link(settings));
    setCullingActive(false);
    // on this Group, not the Geode: FlightGear replaces a loaded Geode that has a StateSet,
    // and its mask with it (so the drawables' bins are on the drawables)
    setNodeMask(settings.node_mask);
    osg::ref_ptr<osg::Geode> geode = new osg::Geode;
    geode->setCullingActive(false);
    osg::ref_ptr<Layer> bg = new Layer(_impl, Layer::Background);
    osg::ref_ptr<Layer> near = new Layer(_impl, Layer::Near);
    bg->getOrCreateStateSet()->setRenderBinDetails(settings.background_bin, "RenderBin");
    near->getOrCreateStateSet()->setRenderBinDetails(settings.near_bin, "RenderBin");
    geode->addDrawable(bg);
    geode->addDrawable(near);
    addChild(geode);
}

osg::ref_ptr<SkyNode> SkyNode::disabled(const std::string &why) {
    osg::ref_ptr<SkyNode> node = new SkyNode();
    node->_impl->status.last_error = why;
    return node;
}

SkyNode::~SkyNode() { close(); }

Status SkyNode::status() const {
    std::lock_guard<std::mutex> g(_impl->lock);
    Status s = _impl->status;
    if (_impl->link) {
        LinkView lv = _impl->link->view();
        s.connected = lv.connected;
        s.cameras_sent = lv.cameras_sent;
        if (s.last_error.empty())
            s.last_error = lv.error;
    }
    return s;
}

const Settings &SkyNode::settings() const { return _impl->settings; }

void SkyNode::setUploadEveryFrame(bool on) { _impl->upload_every_frame = on; }

osg::StateSet *SkyNode::shadowStateSet(unsigned unit) {
    Impl &m = *_impl;
    if (!m.shadow_set) {
        m.shadow_set = new osg::StateSet;
        m.shadow_set->setDataVariance(osg::Object::DYNAMIC);
        m.u_rect = new osg::Uniform("wxsky_shadow_rect", osg::Vec4f(0, 0, 0, 0));
        m.u_sun = new osg::Uniform("wxsky_shadow_sun", osg::Vec4f(0, 0, 0, 0));
        m.u_texels = new osg::Uniform("wxsky_shadow_texels", osg::Vec4f(1, 1, 1, 1));
        for (osg::Uniform *u : {m.u_rect.get(), m.u_sun.get(), m.u_texels.get()}) {
            u->setDataVariance(osg::Object::DYNAMIC);
            m.shadow_set->addUniform(u);
        }
        m.shadow_set->setTextureAttribute(unit, new ShadowTexture(_impl));
        m.shadow_set->addUniform(new osg::Uniform("wxsky_shadow_map", static_cast<int>(unit)));
    }
    return m.shadow_set.get();
}

const char *SkyNode::shadowGlsl() { return WXSKY_GL_SHADOW_GLSL; }

void SkyNode::close() {
    if (_impl->link)
        _impl->link->stop();
}

} // namespace osgwxsky
