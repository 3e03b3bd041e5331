/* The GL compositor (wxsky_host_gl.h): protocol §0 in OpenGL 3.3 core / OpenGL ES 3.0.
 *
 * Textures: one 2D texture per full-screen layer (sky, near, near_front) and one 2D array of
 * 16 layers for the ring (0..7 ring_i, 8..15 ring_in_i), each sized to the segment's
 * capacity; a frame uses the top-left width x height of it.
 *
 * The ring is drawn as one full-screen pass that, per pixel, intersects the view ray with the
 * 8 quads (and, while fading, the 8 incoming ones) exactly as the reference compositor
 * (wxsky/host/compositor.py) does: the nearest quad hit wins, its image is sampled bilinearly
 * with texel centres at (i + 0.5) / size and clamped edges, the two rings are mixed by the
 * fade weight, and the hit's depth goes to gl_FragDepth for the host's depth test. One pass
 * makes the cross-fade exact (two blended passes cannot mix two "over"s), and the ray is
 * relative to the eye, computed in double on the CPU, so world coordinates of any size keep
 * float precision. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef WXSKY_GL_ES
#include <GLES3/gl3.h>
#define WXSKY_GLSL_HEADER                                                                      \
    "#version 300 es\n"                                                                        \
    "precision highp float;\nprecision highp int;\nprecision highp sampler2D;\n"               \
    "precision highp sampler2DArray;\n"
#else
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#define WXSKY_GLSL_HEADER "#version 330 core\n"
#endif

#include "wxsky_host_gl.h"

#define RING_QUADS 8
#define RING_LAYERS 16 /* ring_0..7, then ring_in_0..7 */

enum { FS_SKY = 0, FS_NEAR = 1, FS_FRONT = 2, FS_COUNT = 3 };

struct wxsky_gl_compositor {
    char error[WXSKY_ERROR_MAX];
    int ready;
    int have_frame;
    int rings_valid;
    uint64_t ring_version;
    int flip; /* from the last background draw: layers' top row at framebuffer row 0 */

    /* segment layer indices (-1: absent) and capacities */
    int fs_index[FS_COUNT];
    uint32_t fs_cap_w[FS_COUNT], fs_cap_h[FS_COUNT];
    uint32_t fs_w[FS_COUNT], fs_h[FS_COUNT]; /* as uploaded; 0: not drawn */
    int ring_index[RING_LAYERS];
    uint32_t ring_cap_w, ring_cap_h;
    int32_t ring_size[RING_LAYERS * 2]; /* as uploaded: width, height */

    wxsky_record rec;

    int pbo; /* stream the full-screen layers through pixel-unpack buffers */
    GLuint fs_pbo[FS_COUNT];
    GLuint fs_tex[FS_COUNT];
    GLuint ring_tex;
    GLuint vao;
    GLuint fs_prog, ring_prog;
    /* full-screen program uniforms */
    GLint u_fs_tex, u_fs_size, u_fs_cap, u_fs_viewport, u_fs_flip;
    /* ring program uniforms */
    GLint u_ring_tex, u_ring_size, u_ring_tl, u_ring_u, u_ring_v, u_ring_inv, u_ring_vp,
        u_ring_viewport, u_ring_count, u_ring_fade;
    GLfloat tl[RING_LAYERS * 3], du[RING_LAYERS * 3], dv[RING_LAYERS * 3];
};

static int fail(wxsky_gl_compositor *c, int status, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;

static int fail(wxsky_gl_compositor *c, int status, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->error, sizeof c->error, fmt, ap);
    va_end(ap);
    return status;
}

static int ok(wxsky_gl_compositor *c) {
    c->error[0] = '\0';
    return WXSKY_OK;
}

/* GL errors pending at the end of a call: raised by it, or by the host before it and not yet
 * fetched (the compositor never clears the host's errors unseen; the message says where it
 * noticed it). */
static int gl_check(wxsky_gl_compositor *c, const char *where) {
    GLenum e = glGetError();
    if (e == GL_NO_ERROR)
        return WXSKY_OK;
    for (int i = 0; i < 32 && glGetError() != GL_NO_ERROR; ++i) {
        /* the rest (bounded: a lost context may keep reporting) */
    }
    return fail(c, WXSKY_ESYS, "GL error 0x%04x in %s", (unsigned)e, where);
}

uint32_t wxsky_gl_version(void) {
    return ((uint32_t)WXSKY_HOST_GL_VERSION_MAJOR << 16) | WXSKY_HOST_GL_VERSION_MINOR;
}

/* ---- shaders ------------------------------------------------------------------------- */

/* A full-screen triangle from gl_VertexID (no vertex buffer), at the far plane. */
static const char VS_FULLSCREEN[] =
    "out vec2 ndc;\n"
    "void main() {\n"
    "    vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1));\n"
    "    ndc = p;\n"
    "    gl_Position = vec4(p, 1.0, 1.0);\n"
    "}\n";

/* A full-screen layer stretched over the viewport: texelFetch when the sizes agree (exact),
 * bilinear with clamped edges otherwise. */
