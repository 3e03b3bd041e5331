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
 * float precision.
 *
 * The cloud-shadow map (`shadow`, protocol §3.3) is not drawn: it gets a texture of its own,
 * uploaded when the record's shadow_version changes, for the host's terrain shader
 * (wxsky_gl_shadow, wxsky_gl_shadow_bind, WXSKY_GL_SHADOW_GLSL).
 *
 * HDR layers (a segment whose picture layers are RGBA16F, protocol §1.2): the textures are
 * GL_RGBA16F, uploaded as GL_HALF_FLOAT, and the same draws composite scene-linear colour
 * into the host's (float) framebuffer; wxsky_gl_tone_map then shows that composite through
 * the daemon's exposure and tone map once (WXSKY_GL_DISPLAY_GLSL). */
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

    /* the picture layers' format (all alike): WXSKY_FORMAT_RGBA8 or WXSKY_FORMAT_RGBA16F, and
     * its texture format, upload type and bytes a pixel */
    uint32_t format;
    GLint tex_internal;
    GLenum tex_type;
    uint32_t bpp;

    /* segment layer indices (-1: absent) and capacities */
    int fs_index[FS_COUNT];
    uint32_t fs_cap_w[FS_COUNT], fs_cap_h[FS_COUNT];
    uint32_t fs_w[FS_COUNT], fs_h[FS_COUNT]; /* as uploaded; 0: not drawn */
    int ring_index[RING_LAYERS];
    uint32_t ring_cap_w, ring_cap_h;
    int32_t ring_size[RING_LAYERS * 2]; /* as uploaded: width, height */

    /* the cloud-shadow map: segment layer index (-1: absent), capacity, texture, and what
     * the last upload left in it (w 0: the frame has no map) */
    int shadow_index;
    uint32_t shadow_cap_w, shadow_cap_h;
    uint32_t shadow_w, shadow_h;
    int shadow_valid;
    uint64_t shadow_version;
    GLuint shadow_tex;

    wxsky_record rec;

    int pbo; /* stream the full-screen layers through pixel-unpack buffers */
    GLuint fs_pbo[FS_COUNT];
    GLuint fs_tex[FS_COUNT];
    GLuint ring_tex;
    GLuint vao;
    GLuint fs_prog, ring_prog;
    GLuint tm_prog; /* wxsky_gl_tone_map's, made at its first call */
    GLint u_tm_tex, u_tm_exposure, u_tm_viewport;
    /* full-screen program uniforms */
    GLint u_fs_tex, u_fs_size, u_fs_cap, u_fs_viewport, u_fs_flip, u_fs_z;
    /* the near layer's depth (`near_depth`, optional): segment index (-1: absent), capacity,
     * size as uploaded (0: none this frame), texture, and the program drawing `near` by it */
    int depth_index;
    uint32_t depth_cap_w, depth_cap_h, depth_w, depth_h;
    GLuint depth_tex, depth_prog;
    GLint u_d_tex, u_d_size, u_d_cap, u_d_viewport, u_d_flip, u_d_depth, u_d_depth_size,
        u_d_inv_proj, u_d_proj, u_d_fallback;
    double proj[16]; /* the last background draw's projection (wxsky_gl_draw_near_at) */
    /* ring program uniforms */
    GLint u_ring_tex, u_ring_size, u_ring_tl, u_ring_u, u_ring_v, u_ring_inv, u_ring_vp,
        u_ring_viewport, u_ring_count, u_ring_fade;
    GLfloat tl[RING_LAYERS * 3], du[RING_LAYERS * 3], dv[RING_LAYERS * 3];

    /* zero-copy (protocol §6, wxsky_gl_import_textures): the daemon's slot textures imported
     * as EGLImages, by segment slot and layer index (0: none), the read framebuffer the
     * per-frame copies read them through, and what destroys the images */
    int zc;
    GLuint zc_tex[2][WXSKY_MAX_LAYERS];
    void *zc_image[2][WXSKY_MAX_LAYERS];
    GLuint zc_fbo;
    void *zc_dpy;
    unsigned (*zc_destroy)(void *dpy, void *image);
};

static void release_imports(wxsky_gl_compositor *c);

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
    "uniform float far_z;\n" /* 0: the far plane; else the NDC depth (wxsky_gl_draw_near_at) */
    "void main() {\n"
    "    vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), float((gl_VertexID & 2) * 2 - 1));\n"
    "    ndc = p;\n"
    "    gl_Position = vec4(p, far_z == 0.0 ? 1.0 : far_z, 1.0);\n"
    "}\n";

/* A full-screen layer stretched over the viewport: texelFetch when the sizes agree (exact),
 * bilinear with clamped edges otherwise. layer_colour(v): v the fragment's place in the
 * viewport, 0..1 from its lower left corner. */
#define LAYER_COLOUR_GLSL                                                                   \
    "uniform sampler2D tex;\n"                                                              \
    "uniform ivec2 size;\n"   /* the layer's pixels this frame */                            \
    "uniform vec2 cap;\n"     /* the texture's size */                                       \
    "uniform vec4 viewport;\n"                                                              \
    "uniform int flip;\n"                                                                   \
    "vec2 layer_place(vec2 v) {\n" /* the layer's row order: its top row first */           \
    "    if (flip == 0) v.y = 1.0 - v.y;\n"                                                 \
    "    return v;\n"                                                                       \
    "}\n"                                                                                   \
    "vec4 layer_colour(vec2 v) {\n"                                                         \
    "    vec2 px = layer_place(v) * vec2(size);\n"                                          \
    "    if (ivec2(viewport.zw) == size)\n"                                                 \
    "        return texelFetch(tex, clamp(ivec2(px), ivec2(0), size - 1), 0);\n"            \
    "    px = clamp(px, vec2(0.5), vec2(size) - 0.5);\n"                                    \
    "    return texture(tex, px / cap);\n"                                                  \
    "}\n"

