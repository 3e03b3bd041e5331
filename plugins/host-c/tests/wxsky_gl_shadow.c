/* wxsky_gl_shadow: the GL compositor's cloud-shadow map (wxsky_gl_shadow_bind and
 * WXSKY_GL_SHADOW_GLSL, protocol §3.3) on a headless EGL context, for tests/test_host_c_shadow.py
 * to hold to the Python reference host (wxsky/host/compositor.py).
 *
 *   wxsky_gl_shadow SEGMENT OUT --points IN.f64
 *       T at the N points of IN (N x 3 float64, east north up), evaluated by wxsky_shadow() in
 *       a fragment shader (one pixel per point of an RGBA32F framebuffer): OUT is N float32.
 *   wxsky_gl_shadow SEGMENT OUT.rgba --ground UP_M [--ambient A] [--rgb R,G,B]
 *       the frame composited over a host's flat ground at UP_M drawn first, as a host's
 *       terrain is: per pixel the view ray meets the plane, the point is lit with
 *       rgb (A + (1 - A) T max(0, sun_up)) (T = wxsky_shadow(point), sun the record's) and
 *       its depth written; then wxsky_gl_draw_background, _near, _near_front. OUT is raw
 *       RGBA8, top row first (what the reference compositor's composite(..., Ground) gives).
 *
 * Prints one line "ok ... shadow_version V present P"; on failure one line and exit 1 (exit 2
 * when no headless EGL context, or no float framebuffer, could be made, so the test can
 * skip). Built as wxsky_gl_shadow (OpenGL 3.3 core) and, with glesv2, wxsky_gles_shadow. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "app.h"
#include "gl_context.h"

#ifdef WXSKY_GL_ES
#define HEADER "#version 300 es\nprecision highp float;\nprecision highp int;\n" \
               "precision highp sampler2D;\n"
#else
#define HEADER "#version 330 core\n"
#endif

static const char VS[] = "void main() {\n"
                         "    vec2 p = vec2(float((gl_VertexID & 1) * 4 - 1), "
                         "float((gl_VertexID & 2) * 2 - 1));\n"
                         "    gl_Position = vec4(p, 0.0, 1.0);\n"
                         "}\n";

/* One point per pixel of row 0, read from a float texture. */
static const char FS_POINTS[] = WXSKY_GL_SHADOW_GLSL
    "uniform sampler2D points;\n"
    "out vec4 colour;\n"
    "void main() {\n"
    "    vec3 p = texelFetch(points, ivec2(int(gl_FragCoord.x), 0), 0).xyz;\n"
    "    colour = vec4(wxsky_shadow(p));\n"
    "}\n";

/* The host's flat ground: the camera model of protocol §3 per pixel, the plane met, lit. */
static const char FS_GROUND[] = WXSKY_GL_SHADOW_GLSL
    "uniform vec3 eye, fwd, right, up;\n"
    "uniform vec2 tan_half;\n"  /* tan(fov/2) across, and times height / width up */
    "uniform vec2 size;\n"      /* framebuffer pixels */
    "uniform vec2 depth;\n"     /* proj[10], proj[14] */
    "uniform float ground_m, ambient, far_m;\n"
    "uniform vec3 rgb, sun;\n"
    "out vec4 colour;\n"
    "void main() {\n"
    /* framebuffer row 0 is the picture's top row (the y-flipped projection) */
    "    float x = 2.0 * gl_FragCoord.x / size.x - 1.0;\n"
    "    float y = 1.0 - 2.0 * gl_FragCoord.y / size.y;\n"
    "    vec3 ray = fwd + x * tan_half.x * right + y * tan_half.y * up;\n"
    "    float t = (ground_m - eye.z) / ray.z;\n"
    "    if (!(t > 0.0)) discard;\n"
    "    vec3 rel = ray * t;\n"
    "    float z = -dot(rel, fwd);\n" /* eye space z of the hit */
    "    if (-z > far_m) discard;\n"   /* clipped, as a host's ground is: the sky shows */
    "    gl_FragDepth = clamp(0.5 * (depth.x * z + depth.y) / -z + 0.5, 0.0, 1.0);\n"
    "    float lit = ambient + (1.0 - ambient) * wxsky_shadow(eye + rel) * max(0.0, sun.z);\n"
    "    colour = vec4(rgb * lit, 1.0);\n"
    "}\n";