static const char FS_LAYER[] =
    "uniform sampler2D tex;\n"
    "uniform ivec2 size;\n"   /* the layer's pixels this frame */
    "uniform vec2 cap;\n"     /* the texture's size */
    "uniform vec4 viewport;\n"
    "uniform int flip;\n"
    "out vec4 colour;\n"
    "void main() {\n"
    "    vec2 f = (gl_FragCoord.xy - viewport.xy) / viewport.zw;\n"
    "    if (flip == 0) f.y = 1.0 - f.y;\n"
    "    vec2 px = f * vec2(size);\n"
    "    if (ivec2(viewport.zw) == size) {\n"
    "        colour = texelFetch(tex, clamp(ivec2(px), ivec2(0), size - 1), 0);\n"
    "    } else {\n"
    "        px = clamp(px, vec2(0.5), vec2(size) - 0.5);\n"
    "        colour = texture(tex, px / cap);\n"
    "    }\n"
    "}\n";

/* The ring: the reference compositor's sample_ring and bilinear, per pixel. */
static const char FS_RING[] =
    "uniform sampler2DArray tex;\n"
    "uniform ivec2 size[16];\n" /* each ring layer's pixels this frame; 0: absent */
    "uniform vec3 tl[16];\n"    /* quad corners relative to the eye */
    "uniform vec3 du[16];\n"    /* top-right - top-left */
    "uniform vec3 dv[16];\n"    /* bottom-left - top-left */
    "uniform mat4 inv_vp;\n"    /* inverse of projection x view-about-the-eye */
    "uniform mat4 vp;\n"        /* projection x view-about-the-eye */
    "uniform vec4 viewport;\n"
    "uniform int count;\n"      /* 8, or 16 while fading */
    "uniform float fade;\n"
    "out vec4 colour;\n"
    "vec4 texel(int layer, int x, int y) { return texelFetch(tex, ivec3(x, y, layer), 0); }\n"
    "vec4 bilinear(int layer, float a, float b) {\n"
    "    ivec2 s = size[layer];\n"
    "    float x = clamp(a * float(s.x) - 0.5, 0.0, float(s.x - 1));\n"
    "    float y = clamp(b * float(s.y) - 0.5, 0.0, float(s.y - 1));\n"
    "    int x0 = s.x > 1 ? min(int(x), s.x - 2) : 0;\n"
    "    int y0 = s.y > 1 ? min(int(y), s.y - 2) : 0;\n"
    "    float fx = x - float(x0), fy = y - float(y0);\n"
    "    int x1 = min(x0 + 1, s.x - 1), y1 = min(y0 + 1, s.y - 1);\n"
    "    vec4 top = texel(layer, x0, y0) * (1.0 - fx) + texel(layer, x1, y0) * fx;\n"
    "    vec4 bottom = texel(layer, x0, y1) * (1.0 - fx) + texel(layer, x1, y1) * fx;\n"
    "    return top * (1.0 - fy) + bottom * fy;\n"
    "}\n"
    /* the nearest quad of one ring hit by the ray; t stays 0 when none is */
    "vec4 ring(int first, vec3 ray, out float best) {\n"
    "    vec4 c = vec4(0.0);\n"
    "    best = 0.0;\n"
    "    for (int i = first; i < first + 8; ++i) {\n"
    "        if (size[i].x <= 0 || size[i].y <= 0) continue;\n"
    "        vec3 n = cross(du[i], dv[i]);\n"
    "        float denom = dot(ray, n);\n"
    "        if (denom == 0.0) continue;\n"
    "        float t = dot(tl[i], n) / denom;\n"
    "        if (!(t > 0.0) || (best > 0.0 && !(t < best))) continue;\n"
    "        vec3 p = ray * t - tl[i];\n"
    "        float a = dot(p, du[i]) / dot(du[i], du[i]);\n"
    "        float b = dot(p, dv[i]) / dot(dv[i], dv[i]);\n"
    "        if (a < 0.0 || a > 1.0 || b < 0.0 || b > 1.0) continue;\n"
    "        c = bilinear(i, a, b);\n"
    "        best = t;\n"
    "    }\n"
    "    return c;\n"
    "}\n"
    "void main() {\n"
    "    vec2 ndc = (gl_FragCoord.xy - viewport.xy) / viewport.zw * 2.0 - 1.0;\n"
    "    vec4 far = inv_vp * vec4(ndc, 1.0, 1.0);\n"
    "    vec3 ray = far.xyz / far.w;\n"
    "    float t0, t1 = 0.0;\n"
    "    vec4 c = ring(0, ray, t0);\n"
    "    if (count > 8) {\n"
    "        vec4 c1 = ring(8, ray, t1);\n"
    "        c = (1.0 - fade) * c + fade * c1;\n"
    "    }\n"
    "    float t = t0 > 0.0 && t1 > 0.0 ? min(t0, t1) : max(t0, t1);\n"
    "    if (!(t > 0.0)) discard;\n"
    "    vec4 clip = vp * vec4(ray * t, 1.0);\n"
    "    gl_FragDepth = clamp(clip.z / clip.w * 0.5 + 0.5, 0.0, 1.0);\n"
    "    colour = c;\n"
    "}\n";