static const char FS_LAYER[] =
    LAYER_COLOUR_GLSL
    "out vec4 colour;\n"
    "void main() {\n"
    "    colour = layer_colour((gl_FragCoord.xy - viewport.xy) / viewport.zw);\n"
    "}\n";

/* `near` at the depth of its clouds: FS_LAYER's colour, and for depth the distance the
 * `near_depth` layer holds at the pixel (protocol §1.5): the farthest of the 4 texels a
 * bilinear read would take (along a ridge's skyline a texel straddles the crest: the nearer
 * cloud above it must not pull the farther one below over the terrain), or where none of them
 * holds one, the nearest of the 16 around (a cloud's soft edge takes its cloud's), placed along
 * the pixel's ray through the host's projection; where none is near, `fallback` (the NDC depth
 * of the frame's near_distance_m). */
static const char FS_NEAR_DEPTH[] =
    LAYER_COLOUR_GLSL
    "uniform sampler2D depth;\n"
    "uniform ivec2 depth_size;\n"
    "uniform mat4 inv_proj;\n"
    "uniform mat4 proj;\n"
    "uniform float fallback;\n"
    "out vec4 colour;\n"
    "float depth_q(ivec2 at) {\n" /* the texel's q (0..1), or -1 where it holds none */
    "    vec4 t = texelFetch(depth, clamp(at, ivec2(0), depth_size - 1), 0);\n"
    "    return t.a > 0.5 ? dot(floor(t.rgb * 255.0 + 0.5), vec3(65536.0, 256.0, 1.0)) / "
    "16777215.0 : -1.0;\n"
    "}\n"
    "void main() {\n"
    "    vec2 v = (gl_FragCoord.xy - viewport.xy) / viewport.zw;\n"
    "    colour = layer_colour(v);\n"
    "    if (!(colour.a > 0.0)) discard;\n"
    "    ivec2 at = ivec2(floor(layer_place(v) * vec2(depth_size) - 0.5));\n"
    "    float q = -1.0;\n"
    "    for (int k = 0; k < 4; ++k)\n"
    "        q = max(q, depth_q(at + ivec2(k & 1, k >> 1)));\n"
    "    if (q < 0.0) {\n"
    "        q = 2.0;\n"
    "        for (int dy = -1; dy <= 2; ++dy)\n"
    "            for (int dx = -1; dx <= 2; ++dx) {\n"
    "                float e = depth_q(at + ivec2(dx, dy));\n"
    "                if (e >= 0.0) q = min(q, e);\n"
    "            }\n"
    "    }\n"
    "    float z = fallback;\n"
    "    if (q <= 1.0) {\n"
    "        float d = exp2(q * 18.0) - 1.0;\n"
    "        vec4 e = inv_proj * vec4(v * 2.0 - 1.0, 1.0, 1.0);\n"
    "        vec4 clip = proj * vec4(normalize(e.xyz / e.w) * d, 1.0);\n"
    "        z = clip.w > 0.0 ? clamp(clip.z / clip.w, -1.0, 1.0) : -1.0;\n"
    "    }\n"
    "    gl_FragDepth = z * 0.5 + 0.5;\n"
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

/* wxsky_gl_tone_map: the host's linear composite through the daemon's display transform. */
static const char FS_TONE_MAP[] =
    WXSKY_GL_DISPLAY_GLSL
    "uniform sampler2D tex;\n"
    "uniform float exposure;\n"
    "uniform vec4 viewport;\n"
    "out vec4 colour;\n"
    "void main() {\n"
    "    ivec2 px = ivec2(gl_FragCoord.xy - viewport.xy);\n"
    "    colour = vec4(wxsky_display(texelFetch(tex, px, 0).rgb, exposure), 1.0);\n"
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
    c->shadow_index = -1;
    c->depth_index = -1;
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
        glBufferData(GL_PIXEL_UNPACK_BUFFER,
                     (GLsizeiptr)c->fs_cap_w[i] * c->fs_cap_h[i] * (GLsizeiptr)c->bpp, NULL,
                     GL_STREAM_DRAW);
    }
    glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
}