static GLuint shader(GLenum type, const char *body) {
    const char *src[2] = {HEADER, body};
    GLuint s = glCreateShader(type);
    GLint ok = 0;
    glShaderSource(s, 2, src, NULL);
    glCompileShader(s);
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) {
        char log[512];
        glGetShaderInfoLog(s, sizeof log, NULL, log);
        printf("error shader: %s\n", log);
        glDeleteShader(s);
        return 0;
    }
    return s;
}

static GLuint program(const char *fs_body) {
    GLuint vs = shader(GL_VERTEX_SHADER, VS), fs = vs ? shader(GL_FRAGMENT_SHADER, fs_body) : 0;
    GLuint p = 0;
    GLint ok = 0;
    if (vs && fs) {
        p = glCreateProgram();
        glAttachShader(p, vs);
        glAttachShader(p, fs);
        glLinkProgram(p);
        glGetProgramiv(p, GL_LINK_STATUS, &ok);
        if (!ok) {
            printf("error link\n");
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

static int target(GLuint *fbo, GLuint rb[2], GLenum format, uint32_t w, uint32_t h) {
    glGenFramebuffers(1, fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, *fbo);
    glGenRenderbuffers(2, rb);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[0]);
    glRenderbufferStorage(GL_RENDERBUFFER, format, (GLsizei)w, (GLsizei)h);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, rb[0]);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[1]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, (GLsizei)w, (GLsizei)h);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, rb[1]);
    glViewport(0, 0, (GLsizei)w, (GLsizei)h);
    return glCheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
}

static int write_file(const char *path, const void *data, size_t n) {
    FILE *f = fopen(path, "wb");
    int good = f && fwrite(data, 1, n, f) == n;
    if (f)
        fclose(f);
    if (!good)
        printf("error write: %s\n", path);
    return good;
}