static GLuint compile(wxsky_gl_compositor *c, GLenum type, const char *body, const char *what) {
    const char *src[2] = {WXSKY_GLSL_HEADER, body};
    GLuint s = glCreateShader(type);
    GLint status = 0;
    if (!s) {
        fail(c, WXSKY_ESYS, "glCreateShader failed for the %s shader", what);
        return 0;
    }
    glShaderSource(s, 2, src, NULL);
    glCompileShader(s);
    glGetShaderiv(s, GL_COMPILE_STATUS, &status);
    if (!status) {
        char log[160];
        GLsizei n = 0;
        glGetShaderInfoLog(s, (GLsizei)sizeof log, &n, log);
        for (GLsizei i = 0; i < n; ++i)
            if (log[i] == '\n' || log[i] == '\r')
                log[i] = ' ';
        fail(c, WXSKY_ESYS, "the %s shader does not compile: %.*s", what, (int)n, log);
        glDeleteShader(s);
        return 0;
    }
    return s;
}

static GLuint link_program(wxsky_gl_compositor *c, const char *fs_body, const char *what) {
    GLuint vs = compile(c, GL_VERTEX_SHADER, VS_FULLSCREEN, "full-screen vertex");
    GLuint fs = vs ? compile(c, GL_FRAGMENT_SHADER, fs_body, what) : 0;
    GLuint p = 0;
    GLint status = 0;
    if (vs && fs) {
        p = glCreateProgram();
        glAttachShader(p, vs);
        glAttachShader(p, fs);
        glLinkProgram(p);
        glGetProgramiv(p, GL_LINK_STATUS, &status);
        if (!status) {
            char log[160];
            GLsizei n = 0;
            glGetProgramInfoLog(p, (GLsizei)sizeof log, &n, log);
            for (GLsizei i = 0; i < n; ++i)
                if (log[i] == '\n' || log[i] == '\r')
                    log[i] = ' ';
            fail(c, WXSKY_ESYS, "the %s program does not link: %.*s", what, (int)n, log);
            glDeleteProgram(p);
            p = 0;
        }
    }
    if (vs)
        glDeleteShader(vs);
    if (fs)
        glDeleteShader(fs);
    return p;
}

/* ---- lifetime ------------------------------------------------------------------------ */

static void reset_indices(wxsky_gl_compositor *c) {
    for (int i = 0; i < FS_COUNT; ++i)
        c->fs_index[i] = -1;
    for (int i = 0; i < RING_LAYERS; ++i)
        c->ring_index[i] = -1;
}

wxsky_gl_compositor *wxsky_gl_new(void) {
    wxsky_gl_compositor *c = calloc(1, sizeof *c);
    if (c)
        reset_indices(c);
    return c;
}

static void delete_pbos(wxsky_gl_compositor *c) {
    for (int i = 0; i < FS_COUNT; ++i)
        if (c->fs_pbo[i]) {
            glDeleteBuffers(1, &c->fs_pbo[i]);
            c->fs_pbo[i] = 0;
        }
}

/* One pixel-unpack buffer per full-screen layer, at its capacity. */
static void make_pbos(wxsky_gl_compositor *c) {
    for (int i = 0; i < FS_COUNT; ++i) {
        if (c->fs_index[i] < 0 || c->fs_pbo[i])
            continue;
        glGenBuffers(1, &c->fs_pbo[i]);
        glBindBuffer(GL_PIXEL_UNPACK_BUFFER, c->fs_pbo[i]);
        glBufferData(GL_PIXEL_UNPACK_BUFFER, (GLsizeiptr)c->fs_cap_w[i] * c->fs_cap_h[i] * 4, NULL,
                     GL_STREAM_DRAW);
    }
    glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
}

static void release(wxsky_gl_compositor *c) {
    if (c->fs_prog)
        glDeleteProgram(c->fs_prog);
    if (c->ring_prog)
        glDeleteProgram(c->ring_prog);
    if (c->vao)
        glDeleteVertexArrays(1, &c->vao);
    for (int i = 0; i < FS_COUNT; ++i)
        if (c->fs_tex[i])
            glDeleteTextures(1, &c->fs_tex[i]);
    if (c->ring_tex)
        glDeleteTextures(1, &c->ring_tex);
    delete_pbos(c);
    c->fs_prog = c->ring_prog = c->vao = c->ring_tex = 0;
    memset(c->fs_tex, 0, sizeof c->fs_tex);
    c->ready = c->have_frame = c->rings_valid = 0;
    reset_indices(c);
}

void wxsky_gl_free(wxsky_gl_compositor *comp) {
    if (!comp)
        return;
    release(comp);
    free(comp);
}

const char *wxsky_gl_error(const wxsky_gl_compositor *comp) {
    return comp ? comp->error : "no compositor";
}