static void release(wxsky_gl_compositor *c) {
    release_imports(c);
    if (c->fs_prog)
        glDeleteProgram(c->fs_prog);
    if (c->ring_prog)
        glDeleteProgram(c->ring_prog);
    if (c->tm_prog)
        glDeleteProgram(c->tm_prog);
    c->tm_prog = 0;
    if (c->vao)
        glDeleteVertexArrays(1, &c->vao);
    for (int i = 0; i < FS_COUNT; ++i)
        if (c->fs_tex[i])
            glDeleteTextures(1, &c->fs_tex[i]);
    if (c->ring_tex)
        glDeleteTextures(1, &c->ring_tex);
    if (c->shadow_tex)
        glDeleteTextures(1, &c->shadow_tex);
    c->shadow_tex = 0;
    if (c->depth_tex)
        glDeleteTextures(1, &c->depth_tex);
    if (c->depth_prog)
        glDeleteProgram(c->depth_prog);
    c->depth_tex = c->depth_prog = 0;
    c->depth_w = c->depth_h = 0;
    c->shadow_valid = 0;
    c->shadow_w = c->shadow_h = 0;
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
        if (i == FS_SKY) {
            c->format = info.format;
        } else if (info.format != c->format) {
            reset_indices(c);
            return fail(c, WXSKY_EFORMAT, "layer '%s' has format %u, the sky's is %u: the picture "
                        "layers must share one", FS_NAMES[i], info.format, c->format);
        }
        c->fs_index[i] = k;
        c->fs_cap_w[i] = info.max_width;
        c->fs_cap_h[i] = info.max_height;
    }
    /* RGBA16F: scene-linear half floats, composited in linear (wxsky_gl_tone_map after) */
    c->tex_internal = c->format == WXSKY_FORMAT_RGBA16F ? GL_RGBA16F : GL_RGBA8;
    c->tex_type = c->format == WXSKY_FORMAT_RGBA16F ? GL_HALF_FLOAT : GL_UNSIGNED_BYTE;
    c->bpp = c->format == WXSKY_FORMAT_RGBA16F ? 8u : 4u;
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
        if (info.format != c->format) {
            reset_indices(c);
            return fail(c, WXSKY_EFORMAT, "layer '%s' has format %u, the sky's is %u: the picture "
                        "layers must share one", name, info.format, c->format);
        }
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

    {
        /* the shadow map: optional (a daemon with [scene] shadow_map_px 0 has none) */
        int k = wxsky_segment_find_layer(seg, "shadow");
        if (k >= 0) {
            wxsky_segment_layer(seg, (uint32_t)k, &info);
            if (info.format != WXSKY_FORMAT_RGBA8) {
                reset_indices(c);
                return fail(c, WXSKY_EFORMAT,
                            "layer 'shadow' has format %u: the shadow map is RGBA8 (a map of "
                            "transmittance, protocol section 1.5)", info.format);
            }
            if (info.max_width == 0 || info.max_height == 0 ||
                info.max_width > (uint32_t)max_size || info.max_height > (uint32_t)max_size) {
                reset_indices(c);
                return fail(c, WXSKY_EFORMAT,
                            "layer 'shadow' capacity %ux%u outside 1..%d (GL_MAX_TEXTURE_SIZE)",
                            info.max_width, info.max_height, (int)max_size);
            }
            c->shadow_index = k;
            c->shadow_cap_w = info.max_width;
            c->shadow_cap_h = info.max_height;
        }
    }

    {
        /* the near layer's depth: optional ([output] near_depth), RGBA8 (protocol §1.5) */
        int k = wxsky_segment_find_layer(seg, "near_depth");
        if (k >= 0) {
            wxsky_segment_layer(seg, (uint32_t)k, &info);
            if (info.format != WXSKY_FORMAT_RGBA8 || info.max_width == 0 ||
                info.max_height == 0 || info.max_width > (uint32_t)max_size ||
                info.max_height > (uint32_t)max_size) {
                reset_indices(c);
                return fail(c, WXSKY_EFORMAT,
                            "layer 'near_depth' has format %u and capacity %ux%u: it is RGBA8 "
                            "(protocol section 1.5), 1..%d each way",
                            info.format, info.max_width, info.max_height, (int)max_size);
            }
            c->depth_index = k;
            c->depth_cap_w = info.max_width;
            c->depth_cap_h = info.max_height;
        }
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
    c->u_fs_z = glGetUniformLocation(c->fs_prog, "far_z");
    if (c->depth_index >= 0) {
        c->depth_prog = link_program(c, FS_NEAR_DEPTH, "near by its depth");
        if (!c->depth_prog) {
            release(c);
            return WXSKY_ESYS;
        }
        c->u_d_tex = glGetUniformLocation(c->depth_prog, "tex");
        c->u_d_size = glGetUniformLocation(c->depth_prog, "size");
        c->u_d_cap = glGetUniformLocation(c->depth_prog, "cap");
        c->u_d_viewport = glGetUniformLocation(c->depth_prog, "viewport");
        c->u_d_flip = glGetUniformLocation(c->depth_prog, "flip");
        c->u_d_depth = glGetUniformLocation(c->depth_prog, "depth");
        c->u_d_depth_size = glGetUniformLocation(c->depth_prog, "depth_size");
        c->u_d_inv_proj = glGetUniformLocation(c->depth_prog, "inv_proj");
        c->u_d_proj = glGetUniformLocation(c->depth_prog, "proj");
        c->u_d_fallback = glGetUniformLocation(c->depth_prog, "fallback");
    }
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
        glTexImage2D(GL_TEXTURE_2D, 0, c->tex_internal, (GLsizei)c->fs_cap_w[i],
                     (GLsizei)c->fs_cap_h[i], 0, GL_RGBA, c->tex_type, NULL);
    }
    if (c->pbo)
        make_pbos(c);
    glGenTextures(1, &c->ring_tex);
    glBindTexture(GL_TEXTURE_2D_ARRAY, c->ring_tex);
    tex_params(GL_TEXTURE_2D_ARRAY, GL_NEAREST);
    glTexImage3D(GL_TEXTURE_2D_ARRAY, 0, c->tex_internal, (GLsizei)c->ring_cap_w,
                 (GLsizei)c->ring_cap_h, RING_LAYERS, 0, GL_RGBA, c->tex_type, NULL);
    if (c->depth_index >= 0) {
        glGenTextures(1, &c->depth_tex);
        glBindTexture(GL_TEXTURE_2D, c->depth_tex);
        tex_params(GL_TEXTURE_2D, GL_NEAREST);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, (GLsizei)c->depth_cap_w, (GLsizei)c->depth_cap_h,
                     0, GL_RGBA, GL_UNSIGNED_BYTE, NULL);
    }
    if (c->shadow_index >= 0) {
        /* LINEAR + CLAMP_TO_EDGE: the bilinear sampling protocol §3.3 asks for */
        glGenTextures(1, &c->shadow_tex);
        glBindTexture(GL_TEXTURE_2D, c->shadow_tex);
        tex_params(GL_TEXTURE_2D, GL_LINEAR);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA8, (GLsizei)c->shadow_cap_w,
                     (GLsizei)c->shadow_cap_h, 0, GL_RGBA, GL_UNSIGNED_BYTE, NULL);
    }
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

/* The shadow map of a frame: uploaded only when the record's shadow_version differs from the
 * last upload's (or after wxsky_gl_invalidate); a record without a map (version 0, or a
 * version 2 record) leaves none to sample. */