/* T at each point: 1 pixel per point. */
static int run_points(wxsky_gl_compositor *gl, const char *in_path, const char *out_path) {
    FILE *f = fopen(in_path, "rb");
    double *xyz = NULL;
    float *pts = NULL, *rgba = NULL, *t = NULL;
    long bytes;
    size_t n;
    GLuint prog = 0, tex = 0, vao = 0, fbo = 0, rb[2] = {0, 0};
    int st, code = 1;
    if (!f || fseek(f, 0, SEEK_END) != 0 || (bytes = ftell(f)) <= 0 || bytes % 24 != 0 ||
        bytes / 24 > 4096) {
        printf("error points: %s must hold 1..4096 points of 3 float64\n", in_path);
        if (f)
            fclose(f);
        return 1;
    }
    n = (size_t)bytes / 24;
    rewind(f);
    xyz = malloc((size_t)bytes);
    pts = malloc(n * 4 * sizeof *pts);
    rgba = malloc(n * 4 * sizeof *rgba);
    t = malloc(n * sizeof *t);
    if (!xyz || !pts || !rgba || !t || fread(xyz, 1, (size_t)bytes, f) != (size_t)bytes) {
        printf("error points: reading %s\n", in_path);
        goto done;
    }
    for (size_t i = 0; i < n; ++i) {
        for (int k = 0; k < 3; ++k)
            pts[4 * i + k] = (float)xyz[3 * i + k];
        pts[4 * i + 3] = 0.0f;
    }
    if (!target(&fbo, rb, GL_RGBA32F, (uint32_t)n, 1)) {
        printf("error fbo: no RGBA32F framebuffer here\n");
        code = 2;
        goto done;
    }
    prog = program(FS_POINTS);
    if (!prog)
        goto done;
    glGenVertexArrays(1, &vao);
    glGenTextures(1, &tex);
    glActiveTexture(GL_TEXTURE1);
    glBindTexture(GL_TEXTURE_2D, tex);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, (GLsizei)n, 1, 0, GL_RGBA, GL_FLOAT, pts);
    if ((st = wxsky_gl_shadow_bind(gl, prog, 0)) != WXSKY_OK) {
        printf("error bind %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    glUniform1i(glGetUniformLocation(prog, "points"), 1);
    glDisable(GL_BLEND);
    glDisable(GL_DEPTH_TEST);
    glBindVertexArray(vao);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    glReadPixels(0, 0, (GLsizei)n, 1, GL_RGBA, GL_FLOAT, rgba);
    if (glGetError() != GL_NO_ERROR) {
        printf("error draw: GL error\n");
        goto done;
    }
    for (size_t i = 0; i < n; ++i)
        t[i] = rgba[4 * i];
    code = write_file(out_path, t, n * sizeof *t) ? 0 : 1;
done:
    if (prog)
        glDeleteProgram(prog);
    if (tex)
        glDeleteTextures(1, &tex);
    if (vao)
        glDeleteVertexArrays(1, &vao);
    if (fbo)
        glDeleteFramebuffers(1, &fbo);
    if (rb[0])
        glDeleteRenderbuffers(2, rb);
    if (f)
        fclose(f);
    free(xyz);
    free(pts);
    free(rgba);
    free(t);
    return code;
}

/* The frame over a host's lit, shadowed ground. */
static int run_ground(wxsky_gl_compositor *gl, const wxsky_record *rec, const char *out_path,
                      double ground_m, double ambient, const float rgb[3]) {
    const double d2r = 3.14159265358979323846 / 180.0;
    uint32_t w = rec->width_px, h = rec->height_px;
    double view[16], proj[16], hh = rec->heading_deg * d2r, p = rec->pitch_deg * d2r,
                                r = rec->roll_deg * d2r;
    double fwd[3] = {sin(hh) * cos(p), cos(hh) * cos(p), sin(p)};
    double right0[3] = {cos(hh), -sin(hh), 0.0}, up0[3], right[3], up[3];
    double tx = tan(rec->fov_deg * d2r / 2.0);
    GLuint prog = 0, vao = 0, fbo = 0, rb[2] = {0, 0};
    uint8_t *pixels = malloc((size_t)w * h * 4);
    int st, code = 1;
    up0[0] = right0[1] * fwd[2] - right0[2] * fwd[1];
    up0[1] = right0[2] * fwd[0] - right0[0] * fwd[2];
    up0[2] = right0[0] * fwd[1] - right0[1] * fwd[0];
    for (int i = 0; i < 3; ++i) {
        right[i] = right0[i] * cos(r) - up0[i] * sin(r);
        up[i] = up0[i] * cos(r) + right0[i] * sin(r);
    }
    if (!pixels)
        return 1;
    if (!target(&fbo, rb, GL_RGBA8, w, h)) {
        printf("error fbo: incomplete framebuffer\n");
        goto done;
    }
    glDepthMask(GL_TRUE);
    glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
    clear_depth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    wxsky_gl_camera_matrices(rec, 1, view, proj);
    prog = program(FS_GROUND);
    if (!prog)
        goto done;
    if ((st = wxsky_gl_shadow_bind(gl, prog, 2)) != WXSKY_OK) {
        printf("error bind %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    glUniform3f(glGetUniformLocation(prog, "eye"), (float)rec->position_m[0],
                (float)rec->position_m[1], (float)rec->position_m[2]);
    glUniform3f(glGetUniformLocation(prog, "fwd"), (float)fwd[0], (float)fwd[1], (float)fwd[2]);
    glUniform3f(glGetUniformLocation(prog, "right"), (float)right[0], (float)right[1],
                (float)right[2]);
    glUniform3f(glGetUniformLocation(prog, "up"), (float)up[0], (float)up[1], (float)up[2]);
    glUniform2f(glGetUniformLocation(prog, "tan_half"), (float)tx,
                (float)(tx * (double)h / (double)w));
    glUniform2f(glGetUniformLocation(prog, "size"), (float)w, (float)h);
    glUniform2f(glGetUniformLocation(prog, "depth"), (float)proj[10], (float)proj[14]);
    glUniform1f(glGetUniformLocation(prog, "ground_m"), (float)ground_m);
    glUniform1f(glGetUniformLocation(prog, "ambient"), (float)ambient);
    glUniform1f(glGetUniformLocation(prog, "far_m"), (float)WXSKY_GL_FAR_M);
    glUniform3f(glGetUniformLocation(prog, "rgb"), rgb[0], rgb[1], rgb[2]);
    glUniform3f(glGetUniformLocation(prog, "sun"), (float)rec->sun_direction_enu[0],
                (float)rec->sun_direction_enu[1], (float)rec->sun_direction_enu[2]);
    glGenVertexArrays(1, &vao);
    glBindVertexArray(vao);
    /* the host's opaque terrain, first, writing depth */
    glDisable(GL_BLEND);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    if ((st = wxsky_gl_draw_background(gl, view, proj)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near(gl)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near_front(gl)) != WXSKY_OK) {
        printf("error draw %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glReadPixels(0, 0, (GLsizei)w, (GLsizei)h, GL_RGBA, GL_UNSIGNED_BYTE, pixels);
    if (glGetError() != GL_NO_ERROR) {
        printf("error readback: GL error\n");
        goto done;
    }
    code = write_file(out_path, pixels, (size_t)w * h * 4) ? 0 : 1;
done:
    if (prog)
        glDeleteProgram(prog);
    if (vao)
        glDeleteVertexArrays(1, &vao);
    if (fbo)
        glDeleteFramebuffers(1, &fbo);
    if (rb[0])
        glDeleteRenderbuffers(2, rb);
    free(pixels);
    return code;
}

int main(int argc, char **argv) {
    char why[APP_ERR];
    const char *name, *out_path, *points = NULL;
    double ground_m = NAN, ambient = 0.35;
    float rgb[3] = {0.30f, 0.38f, 0.20f};
    wxsky_segment *seg = NULL;
    wxsky_gl_compositor *gl = NULL;
    wxsky_frame_copy copy;
    wxsky_record rec;
    wxsky_gl_shadow_params sp;
    char err[WXSKY_ERROR_MAX];
    egl_state e;
    int st, code = 1;

    if (argc < 5)
        return die(1, "usage",
                   "wxsky_gl_shadow SEGMENT OUT (--points IN.f64 | --ground UP_M [--ambient A] "
                   "[--rgb R,G,B])");
    name = argv[1];
    out_path = argv[2];
    for (int i = 3; i < argc; ++i) {
        if (!strcmp(argv[i], "--points") && i + 1 < argc)
            points = argv[++i];
        else if (!strcmp(argv[i], "--ground") && i + 1 < argc)
            ground_m = atof(argv[++i]);
        else if (!strcmp(argv[i], "--ambient") && i + 1 < argc)
            ambient = atof(argv[++i]);
        else if (!strcmp(argv[i], "--rgb") && i + 1 < argc &&
                 sscanf(argv[i + 1], "%f,%f,%f", &rgb[0], &rgb[1], &rgb[2]) == 3)
            ++i;
        else
            return die(1, "usage", argv[i]);
    }
    if ((points != NULL) == !isnan(ground_m)) /* exactly one of the two modes */
        return die(1, "usage", "give --points or --ground");
    memset(&copy, 0, sizeof copy);
    memset(&e, 0, sizeof e);
    seg = wxsky_segment_new();
    gl = wxsky_gl_new();
    if (!seg || !gl)
        return die(1, "alloc", "out of memory");
    if ((st = app_segment_open(seg, name, 1000, why)) != WXSKY_OK) {
        printf("error open %s\n", why);
        goto done;
    }
    if (app_copy_alloc(seg, &copy) != 0) {
        printf("error alloc: frame buffers\n");
        goto done;
    }
    if ((st = wxsky_frame_read(seg, &copy, 2000)) != WXSKY_OK) {
        printf("error read %s: %s\n", wxsky_status_name(st), wxsky_segment_error(seg));
        goto done;
    }
    if ((st = wxsky_record_decode(copy.meta, copy.meta_length, &rec, err, sizeof err)) !=
        WXSKY_OK) {
        printf("error record %s: %s\n", wxsky_status_name(st), err);
        goto done;
    }
    if (!make_context(&e)) {
        printf("error egl: no headless EGL display with a GL context (0x%x)\n",
               (unsigned)eglGetError());
        code = 2;
        goto done;
    }
    if ((st = wxsky_gl_init(gl, seg)) != WXSKY_OK ||
        (st = wxsky_gl_upload_copy(gl, &copy, &rec)) != WXSKY_OK ||
        /* a second upload of the same frame keeps the map (same shadow_version) */
        (st = wxsky_gl_upload_copy(gl, &copy, &rec)) != WXSKY_OK) {
        printf("error upload %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    if ((st = wxsky_gl_shadow(gl, &sp)) != WXSKY_OK) {
        printf("error shadow %s\n", wxsky_status_name(st));
        goto done;
    }
    code = points ? run_points(gl, points, out_path)
                  : run_ground(gl, &rec, out_path, ground_m, ambient, rgb);
    if (code == 0)
        printf("ok frame %llu shadow_version %llu present %d renderer %s\n",
               (unsigned long long)copy.frame_number, (unsigned long long)rec.shadow_version,
               sp.present, (const char *)glGetString(GL_RENDERER));
done:
    if (e.ctx) {
        wxsky_gl_free(gl);
        gl = NULL;
        close_context(&e);
    }
    wxsky_gl_free(gl);
    for (int i = 0; i < WXSKY_MAX_LAYERS; ++i)
        free(copy.pixels[i]);
    free(copy.meta);
    wxsky_segment_free(seg);
    return code;
}