static void tex_params(GLenum target, GLint filter) {
    glTexParameteri(target, GL_TEXTURE_MIN_FILTER, filter);
    glTexParameteri(target, GL_TEXTURE_MAG_FILTER, filter);
    glTexParameteri(target, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(target, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
}

int wxsky_gl_init(wxsky_gl_compositor *c, const wxsky_segment *seg) {
    static const char *const FS_NAMES[FS_COUNT] = {"sky", "near", "near_front"};
    wxsky_layer_info info;
    GLint max_size = 0, max_layers = 0;
    int st;
    if (!c)
        return WXSKY_EINVAL;
    if (!seg || wxsky_segment_layer_count(seg) == 0)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_init: no open segment");
    release(c);
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_size);
    glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);

    for (int i = 0; i < FS_COUNT; ++i) {
        int k = wxsky_segment_find_layer(seg, FS_NAMES[i]);
        if (k < 0) {
            if (i == FS_FRONT)
                continue;
            return fail(c, WXSKY_EFORMAT, "the segment has no layer '%s'", FS_NAMES[i]);
        }
        wxsky_segment_layer(seg, (uint32_t)k, &info);
        if (info.max_width == 0 || info.max_height == 0 || info.max_width > (uint32_t)max_size ||
            info.max_height > (uint32_t)max_size)
            return fail(c, WXSKY_EFORMAT, "layer '%s' capacity %ux%u outside 1..%d (GL_MAX_TEXTURE_SIZE)",
                        FS_NAMES[i], info.max_width, info.max_height, (int)max_size);
        c->fs_index[i] = k;
        c->fs_cap_w[i] = info.max_width;
        c->fs_cap_h[i] = info.max_height;
    }
    for (int i = 0; i < RING_LAYERS; ++i) {
        char name[WXSKY_LAYER_NAME_MAX + 1];
        int k;
        snprintf(name, sizeof name, i < RING_QUADS ? "ring_%d" : "ring_in_%d", i % RING_QUADS);
        k = wxsky_segment_find_layer(seg, name);
        if (k < 0) {
            if (i >= RING_QUADS)
                continue;
            reset_indices(c);
            return fail(c, WXSKY_EFORMAT, "the segment has no layer '%s'", name);
        }
        wxsky_segment_layer(seg, (uint32_t)k, &info);
        if (i == 0) {
            c->ring_cap_w = info.max_width;
            c->ring_cap_h = info.max_height;
        } else if (info.max_width != c->ring_cap_w || info.max_height != c->ring_cap_h) {
            reset_indices(c);
            return fail(c, WXSKY_EFORMAT, "layer '%s' capacity %ux%u differs from ring_0's %ux%u",
                        name, info.max_width, info.max_height, c->ring_cap_w, c->ring_cap_h);
        }
        c->ring_index[i] = k;
    }
    if (c->ring_cap_w == 0 || c->ring_cap_h == 0 || c->ring_cap_w > (uint32_t)max_size ||
        c->ring_cap_h > (uint32_t)max_size || max_layers < RING_LAYERS) {
        uint32_t w = c->ring_cap_w, h = c->ring_cap_h;
        reset_indices(c);
        return fail(c, WXSKY_EFORMAT, "ring capacity %ux%u x %d layers beyond this GL (%d, %d)",
                    w, h, RING_LAYERS, (int)max_size, (int)max_layers);
    }

    c->fs_prog = link_program(c, FS_LAYER, "full-screen layer");
    c->ring_prog = c->fs_prog ? link_program(c, FS_RING, "ring") : 0;
    if (!c->ring_prog) {
        release(c);
        return WXSKY_ESYS; /* message set by link_program */
    }
    c->u_fs_tex = glGetUniformLocation(c->fs_prog, "tex");
    c->u_fs_size = glGetUniformLocation(c->fs_prog, "size");
    c->u_fs_cap = glGetUniformLocation(c->fs_prog, "cap");
    c->u_fs_viewport = glGetUniformLocation(c->fs_prog, "viewport");
    c->u_fs_flip = glGetUniformLocation(c->fs_prog, "flip");
    c->u_ring_tex = glGetUniformLocation(c->ring_prog, "tex");
    c->u_ring_size = glGetUniformLocation(c->ring_prog, "size");
    c->u_ring_tl = glGetUniformLocation(c->ring_prog, "tl");
    c->u_ring_u = glGetUniformLocation(c->ring_prog, "du");
    c->u_ring_v = glGetUniformLocation(c->ring_prog, "dv");
    c->u_ring_inv = glGetUniformLocation(c->ring_prog, "inv_vp");
    c->u_ring_vp = glGetUniformLocation(c->ring_prog, "vp");
    c->u_ring_viewport = glGetUniformLocation(c->ring_prog, "viewport");
    c->u_ring_count = glGetUniformLocation(c->ring_prog, "count");
    c->u_ring_fade = glGetUniformLocation(c->ring_prog, "fade");

    glGenVertexArrays(1, &c->vao);
    glActiveTexture(GL_TEXTURE0);
    for (int i = 0; i < FS_COUNT; ++i) {
        if (c->fs_index[i] < 0)
            continue;
        glGenTextures(1, &c->fs_tex[i]);
        glBindTexture(GL_TEXTURE_2D, c->fs_tex[i]);
        tex_params(GL_TEXTURE_2D, GL_LINEAR);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, (GLsizei)c->fs_cap_w[i], (GLsizei)c->fs_cap_h[i],
                     0, GL_RGBA, GL_UNSIGNED_BYTE, NULL);
    }
    if (c->pbo)
        make_pbos(c);
    glGenTextures(1, &c->ring_tex);
    glBindTexture(GL_TEXTURE_2D_ARRAY, c->ring_tex);
    tex_params(GL_TEXTURE_2D_ARRAY, GL_NEAREST);
    glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, GL_RGBA8, (GLsizei)c->ring_cap_w, (GLsizei)c->ring_cap_h,
                 RING_LAYERS, 0, GL_RGBA, GL_UNSIGNED_BYTE, NULL);
    st = gl_check(c, "wxsky_gl_init (making textures)");
    if (st != WXSKY_OK) {
        char msg[WXSKY_ERROR_MAX];
        memcpy(msg, c->error, sizeof msg);
        release(c);
        memcpy(c->error, msg, sizeof msg);
        return st;
    }
    c->ready = 1;
    return ok(c);
}