static int upload_shadow(wxsky_gl_compositor *c, const uint8_t *const *pixels,
                         const uint32_t *width, const uint32_t *height, uint32_t count,
                         const wxsky_record *rec) {
    int k = c->shadow_index;
    uint32_t w, h;
    if (k < 0 || (uint32_t)k >= count || rec->shadow_version == 0) {
        c->shadow_w = c->shadow_h = 0;
        return WXSKY_OK;
    }
    if (c->shadow_valid && rec->shadow_version == c->shadow_version)
        return WXSKY_OK;
    w = width[k];
    h = height[k];
    if (w > c->shadow_cap_w || h > c->shadow_cap_h)
        return fail(c, WXSKY_EINVAL, "layer %d is %ux%u, beyond its capacity %ux%u", k, w, h,
                    c->shadow_cap_w, c->shadow_cap_h);
    if (!pixels[k])
        return WXSKY_OK; /* not given: keep what the texture had */
    if (w && h) {
        glBindTexture(GL_TEXTURE_2D, c->shadow_tex);
        glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, (GLsizei)w, (GLsizei)h, GL_RGBA,
                        GL_UNSIGNED_BYTE, pixels[k]);
    }
    c->shadow_w = w && h ? w : 0;
    c->shadow_h = w && h ? h : 0;
    c->shadow_version = rec->shadow_version;
    c->shadow_valid = 1;
    return WXSKY_OK;
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
            GLsizeiptr full = (GLsizeiptr)c->fs_cap_w[i] * c->fs_cap_h[i] * (GLsizeiptr)c->bpp;
            size_t bytes = (size_t)width[k] * height[k] * c->bpp;
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
                            GL_RGBA, c->tex_type, (const void *)0);
            glBindBuffer(GL_PIXEL_UNPACK_BUFFER, 0);
        } else {
            glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, (GLsizei)width[k], (GLsizei)height[k],
                            GL_RGBA, c->tex_type, pixels[k]);
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
                                    GL_RGBA, c->tex_type, pixels[k]);
            }
            c->ring_size[2 * i] = (int32_t)(w && h ? w : 0);
            c->ring_size[2 * i + 1] = (int32_t)(w && h ? h : 0);
        }
        c->ring_version = rec->ring_version;
        c->rings_valid = 1;
    }
    {
        int st = upload_shadow(c, pixels, width, height, count, rec);
        if (st != WXSKY_OK)
            return st;
    }
    if (c->depth_index >= 0) {
        /* every frame, as `near` (a layer not given keeps what the texture had) */
        int k = c->depth_index;
        if ((uint32_t)k >= count) {
            c->depth_w = c->depth_h = 0;
        } else if (width[k] > c->depth_cap_w || height[k] > c->depth_cap_h) {
            return fail(c, WXSKY_EINVAL, "layer %d is %ux%u, beyond its capacity %ux%u", k,
                        width[k], height[k], c->depth_cap_w, c->depth_cap_h);
        } else if (pixels[k]) {
            c->depth_w = width[k];
            c->depth_h = height[k];
            if (c->depth_w && c->depth_h) {
                glBindTexture(GL_TEXTURE_2D, c->depth_tex);
                glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, (GLsizei)c->depth_w, (GLsizei)c->depth_h,
                                GL_RGBA, GL_UNSIGNED_BYTE, pixels[k]);
            }
        }
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
    if (c) {
        c->rings_valid = 0;
        c->shadow_valid = 0;
    }
}

/* ---- the cloud-shadow map for the host's terrain (protocol §3.3) ------------------------ */

int wxsky_gl_shadow(const wxsky_gl_compositor *c, wxsky_gl_shadow_params *out) {
    const wxsky_record *r;
    if (!c || !out)
        return WXSKY_EINVAL;
    memset(out, 0, sizeof *out);
    if (!c->ready || !c->have_frame)
        return WXSKY_EINVAL;
    r = &c->rec;
    out->texture = c->shadow_tex;
    out->present = c->shadow_w > 0 && c->shadow_h > 0 && r->shadow_version != 0;
    if (!out->present)
        return WXSKY_OK;
    /* the record's placement, in double until here: the host's world coordinates are the
     * record's, so float keeps millimetres over the kilometres of a map */
    out->rect[0] = (float)(r->shadow_centre_m[0] - 0.5 * r->shadow_size_m);
    out->rect[1] = (float)(r->shadow_centre_m[1] + 0.5 * r->shadow_size_m);
    out->rect[2] = (float)(1.0 / r->shadow_size_m);
    out->rect[3] = 1.0f;
    for (int i = 0; i < 3; ++i)
        out->sun[i] = (float)r->shadow_sun_enu[i];
    out->sun[3] = (float)r->shadow_centre_m[2];
    out->texels[0] = (float)c->shadow_w;
    out->texels[1] = (float)c->shadow_h;
    out->texels[2] = (float)c->shadow_cap_w;
    out->texels[3] = (float)c->shadow_cap_h;
    return WXSKY_OK;
}

int wxsky_gl_shadow_bind(wxsky_gl_compositor *c, unsigned int program, int unit) {
    wxsky_gl_shadow_params p;
    GLint max_units = 0;
    int st;
    if (!c)
        return WXSKY_EINVAL;
    if (!program)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_shadow_bind: no program");
    if (!c->ready || !c->have_frame)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_shadow_bind: %s",
                    c->ready ? "no frame uploaded" : "the compositor is not initialised");
    glGetIntegerv(GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS, &max_units);
    if (unit < 0 || unit >= max_units)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_shadow_bind: texture unit %d outside 0..%d", unit,
                    (int)max_units - 1);
    wxsky_gl_shadow(c, &p);
    glUseProgram((GLuint)program);
    glActiveTexture(GL_TEXTURE0 + (GLenum)unit);
    glBindTexture(GL_TEXTURE_2D, p.texture);
    glUniform1i(glGetUniformLocation((GLuint)program, "wxsky_shadow_map"), unit);
    glUniform4fv(glGetUniformLocation((GLuint)program, "wxsky_shadow_rect"), 1, p.rect);
    glUniform4fv(glGetUniformLocation((GLuint)program, "wxsky_shadow_sun"), 1, p.sun);
    glUniform4fv(glGetUniformLocation((GLuint)program, "wxsky_shadow_texels"), 1, p.texels);
    glActiveTexture(GL_TEXTURE0);
    if ((st = gl_check(c, "wxsky_gl_shadow_bind")) != WXSKY_OK)
        return st;
    return ok(c);
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