/* ---- upload -------------------------------------------------------------------------- */

static void unpack_state(void) {
    glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
    glPixelStorei(GL_UNPACK_ALIGNMENT, 4);
    glPixelStorei(GL_UNPACK_ROW_LENGTH, 0);
    glPixelStorei(GL_UNPACK_SKIP_ROWS, 0);
    glPixelStorei(GL_UNPACK_SKIP_PIXELS, 0);
    glPixelStorei(GL_UNPACK_IMAGE_HEIGHT, 0);
    glPixelStorei(GL_UNPACK_SKIP_IMAGES, 0);
}

/* One upload from per-layer-index pointers and sizes (pixels NULL: not given). */
static int upload(wxsky_gl_compositor *c, const uint8_t *const *pixels, const uint32_t *width,
                  const uint32_t *height, uint32_t count, const wxsky_record *rec) {
    int rings;
    if (!c)
        return WXSKY_EINVAL;
    if (!c->ready)
        return fail(c, WXSKY_EINVAL, "wxsky_gl upload: the compositor is not initialised");
    if (!rec)
        return fail(c, WXSKY_EINVAL, "wxsky_gl upload: no record");
    unpack_state();
    glActiveTexture(GL_TEXTURE0);
    for (int i = 0; i < FS_COUNT; ++i) {
        int k = c->fs_index[i];
        if (k < 0 || (uint32_t)k >= count) {
            c->fs_w[i] = c->fs_h[i] = 0;
            continue;
        }
        if (width[k] > c->fs_cap_w[i] || height[k] > c->fs_cap_h[i])
            return fail(c, WXSKY_EINVAL, "layer %d is %ux%u, beyond its capacity %ux%u", k,
                        width[k], height[k], c->fs_cap_w[i], c->fs_cap_h[i]);
        if (!pixels[k])
            continue;
        c->fs_w[i] = width[k];
        c->fs_h[i] = height[k];
        if (width[k] == 0 || height[k] == 0)
            continue;
        glBindTexture(GL_TEXTURE_2D, c->fs_tex[i]);
        if (c->pbo && c->fs_pbo[i]) {
            /* orphan the buffer's last storage (the GPU may still read it), copy, and let the
             * driver take the texture update from the buffer asynchronously */
            GLsizeiptr full = (GLsizeiptr)c->fs_cap_w[i] * c->fs_cap_h[i] * 4;
            size_t bytes = (size_t)width[k] * height[k] * 4;
            void *dst;
            glBindBuffer(GL_PIXEL_UNPACK_BUFFER, c->fs_pbo[i]);
            glBufferData(GL_PIXEL_UNPACK_BUFFER, full, NULL, GL_STREAM_DRAW);
            dst = glMapBufferRange(GL_PIXEL_UNPACK_BUFFER, 0, (GLsizeiptr)bytes,
                                   GL_MAP_WRITE_BIT | GL_MAP_INVALIDATE_BUFFER_BIT);
            if (!dst) {
                glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
                (void)gl_check(c, "wxsky_gl upload (mapping a pixel buffer)");
                return fail(c, WXSKY_ESYS, "wxsky_gl upload: glMapBufferRange failed for layer %d",
                            k);
            }
            memcpy(dst, pixels[k], bytes);
            glUnmapBuffer(GL_PIXEL_UNPACK_BUFFER);
            glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, (GLsizei)width[k], (GLsizei)height[k],
                            GL_RGBA, GL_UNSIGNED_BYTE, (const void *)0);
            glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
        } else {
            glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, (GLsizei)width[k], (GLsizei)height[k],
                            GL_RGBA, GL_UNSIGNED_BYTE, pixels[k]);
        }
    }
    rings = !c->rings_valid || rec->ring_version != c->ring_version;
    if (rings) {
        glBindTexture(GL_TEXTURE_2D_ARRAY, c->ring_tex);
        for (int i = 0; i < RING_LAYERS; ++i) {
            int k = c->ring_index[i];
            uint32_t w = 0, h = 0;
            if (k >= 0 && (uint32_t)k < count && (i < RING_QUADS || rec->fading)) {
                w = width[k];
                h = height[k];
                if (w > c->ring_cap_w || h > c->ring_cap_h)
                    return fail(c, WXSKY_EINVAL, "layer %d is %ux%u, beyond its capacity %ux%u",
                                k, w, h, c->ring_cap_w, c->ring_cap_h);
                if (!pixels[k]) {
                    /* not given: keep what the texture had */
                    continue;
                }
                if (w && h)
                    glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, i, (GLsizei)w, (GLsizei)h, 1,
                                    GL_RGBA, GL_UNSIGNED_BYTE, pixels[k]);
            }
            c->ring_size[2 * i] = (int32_t)(w && h ? w : 0);
            c->ring_size[2 * i + 1] = (int32_t)(w && h ? h : 0);
        }
        c->ring_version = rec->ring_version;
        c->rings_valid = 1;
    }
    c->rec = *rec;
    {
        int st = gl_check(c, "wxsky_gl upload");
        if (st != WXSKY_OK) {
            c->rings_valid = 0;
            return st;
        }
    }
    c->have_frame = 1;
    return ok(c);
}

int wxsky_gl_upload_copy(wxsky_gl_compositor *c, const wxsky_frame_copy *copy,
                         const wxsky_record *rec) {
    const uint8_t *pixels[WXSKY_MAX_LAYERS];
    if (!c)
        return WXSKY_EINVAL;
    if (!copy)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_upload_copy: no copy");
    for (int i = 0; i < WXSKY_MAX_LAYERS; ++i)
        pixels[i] = copy->pixels[i];
    return upload(c, pixels, copy->width, copy->height, WXSKY_MAX_LAYERS, rec);
}

int wxsky_gl_upload_view(wxsky_gl_compositor *c, const wxsky_frame_view *view,
                         const wxsky_record *rec) {
    const uint8_t *pixels[WXSKY_MAX_LAYERS];
    uint32_t width[WXSKY_MAX_LAYERS], height[WXSKY_MAX_LAYERS];
    uint32_t n;
    if (!c)
        return WXSKY_EINVAL;
    if (!view)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_upload_view: no view");
    n = view->layer_count > WXSKY_MAX_LAYERS ? WXSKY_MAX_LAYERS : view->layer_count;
    for (uint32_t i = 0; i < n; ++i) {
        width[i] = view->layers[i].width;
        height[i] = view->layers[i].height;
        /* an absent layer has no pointer: still "given", as width 0 */
        pixels[i] = view->layers[i].pixels ? view->layers[i].pixels : (const uint8_t *)"";
    }
    return upload(c, pixels, width, height, n, rec);
}

int wxsky_gl_set_streaming(wxsky_gl_compositor *c, int pbo) {
    if (!c)
        return WXSKY_EINVAL;
    c->pbo = pbo != 0;
    if (c->ready) {
        if (c->pbo)
            make_pbos(c);
        else
            delete_pbos(c);
        return gl_check(c, "wxsky_gl_set_streaming") == WXSKY_OK ? ok(c) : WXSKY_ESYS;
    }
    return ok(c);
}

void wxsky_gl_invalidate(wxsky_gl_compositor *c) {
    if (c)
        c->rings_valid = 0;
}

/* ---- matrices ------------------------------------------------------------------------ */

/* r = a * b, column-major 4x4 */
static void mat_mul(const double *a, const double *b, double *r) {
    for (int col = 0; col < 4; ++col)
        for (int row = 0; row < 4; ++row) {
            double s = 0.0;
            for (int k = 0; k < 4; ++k)
                s += a[k * 4 + row] * b[col * 4 + k];
            r[col * 4 + row] = s;
        }
}

/* The inverse (any layout: inverse commutes with transposition); 0 when singular. */
static int mat_inverse(const double *m, double *out) {
    double inv[16], det;
    inv[0] = m[5] * m[10] * m[15] - m[5] * m[11] * m[14] - m[9] * m[6] * m[15] +
             m[9] * m[7] * m[14] + m[13] * m[6] * m[11] - m[13] * m[7] * m[10];
    inv[4] = -m[4] * m[10] * m[15] + m[4] * m[11] * m[14] + m[8] * m[6] * m[15] -
             m[8] * m[7] * m[14] - m[12] * m[6] * m[11] + m[12] * m[7] * m[10];
    inv[8] = m[4] * m[9] * m[15] - m[4] * m[11] * m[13] - m[8] * m[5] * m[15] +
             m[8] * m[7] * m[13] + m[12] * m[5] * m[11] - m[12] * m[7] * m[9];
    inv[12] = -m[4] * m[9] * m[14] + m[4] * m[10] * m[13] + m[8] * m[5] * m[14] -
              m[8] * m[6] * m[13] - m[12] * m[5] * m[10] + m[12] * m[6] * m[9];
    inv[1] = -m[1] * m[10] * m[15] + m[1] * m[11] * m[14] + m[9] * m[2] * m[15] -
             m[9] * m[3] * m[14] - m[13] * m[2] * m[11] + m[13] * m[3] * m[10];
    inv[5] = m[0] * m[10] * m[15] - m[0] * m[11] * m[14] - m[8] * m[2] * m[15] +
             m[8] * m[3] * m[14] + m[12] * m[2] * m[11] - m[12] * m[3] * m[10];
    inv[9] = -m[0] * m[9] * m[15] + m[0] * m[11] * m[13] + m[8] * m[1] * m[15] -
             m[8] * m[3] * m[13] - m[12] * m[1] * m[11] + m[12] * m[3] * m[9];
    inv[13] = m[0] * m[9] * m[14] - m[0] * m[10] * m[13] - m[8] * m[1] * m[14] +
              m[8] * m[2] * m[13] + m[12] * m[1] * m[10] - m[12] * m[2] * m[9];
    inv[2] = m[1] * m[6] * m[15] - m[1] * m[7] * m[14] - m[5] * m[2] * m[15] +
             m[5] * m[3] * m[14] + m[13] * m[2] * m[7] - m[13] * m[3] * m[6];
    inv[6] = -m[0] * m[6] * m[15] + m[0] * m[7] * m[14] + m[4] * m[2] * m[15] -
             m[4] * m[3] * m[14] - m[12] * m[2] * m[7] + m[12] * m[3] * m[6];
    inv[10] = m[0] * m[5] * m[15] - m[0] * m[7] * m[13] - m[4] * m[1] * m[15] +
              m[4] * m[3] * m[13] + m[12] * m[1] * m[7] - m[12] * m[3] * m[5];
    inv[14] = -m[0] * m[5] * m[14] + m[0] * m[6] * m[13] + m[4] * m[1] * m[14] -
              m[4] * m[2] * m[13] - m[12] * m[1] * m[6] + m[12] * m[2] * m[5];
    inv[3] = -m[1] * m[6] * m[11] + m[1] * m[7] * m[10] + m[5] * m[2] * m[11] -
             m[5] * m[3] * m[10] - m[9] * m[2] * m[7] + m[9] * m[3] * m[6];
    inv[7] = m[0] * m[6] * m[11] - m[0] * m[7] * m[10] - m[4] * m[2] * m[11] +
             m[4] * m[3] * m[10] + m[8] * m[2] * m[7] - m[8] * m[3] * m[6];
    inv[11] = -m[0] * m[5] * m[11] + m[0] * m[7] * m[9] + m[4] * m[1] * m[11] -
              m[4] * m[3] * m[9] - m[8] * m[1] * m[7] + m[8] * m[3] * m[5];
    inv[15] = m[0] * m[5] * m[10] - m[0] * m[6] * m[9] - m[4] * m[1] * m[10] +
              m[4] * m[2] * m[9] + m[8] * m[1] * m[6] - m[8] * m[2] * m[5];
    det = m[0] * inv[0] + m[1] * inv[4] + m[2] * inv[8] + m[3] * inv[12];
    if (!(det != 0.0) || !isfinite(det))
        return 0;
    for (int i = 0; i < 16; ++i)
        out[i] = inv[i] / det;
    return 1;
}