/* z_ndc 0: at the far plane (the vertex shader's default), else that NDC depth. */
static void draw_fullscreen(wxsky_gl_compositor *c, int which, const GLint *vp, float z_ndc) {
    glUseProgram(c->fs_prog);
    glUniform1f(c->u_fs_z, z_ndc);
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
    memcpy(c->proj, proj, sizeof c->proj);
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
        draw_fullscreen(c, FS_SKY, viewport, 0.0f);

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

static int draw_layer(wxsky_gl_compositor *c, int which, const char *what, float z_ndc) {
    GLint viewport[4];
    int st;
    if (!c)
        return WXSKY_EINVAL;
    if ((st = check_drawable(c, what)) != WXSKY_OK)
        return st;
    if (!c->fs_w[which] || !c->fs_h[which])
        return ok(c);
    glGetIntegerv(GL_VIEWPORT, viewport);
    blend_state(z_ndc != 0.0f);
    draw_fullscreen(c, which, viewport, z_ndc);
    if ((st = gl_check(c, what)) != WXSKY_OK)
        return st;
    return ok(c);
}

int wxsky_gl_draw_near(wxsky_gl_compositor *c) {
    return draw_layer(c, FS_NEAR, "wxsky_gl_draw_near", 0.0f);
}

/* `near` by the `near_depth` layer, fallback_z the NDC depth where it holds none. */
static int draw_near_by_depth(wxsky_gl_compositor *c, float fallback_z) {
    GLint viewport[4];
    double inv[16];
    GLfloat invf[16], projf[16];
    int st;
    if (!mat_inverse(c->proj, inv))
        return fail(c, WXSKY_EINVAL, "wxsky_gl_draw_near_at: the projection is singular");
    for (int i = 0; i < 16; ++i) {
        invf[i] = (GLfloat)inv[i];
        projf[i] = (GLfloat)c->proj[i];
    }
    glGetIntegerv(GL_VIEWPORT, viewport);
    blend_state(1);
    glUseProgram(c->depth_prog);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D, c->depth_tex);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, c->fs_tex[FS_NEAR]);
    glUniform1i(c->u_d_tex, 0);
    glUniform1i(c->u_d_depth, 1);
    glUniform2i(c->u_d_size, (GLint)c->fs_w[FS_NEAR], (GLint)c->fs_h[FS_NEAR]);
    glUniform2f(c->u_d_cap, (GLfloat)c->fs_cap_w[FS_NEAR], (GLfloat)c->fs_cap_h[FS_NEAR]);
    glUniform2i(c->u_d_depth_size, (GLint)c->depth_w, (GLint)c->depth_h);
    glUniform4f(c->u_d_viewport, (GLfloat)viewport[0], (GLfloat)viewport[1],
                (GLfloat)viewport[2], (GLfloat)viewport[3]);
    glUniform1i(c->u_d_flip, c->flip);
    glUniformMatrix4fv(c->u_d_inv_proj, 1, GL_FALSE, invf);
    glUniformMatrix4fv(c->u_d_proj, 1, GL_FALSE, projf);
    glUniform1f(c->u_d_fallback, fallback_z);
    glBindVertexArray(c->vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    if ((st = gl_check(c, "wxsky_gl_draw_near_at")) != WXSKY_OK)
        return st;
    return ok(c);
}

int wxsky_gl_draw_near_at(wxsky_gl_compositor *c, double distance_m) {
    const double *p;
    double z, w, z_ndc;
    int st;
    if (!c)
        return WXSKY_EINVAL;
    if ((st = check_drawable(c, "wxsky_gl_draw_near_at")) != WXSKY_OK)
        return st;
    if (!(distance_m >= 0.0) || !isfinite(distance_m))
        return fail(c, WXSKY_EINVAL, "wxsky_gl_draw_near_at: distance_m %g is not >= 0",
                    distance_m);
    p = c->proj;
    /* the eye-space point (0, 0, -d) through the last background's projection; nearer than
     * the near plane: -1, in front of everything (and never 0, the far plane's marker) */
    z = -p[10] * distance_m + p[14];
    w = -p[11] * distance_m + p[15];
    z_ndc = w > 0.0 ? z / w : -1.0;
    if (!(z_ndc > -1.0))
        z_ndc = -1.0;
    if (z_ndc > 1.0)
        z_ndc = 1.0;
    if (z_ndc == 0.0)
        z_ndc = 1e-7;
    if (!c->fs_w[FS_NEAR] || !c->fs_h[FS_NEAR])
        return ok(c);
    if (c->depth_prog && c->depth_w && c->depth_h)
        return draw_near_by_depth(c, (float)z_ndc);
    return draw_layer(c, FS_NEAR, "wxsky_gl_draw_near_at", (float)z_ndc);
}

int wxsky_gl_draw_near_front(wxsky_gl_compositor *c) {
    return draw_layer(c, FS_FRONT, "wxsky_gl_draw_near_front", 0.0f);
}

int wxsky_gl_layer_format(const wxsky_gl_compositor *c) {
    return c && c->ready ? (int)c->format : -1;
}

int wxsky_gl_tone_map(wxsky_gl_compositor *c, unsigned int linear_texture, float exposure) {
    GLint viewport[4];
    int st;
    if (!c)
        return WXSKY_EINVAL;
    if (!c->ready)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_tone_map: the compositor is not initialised");
    if (!linear_texture)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_tone_map: no texture");
    if (!isfinite(exposure) || exposure <= 0.0f)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_tone_map: exposure %g is not a positive number",
                    (double)exposure);
    if (!c->tm_prog) {
        c->tm_prog = link_program(c, FS_TONE_MAP, "tone map");
        if (!c->tm_prog)
            return WXSKY_ESYS; /* message set by link_program */
        c->u_tm_tex = glGetUniformLocation(c->tm_prog, "tex");
        c->u_tm_exposure = glGetUniformLocation(c->tm_prog, "exposure");
        c->u_tm_viewport = glGetUniformLocation(c->tm_prog, "viewport");
    }
    glGetIntegerv(GL_VIEWPORT, viewport);
    glDisable(GL_BLEND);
    glDisable(GL_DEPTH_TEST);
    glDepthMask(GL_FALSE);
    glDisable(GL_CULL_FACE);
    glUseProgram(c->tm_prog);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_2D, (GLuint)linear_texture);
    glUniform1i(c->u_tm_tex, 0);
    glUniform1f(c->u_tm_exposure, exposure);
    glUniform4f(c->u_tm_viewport, (GLfloat)viewport[0], (GLfloat)viewport[1],
                (GLfloat)viewport[2], (GLfloat)viewport[3]);
    glBindVertexArray(c->vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    if ((st = gl_check(c, "wxsky_gl_tone_map")) != WXSKY_OK)
        return st;
    return ok(c);
}

/* ---- zero-copy textures (protocol §6) -------------------------------------------------- */

/* EGL_EXT_image_dma_buf_import(_modifiers): the values, so this file needs no EGL headers. */
#define ZC_EGL_EXTENSIONS 0x3055
#define ZC_EGL_NONE 0x3038
#define ZC_EGL_WIDTH 0x3057
#define ZC_EGL_HEIGHT 0x3056
#define ZC_EGL_LINUX_DMA_BUF 0x3270
#define ZC_EGL_FOURCC 0x3271

typedef const char *(*zc_query_string_fn)(void *dpy, int32_t name);
typedef void *(*zc_create_image_fn)(void *dpy, void *ctx, unsigned target, void *buffer,
                                    const int32_t *attribs);
typedef unsigned (*zc_destroy_image_fn)(void *dpy, void *image);
typedef int32_t (*zc_get_error_fn)(void);
typedef void (*zc_image_target_fn)(GLenum target, void *image);

static int zc_has(const char *list, const char *name) {
    size_t n = strlen(name);
    for (const char *p = list; p && (p = strstr(p, name)) != NULL; p += n)
        if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0'))
            return 1;
    return 0;
}

static int zc_gl_has(const char *name) {
    GLint n = 0;
    glGetIntegerv(GL_NUM_EXTENSIONS, &n);
    for (GLint i = 0; i < n; ++i) {
        const char *e = (const char *)glGetStringi(GL_EXTENSIONS, (GLuint)i);
        if (e && !strcmp(e, name))
            return 1;
    }
    return 0;
}

static void release_imports(wxsky_gl_compositor *c) {
    for (int s = 0; s < 2; ++s)
        for (int k = 0; k < WXSKY_MAX_LAYERS; ++k) {
            if (c->zc_tex[s][k])
                glDeleteTextures(1, &c->zc_tex[s][k]);
            if (c->zc_image[s][k] && c->zc_destroy)
                c->zc_destroy(c->zc_dpy, c->zc_image[s][k]);
            c->zc_tex[s][k] = 0;
            c->zc_image[s][k] = NULL;
        }
    if (c->zc_fbo)
        glDeleteFramebuffers(1, &c->zc_fbo);
    c->zc_fbo = 0;
    c->zc = 0;
}

void wxsky_gl_release_textures(wxsky_gl_compositor *c) {
    if (c) {
        release_imports(c);
        /* the next upload, from the segment, sends every layer */
        c->rings_valid = c->shadow_valid = 0;
    }
}

int wxsky_gl_zero_copy(const wxsky_gl_compositor *c) { return c ? c->zc : 0; }

/* Is segment layer k one the compositor draws? */
static int zc_used(const wxsky_gl_compositor *c, int k) {
    for (int i = 0; i < FS_COUNT; ++i)
        if (c->fs_index[i] == k)
            return 1;
    for (int i = 0; i < RING_LAYERS; ++i)
        if (c->ring_index[i] == k)
            return 1;
    return k >= 0 && c->shadow_index == k;
}