void wxsky_gl_camera_matrices(const wxsky_record *rec, int flip_y, double view[16],
                              double proj[16]) {
    const double d2r = 3.14159265358979323846 / 180.0;
    double h = rec->heading_deg * d2r, p = rec->pitch_deg * d2r, r = rec->roll_deg * d2r;
    double fwd[3] = {sin(h) * cos(p), cos(h) * cos(p), sin(p)};
    double right0[3] = {cos(h), -sin(h), 0.0};
    /* up0 = right0 x fwd */
    double up0[3] = {right0[1] * fwd[2] - right0[2] * fwd[1], right0[2] * fwd[0] - right0[0] * fwd[2],
                     right0[0] * fwd[1] - right0[1] * fwd[0]};
    double right[3], up[3], rows[3][3];
    const double *eye = rec->position_m;
    double tx = tan(rec->fov_deg * d2r / 2.0);
    double ty = rec->width_px ? tx * (double)rec->height_px / (double)rec->width_px : tx;
    double n = WXSKY_GL_NEAR_M, f = WXSKY_GL_FAR_M;
    double l = -tx * n, rt = tx * n, b = -ty * n, t = ty * n;
    for (int i = 0; i < 3; ++i) {
        right[i] = right0[i] * cos(r) - up0[i] * sin(r);
        up[i] = up0[i] * cos(r) + right0[i] * sin(r);
    }
    for (int i = 0; i < 3; ++i) {
        rows[0][i] = right[i];
        rows[1][i] = up[i];
        rows[2][i] = -fwd[i];
    }
    memset(view, 0, 16 * sizeof *view);
    for (int row = 0; row < 3; ++row) {
        for (int col = 0; col < 3; ++col)
            view[col * 4 + row] = rows[row][col];
        view[12 + row] = -(rows[row][0] * eye[0] + rows[row][1] * eye[1] + rows[row][2] * eye[2]);
    }
    view[15] = 1.0;
    memset(proj, 0, 16 * sizeof *proj);
    proj[0] = 2 * n / (rt - l);
    proj[8] = (rt + l) / (rt - l);
    proj[5] = 2 * n / (t - b);
    proj[9] = (t + b) / (t - b);
    proj[10] = -(f + n) / (f - n);
    proj[14] = -2 * f * n / (f - n);
    proj[11] = -1.0;
    if (flip_y) {
        proj[1] = -proj[1];
        proj[5] = -proj[5];
        proj[9] = -proj[9];
        proj[13] = -proj[13];
    }
}

/* ---- draws --------------------------------------------------------------------------- */

static void blend_state(int depth_test) {
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFunc(GL_ONE, GL_ONE_MINUS_SRC_ALPHA);
    glDepthMask(GL_FALSE);
    glDisable(GL_CULL_FACE);
    if (depth_test) {
        glEnable(GL_DEPTH_TEST);
        glDepthFunc(GL_LEQUAL);
    } else {
        glDisable(GL_DEPTH_TEST);
    }
}

static void draw_fullscreen(wxsky_gl_compositor *c, int which, const GLint *vp) {
    glUseProgram(c->fs_prog);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, c->fs_tex[which]);
    glUniform1i(c->u_fs_tex, 0);
    glUniform2i(c->u_fs_size, (GLint)c->fs_w[which], (GLint)c->fs_h[which]);
    glUniform2f(c->u_fs_cap, (GLfloat)c->fs_cap_w[which], (GLfloat)c->fs_cap_h[which]);
    glUniform4f(c->u_fs_viewport, (GLfloat)vp[0], (GLfloat)vp[1], (GLfloat)vp[2], (GLfloat)vp[3]);
    glUniform1i(c->u_fs_flip, c->flip);
    glBindVertexArray(c->vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
}