int wxsky_gl_import_textures(wxsky_gl_compositor *c, const wxsky_segment *seg,
                             const wxsky_textures *tex, void *egl_display,
                             wxsky_gl_get_proc get_proc) {
    static const int32_t plane_attr[WXSKY_TEXTURE_PLANES][5] = {
        /* fd, offset, pitch, modifier lo, modifier hi */
        {0x3272, 0x3273, 0x3274, 0x3443, 0x3444},
        {0x3275, 0x3276, 0x3277, 0x3445, 0x3446},
        {0x3278, 0x3279, 0x327A, 0x3447, 0x3448},
        {0x3440, 0x3441, 0x3442, 0x3449, 0x344A},
    };
    zc_query_string_fn query;
    zc_create_image_fn create;
    zc_get_error_fn get_error;
    zc_image_target_fn target;
    const char *ext;
    GLint prev_read = 0;
    int st = WXSKY_ESYS;
    if (!c)
        return WXSKY_EINVAL;
    if (!c->ready)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_import_textures: the compositor is not initialised");
    if (!seg || !tex || !egl_display || !get_proc)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_import_textures: NULL argument");
    if (!tex->supported)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_import_textures: the daemon exports none (%.200s)",
                    tex->reason);
    release_imports(c);
    query = (zc_query_string_fn)get_proc("eglQueryString");
    create = (zc_create_image_fn)get_proc("eglCreateImageKHR");
    c->zc_destroy = (zc_destroy_image_fn)get_proc("eglDestroyImageKHR");
    get_error = (zc_get_error_fn)get_proc("eglGetError");
    target = (zc_image_target_fn)get_proc("glEGLImageTargetTexture2DOES");
    c->zc_dpy = egl_display;
    if (!query || !create || !c->zc_destroy || !get_error || !target)
        return fail(c, WXSKY_EFORMAT, "wxsky_gl_import_textures: get_proc finds no %s",
                    !query ? "eglQueryString" : !create ? "eglCreateImageKHR"
                    : !c->zc_destroy ? "eglDestroyImageKHR" : !get_error ? "eglGetError"
                    : "glEGLImageTargetTexture2DOES");
    ext = query(egl_display, ZC_EGL_EXTENSIONS);
    if (!ext || !zc_has(ext, "EGL_KHR_image_base") || !zc_has(ext, "EGL_EXT_image_dma_buf_import"))
        return fail(c, WXSKY_EFORMAT, "no EGL_EXT_image_dma_buf_import on this EGL display: use "
                    "the segment");
    if (!zc_gl_has("GL_OES_EGL_image"))
        return fail(c, WXSKY_EFORMAT, "no GL_OES_EGL_image in this GL context: use the segment");
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &prev_read);
    glGenFramebuffers(1, &c->zc_fbo);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, c->zc_fbo);
    glActiveTexture(GL_TEXTURE0);
    for (uint32_t i = 0; i < tex->count && i < WXSKY_TEXTURES_MAX; ++i) {
        const wxsky_texture *t = &tex->textures[i];
        int32_t attr[6 + WXSKY_TEXTURE_PLANES * 10 + 1];
        int n = 0, k = wxsky_segment_find_layer(seg, t->layer);
        wxsky_layer_info info;
        void *image;
        GLuint name = 0;
        if (k < 0 || !zc_used(c, k) || t->slot > 1)
            continue; /* a layer this compositor does not draw */
        wxsky_segment_layer(seg, (uint32_t)k, &info);
        if (t->width != info.max_width || t->height != info.max_height) {
            st = fail(c, WXSKY_EFORMAT, "texture '%s' slot %u is %ux%u, not the layer's capacity %ux%u",
                 t->layer, t->slot, t->width, t->height, info.max_width, info.max_height);
            goto failed;
        }
        if (t->modifier != WXSKY_DRM_FORMAT_MOD_INVALID &&
            !zc_has(ext, "EGL_EXT_image_dma_buf_import_modifiers")) {
            st = fail(c, WXSKY_EFORMAT, "texture '%s' has modifier 0x%016llx and this EGL display has "
                 "no EGL_EXT_image_dma_buf_import_modifiers", t->layer,
                 (unsigned long long)t->modifier);
            goto failed;
        }
        attr[n++] = ZC_EGL_WIDTH;
        attr[n++] = (int32_t)t->width;
        attr[n++] = ZC_EGL_HEIGHT;
        attr[n++] = (int32_t)t->height;
        attr[n++] = ZC_EGL_FOURCC;
        attr[n++] = (int32_t)t->fourcc;
        for (uint32_t p = 0; p < t->plane_count && p < WXSKY_TEXTURE_PLANES; ++p) {
            attr[n++] = plane_attr[p][0];
            attr[n++] = t->planes[p].fd;
            attr[n++] = plane_attr[p][1];
            attr[n++] = (int32_t)t->planes[p].offset;
            attr[n++] = plane_attr[p][2];
            attr[n++] = (int32_t)t->planes[p].stride;
            if (t->modifier != WXSKY_DRM_FORMAT_MOD_INVALID) {
                attr[n++] = plane_attr[p][3];
                attr[n++] = (int32_t)(uint32_t)(t->modifier & 0xffffffffu);
                attr[n++] = plane_attr[p][4];
                attr[n++] = (int32_t)(uint32_t)(t->modifier >> 32);
            }
        }
        attr[n++] = ZC_EGL_NONE;
        (void)get_error();
        image = create(egl_display, NULL, ZC_EGL_LINUX_DMA_BUF, NULL, attr);
        if (!image) {
            st = fail(c, WXSKY_ESYS, "eglCreateImageKHR(EGL_LINUX_DMA_BUF_EXT) for '%s' slot %u "
                 "(fourcc 0x%08x, modifier 0x%016llx) failed: EGL error 0x%04x", t->layer,
                 t->slot, t->fourcc, (unsigned long long)t->modifier, (unsigned)get_error());
            goto failed;
        }
        c->zc_image[t->slot][k] = image;
        glGenTextures(1, &name);
        c->zc_tex[t->slot][k] = name;
        glBindTexture(GL_TEXTURE_2D, name);
        target(GL_TEXTURE_2D, image);
        tex_params(GL_TEXTURE_2D, GL_NEAREST);
        glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, name, 0);
        if (glCheckFramebufferStatus(GL_READ_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE ||
            glGetError() != GL_NO_ERROR) {
            st = fail(c, WXSKY_ESYS, "the imported texture '%s' slot %u cannot be read through a "
                 "framebuffer", t->layer, t->slot);
            goto failed;
        }
    }
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, 0, 0);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)prev_read);
    /* every layer drawn, in both slots */
    for (int s = 0; s < 2; ++s)
        for (int k = 0; k < WXSKY_MAX_LAYERS; ++k)
            if (zc_used(c, k) && !c->zc_tex[s][k]) {
                fail(c, WXSKY_EFORMAT, "the daemon exported no texture for layer %d slot %d", k, s);
                release_imports(c);
                return WXSKY_EFORMAT;
            }
    if (gl_check(c, "wxsky_gl_import_textures") != WXSKY_OK) {
        release_imports(c);
        return WXSKY_ESYS;
    }
    c->zc = 1;
    c->rings_valid = c->shadow_valid = 0;
    return ok(c);