static int check_drawable(wxsky_gl_compositor *c, const char *what) {
    if (!c->ready)
        return fail(c, WXSKY_EINVAL, "%s: the compositor is not initialised", what);
    if (!c->have_frame)
        return fail(c, WXSKY_EINVAL, "%s: no frame uploaded", what);
    return WXSKY_OK;
}

int wxsky_gl_draw_background(wxsky_gl_compositor *c, const double view[16],
                             const double proj[16]) {
    double about_eye[16], vp[16], inv[16], eye[3];
    GLfloat vpf[16], invf[16];
    GLint viewport[4];
    int st, count;
    if (!c)
        return WXSKY_EINVAL;
    if ((st = check_drawable(c, "wxsky_gl_draw_background")) != WXSKY_OK)
        return st;
    if (!view || !proj)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_draw_background: no matrices");
    for (int i = 0; i < 16; ++i)
        if (!isfinite(view[i]) || !isfinite(proj[i]))
            return fail(c, WXSKY_EINVAL, "wxsky_gl_draw_background: a matrix is not finite");
    /* the eye: view maps it to the origin, so it is the inverse's translation */
    if (!mat_inverse(view, inv))
        return fail(c, WXSKY_EINVAL, "wxsky_gl_draw_background: the view matrix is singular");
    eye[0] = inv[12] / inv[15];
    eye[1] = inv[13] / inv[15];
    eye[2] = inv[14] / inv[15];
    /* view about the eye: view x translate(eye) */
    memcpy(about_eye, view, sizeof about_eye);
    for (int row = 0; row < 4; ++row)
        about_eye[12 + row] = view[row] * eye[0] + view[4 + row] * eye[1] +
                              view[8 + row] * eye[2] + view[12 + row];
    mat_mul(proj, about_eye, vp);
    if (!mat_inverse(vp, inv))
        return fail(c, WXSKY_EINVAL, "wxsky_gl_draw_background: projection x view is singular");
    for (int i = 0; i < 16; ++i) {
        vpf[i] = (GLfloat)vp[i];
        invf[i] = (GLfloat)inv[i];
    }
    c->flip = proj[5] < 0.0;
    count = c->rec.fading && c->rec.ring_fade > 0.0 ? RING_LAYERS : RING_QUADS;
    for (int i = 0; i < RING_LAYERS; ++i) {
        const double(*q)[3] = i < RING_QUADS ? c->rec.ring_quads_m[i]
                                             : c->rec.ring_in_quads_m[i - RING_QUADS];
        for (int k = 0; k < 3; ++k) {
            c->tl[3 * i + k] = (GLfloat)(q[0][k] - eye[k]);
            c->du[3 * i + k] = (GLfloat)(q[1][k] - q[0][k]);
            c->dv[3 * i + k] = (GLfloat)(q[3][k] - q[0][k]);
        }
    }

    glGetIntegerv(GL_VIEWPORT, viewport);
    blend_state(1);
    if (c->fs_w[FS_SKY] && c->fs_h[FS_SKY])
        draw_fullscreen(c, FS_SKY, viewport);

    glUseProgram(c->ring_prog);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D_ARRAY, c->ring_tex);
    glUniform1i(c->u_ring_tex, 1);
    glUniform2iv(c->u_ring_size, RING_LAYERS, c->ring_size);
    glUniform3fv(c->u_ring_tl, RING_LAYERS, c->tl);
    glUniform3fv(c->u_ring_u, RING_LAYERS, c->du);
    glUniform3fv(c->u_ring_v, RING_LAYERS, c->dv);
    glUniformMatrix4fv(c->u_ring_inv, 1, GL_FALSE, invf);
    glUniformMatrix4fv(c->u_ring_vp, 1, GL_FALSE, vpf);
    glUniform4f(c->u_ring_viewport, (GLfloat)viewport[0], (GLfloat)viewport[1],
                (GLfloat)viewport[2], (GLfloat)viewport[3]);
    glUniform1i(c->u_ring_count, count);
    glUniform1f(c->u_ring_fade, (GLfloat)c->rec.ring_fade);
    glBindVertexArray(c->vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glActiveTexture(GL_TEXTURE0);
    if ((st = gl_check(c, "wxsky_gl_draw_background")) != WXSKY_OK)
        return st;
    return ok(c);
}

static int draw_layer(wxsky_gl_compositor *c, int which, const char *what) {
    GLint viewport[4];
    int st;
    if (!c)
        return WXSKY_EINVAL;
    if ((st = check_drawable(c, what)) != WXSKY_OK)
        return st;
    if (!c->fs_w[which] || !c->fs_h[which])
        return ok(c);
    glGetIntegerv(GL_VIEWPORT, viewport);
    blend_state(0);
    draw_fullscreen(c, which, viewport);
    if ((st = gl_check(c, what)) != WXSKY_OK)
        return st;
    return ok(c);
}

int wxsky_gl_draw_near(wxsky_gl_compositor *c) {
    return draw_layer(c, FS_NEAR, "wxsky_gl_draw_near");
}

int wxsky_gl_draw_near_front(wxsky_gl_compositor *c) {
    return draw_layer(c, FS_FRONT, "wxsky_gl_draw_near_front");
}