failed:
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, 0, 0);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)prev_read);
    while (glGetError() != GL_NO_ERROR) {
    }
    release_imports(c);
    return st;
}

/* One GPU copy of the view's slot texture k (w x h) into the compositor's own texture. */
static void zc_copy(wxsky_gl_compositor *c, int slot, int k, GLenum dst_target, GLuint dst,
                    int layer, uint32_t w, uint32_t h) {
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D,
                           c->zc_tex[slot][k], 0);
    glBindTexture(dst_target, dst);
    if (dst_target == GL_TEXTURE_2D)
        glCopyTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, 0, 0, (GLsizei)w, (GLsizei)h);
    else
        glCopyTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, layer, 0, 0, (GLsizei)w, (GLsizei)h);
}

int wxsky_gl_import_view(wxsky_gl_compositor *c, const wxsky_frame_view *view,
                         const wxsky_record *rec) {
    GLint prev_read = 0;
    GLsync fence;
    GLenum waited;
    int rings, slot;
    if (!c)
        return WXSKY_EINVAL;
    if (!c->ready || !c->zc)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_import_view: no textures imported");
    if (!view || !rec)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_import_view: no view or record");
    slot = (int)view->slot_;
    if (slot < 0 || slot > 1)
        return fail(c, WXSKY_EINVAL, "wxsky_gl_import_view: a view of no slot");
    glGetIntegerv(GL_READ_FRAMEBUFFER_BINDING, &prev_read);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, c->zc_fbo);
    glActiveTexture(GL_TEXTURE0);
    for (int i = 0; i < FS_COUNT; ++i) {
        int k = c->fs_index[i];
        uint32_t w = 0, h = 0;
        if (k >= 0 && (uint32_t)k < view->layer_count) {
            w = view->layers[k].width;
            h = view->layers[k].height;
        }
        if (w > c->fs_cap_w[i] || h > c->fs_cap_h[i]) {
            glBindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)prev_read);
            return fail(c, WXSKY_EINVAL, "layer %d is %ux%u, beyond its capacity %ux%u", k, w, h,
                        c->fs_cap_w[i], c->fs_cap_h[i]);
        }
        c->fs_w[i] = w;
        c->fs_h[i] = h;
        if (w && h)
            zc_copy(c, slot, k, GL_TEXTURE_2D, c->fs_tex[i], 0, w, h);
    }
    rings = !c->rings_valid || rec->ring_version != c->ring_version;
    if (rings) {
        for (int i = 0; i < RING_LAYERS; ++i) {
            int k = c->ring_index[i];
            uint32_t w = 0, h = 0;
            if (k >= 0 && (uint32_t)k < view->layer_count && (i < RING_QUADS || rec->fading)) {
                w = view->layers[k].width;
                h = view->layers[k].height;
                if (w > c->ring_cap_w || h > c->ring_cap_h) {
                    glBindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)prev_read);
                    return fail(c, WXSKY_EINVAL, "layer %d is %ux%u, beyond its capacity %ux%u",
                                k, w, h, c->ring_cap_w, c->ring_cap_h);
                }
                if (w && h)
                    zc_copy(c, slot, k, GL_TEXTURE_2D_ARRAY, c->ring_tex, i, w, h);
            }
            c->ring_size[2 * i] = (int32_t)(w && h ? w : 0);
            c->ring_size[2 * i + 1] = (int32_t)(w && h ? h : 0);
        }
        c->ring_version = rec->ring_version;
        c->rings_valid = 1;
    }
    /* the shadow map, as upload_shadow: only when its version changed */
    if (c->shadow_index < 0 || (uint32_t)c->shadow_index >= view->layer_count ||
        rec->shadow_version == 0) {
        c->shadow_w = c->shadow_h = 0;
    } else if (!c->shadow_valid || rec->shadow_version != c->shadow_version) {
        int k = c->shadow_index;
        uint32_t w = view->layers[k].width, h = view->layers[k].height;
        if (w > c->shadow_cap_w || h > c->shadow_cap_h) {
            glBindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)prev_read);
            return fail(c, WXSKY_EINVAL, "layer %d is %ux%u, beyond its capacity %ux%u", k, w,
                        h, c->shadow_cap_w, c->shadow_cap_h);
        }
        if (w && h)
            zc_copy(c, slot, k, GL_TEXTURE_2D, c->shadow_tex, 0, w, h);
        c->shadow_w = w && h ? w : 0;
        c->shadow_h = w && h ? h : 0;
        c->shadow_version = rec->shadow_version;
        c->shadow_valid = 1;
    }
    glFramebufferTexture2D(GL_READ_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, 0, 0);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, (GLuint)prev_read);
    /* The copies must be done before wxsky_frame_end checks the slot: until then the daemon
     * may come back to it (protocol §6). The wait covers the copies only; the composite that
     * follows reads the compositor's own textures, asynchronously. */
    fence = glFenceSync(GL_SYNC_GPU_COMMANDS_COMPLETE, 0);
    waited = fence ? glClientWaitSync(fence, GL_SYNC_FLUSH_COMMANDS_BIT, 1000000000ull)
                   : GL_WAIT_FAILED;
    if (fence)
        glDeleteSync(fence);
    c->rec = *rec;
    if (waited != GL_ALREADY_SIGNALED && waited != GL_CONDITION_SATISFIED) {
        c->rings_valid = c->shadow_valid = 0;
        (void)gl_check(c, "wxsky_gl_import_view");
        return fail(c, WXSKY_ESYS, "wxsky_gl_import_view: the copies did not finish within 1 s "
                    "(glClientWaitSync 0x%04x)", (unsigned)waited);
    }
    if (gl_check(c, "wxsky_gl_import_view") != WXSKY_OK) {
        c->rings_valid = c->shadow_valid = 0;
        return WXSKY_ESYS;
    }
    c->have_frame = 1;
    return ok(c);
}
