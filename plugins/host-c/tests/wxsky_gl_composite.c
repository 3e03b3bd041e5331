/* wxsky_gl_composite: composites the latest frame of a segment with the GL compositor on a
 * headless EGL context and writes the picture as raw RGBA8, top row first (what the Python
 * reference compositor returns), for tests/test_host_c_gl.py.
 *
 *   wxsky_gl_composite SEGMENT OUT.rgba [--window] [--twice] [--view] [--pbo]
 *                      [--terrain-m D] [--scale S]
 *
 * --window: draw with the unflipped (window) projection, then flip the rows read back, to
 * test that orientation too. --twice: upload the frame a second time (the ring layers are then
 * skipped, their ring_version unchanged) before drawing. --view: upload from a zero-copy view
 * (wxsky_frame_begin / wxsky_gl_upload_view / wxsky_frame_end) instead of the copy. --pbo:
 * stream the full-screen layers through pixel-unpack buffers (wxsky_gl_set_streaming).
 * --scale S: a framebuffer S times the record's size (the layers are stretched over it). --terrain-m D: before the background,
 * stand in for a host's opaque terrain: the left half of the picture cleared to green (0, 128,
 * 0) at the depth of a plane D metres ahead (depth written), so the sky is hidden there and
 * ring clouds beyond D too, while those nearer than D are blended over it.
 * Built twice: wxsky_gl_composite (OpenGL 3.3 core, libwxsky_host_gl) and, where pkg-config
 * finds glesv2, wxsky_gles_composite (-DWXSKY_GL_ES: OpenGL ES 3.0, libwxsky_host_gles).
 * Prints one line "ok WIDTHxHEIGHT frame N renderer R"; on failure one line and exit 1 (exit
 * 2 when no headless EGL/GL 3.3 context could be made, so the test can skip). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <EGL/egl.h>
#include <EGL/eglext.h>
#ifdef WXSKY_GL_ES
/* built as wxsky_gles_composite: an OpenGL ES 3.0 context and the GLES build of the library */
#include <GLES3/gl3.h>
#define WXSKY_EGL_API EGL_OPENGL_ES_API
#define WXSKY_EGL_BIT EGL_OPENGL_ES3_BIT
#define clear_depth(d) glClearDepthf((GLfloat)(d))
#else
#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>
#define WXSKY_EGL_API EGL_OPENGL_API
#define WXSKY_EGL_BIT EGL_OPENGL_BIT
#define clear_depth(d) glClearDepth(d)
#endif

#include "wxsky_host.h"
#include "wxsky_host_gl.h"

static int die(int code, const char *what, const char *msg) {
    printf("error %s: %s\n", what, msg);
    return code;
}

static int has_ext(const char *list, const char *name) {
    size_t n = strlen(name);
    const char *p = list;
    while (p && (p = strstr(p, name)) != NULL) {
        if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == '\0'))
            return 1;
        p += n;
    }
    return 0;
}

typedef struct egl_state {
    EGLDisplay dpy;
    EGLContext ctx;
    EGLSurface surf;
} egl_state;

/* A display: surfaceless Mesa, then each EGL device, then the default display. */
static int try_display(egl_state *e, EGLDisplay dpy) {
    EGLint major = 0, minor = 0, n = 0;
    EGLConfig cfg;
    const EGLint cfg_attr[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE,
                               WXSKY_EGL_BIT, EGL_NONE};
    const EGLint cfg_attr_any[] = {EGL_RENDERABLE_TYPE, WXSKY_EGL_BIT, EGL_SURFACE_TYPE, 0,
                                   EGL_NONE};
#ifdef WXSKY_GL_ES
    const EGLint ctx_attr[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 0,
                               EGL_NONE};
#else
    const EGLint ctx_attr[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
                               EGL_CONTEXT_OPENGL_PROFILE_MASK,
                               EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
#endif
    const EGLint pb_attr[] = {EGL_WIDTH, 16, EGL_HEIGHT, 16, EGL_NONE};
    int pbuffer = 1;
    if (dpy == EGL_NO_DISPLAY || !eglInitialize(dpy, &major, &minor))
        return 0;
    if (!eglBindAPI(WXSKY_EGL_API))
        goto fail;
    if (!eglChooseConfig(dpy, cfg_attr, &cfg, 1, &n) || n < 1) {
        pbuffer = 0;
        if (!eglChooseConfig(dpy, cfg_attr_any, &cfg, 1, &n) || n < 1)
            goto fail;
    }
    e->ctx = eglCreateContext(dpy, cfg, EGL_NO_CONTEXT, ctx_attr);
    if (e->ctx == EGL_NO_CONTEXT)
        goto fail;
    e->surf = EGL_NO_SURFACE;
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, e->ctx)) {
        if (!pbuffer)
            goto fail_ctx;
        e->surf = eglCreatePbufferSurface(dpy, cfg, pb_attr);
        if (e->surf == EGL_NO_SURFACE || !eglMakeCurrent(dpy, e->surf, e->surf, e->ctx))
            goto fail_ctx;
    }
    e->dpy = dpy;
    return 1;
fail_ctx:
    if (e->surf != EGL_NO_SURFACE)
        eglDestroySurface(dpy, e->surf);
    eglDestroyContext(dpy, e->ctx);
fail:
    eglTerminate(dpy);
    return 0;
}

static int make_context(egl_state *e) {
    const char *client = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    PFNEGLGETPLATFORMDISPLAYEXTPROC get_platform =
        (PFNEGLGETPLATFORMDISPLAYEXTPROC)eglGetProcAddress("eglGetPlatformDisplayEXT");
    if (client && get_platform && has_ext(client, "EGL_MESA_platform_surfaceless") &&
        try_display(e, get_platform(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL)))
        return 1;
    if (client && get_platform && has_ext(client, "EGL_EXT_platform_device")) {
        PFNEGLQUERYDEVICESEXTPROC query =
            (PFNEGLQUERYDEVICESEXTPROC)eglGetProcAddress("eglQueryDevicesEXT");
        EGLDeviceEXT devices[16];
        EGLint n = 0;
        if (query && query(16, devices, &n))
            for (EGLint i = 0; i < n; ++i)
                if (try_display(e, get_platform(EGL_PLATFORM_DEVICE_EXT, devices[i], NULL)))
                    return 1;
    }
    return try_display(e, eglGetDisplay(EGL_DEFAULT_DISPLAY));
}

int main(int argc, char **argv) {
    const char *name, *out_path;
    int window = 0, twice = 0, use_view = 0, pbo = 0, st, code = 1;
    double terrain_m = 0.0;
    int scale = 1;
    wxsky_segment *seg = NULL;
    wxsky_gl_compositor *gl = NULL;
    wxsky_frame_copy copy;
    wxsky_record rec;
    char err[WXSKY_ERROR_MAX];
    uint8_t *pixels = NULL, *row = NULL;
    egl_state e;
    GLuint fbo = 0, rb[2] = {0, 0};
    double view[16], proj[16];
    uint32_t w, h;
    FILE *f;

    if (argc < 3)
        return die(1, "usage",
                   "wxsky_gl_composite SEGMENT OUT.rgba [--window] [--twice] [--view] "
                   "[--pbo] [--terrain-m D] [--scale S]");
    name = argv[1];
    out_path = argv[2];
    for (int i = 3; i < argc; ++i) {
        if (!strcmp(argv[i], "--window"))
            window = 1;
        else if (!strcmp(argv[i], "--twice"))
            twice = 1;
        else if (!strcmp(argv[i], "--view"))
            use_view = 1;
        else if (!strcmp(argv[i], "--pbo"))
            pbo = 1;
        else if (!strcmp(argv[i], "--terrain-m") && i + 1 < argc)
            terrain_m = atof(argv[++i]);
        else if (!strcmp(argv[i], "--scale") && i + 1 < argc && atoi(argv[i + 1]) >= 1 &&
                 atoi(argv[i + 1]) <= 8)
            scale = atoi(argv[++i]);
        else
            return die(1, "usage", argv[i]);
    }
    memset(&copy, 0, sizeof copy);
    memset(&e, 0, sizeof e);

    seg = wxsky_segment_new();
    gl = wxsky_gl_new();
    if (!seg || !gl)
        return die(1, "alloc", "out of memory");
    for (int tries = 0; (st = wxsky_segment_open(seg, name)) == WXSKY_STARTING && tries < 200;
         ++tries) {
        struct timespec ts = {0, 5000000};
        nanosleep(&ts, NULL);
    }
    if (st != WXSKY_OK) {
        printf("error open %s: %s\n", wxsky_status_name(st), wxsky_segment_error(seg));
        goto done;
    }
    for (uint32_t i = 0; i < wxsky_segment_layer_count(seg); ++i) {
        wxsky_layer_info info;
        wxsky_segment_layer(seg, i, &info);
        copy.pixels[i] = malloc(info.capacity ? info.capacity : 1);
        copy.pixels_size[i] = info.capacity;
        if (!copy.pixels[i]) {
            printf("error alloc: layer %u\n", i);
            goto done;
        }
    }
    copy.meta_size = wxsky_segment_meta_capacity(seg);
    copy.meta = malloc(copy.meta_size ? copy.meta_size : 1);
    if (!copy.meta)
        goto done;
    st = wxsky_frame_read(seg, &copy, 2000);
    if (st != WXSKY_OK) {
        printf("error read %s: %s\n", wxsky_status_name(st), wxsky_segment_error(seg));
        goto done;
    }
    st = wxsky_record_decode(copy.meta, copy.meta_length, &rec, err, sizeof err);
    if (st != WXSKY_OK) {
        printf("error record %s: %s\n", wxsky_status_name(st), err);
        goto done;
    }
    w = rec.width_px * (uint32_t)scale;
    h = rec.height_px * (uint32_t)scale;

    if (!make_context(&e)) {
        printf("error egl: no headless EGL display with a %s context (0x%x)\n",
#ifdef WXSKY_GL_ES
               "OpenGL ES 3.0",
#else
               "OpenGL 3.3 core",
#endif
               (unsigned)eglGetError());
        code = 2;
        goto done;
    }
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glGenRenderbuffers(2, rb);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[0]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, (GLsizei)w, (GLsizei)h);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, rb[0]);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[1]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, (GLsizei)w, (GLsizei)h);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, rb[1]);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
        printf("error fbo: incomplete framebuffer\n");
        goto done;
    }
    glViewport(0, 0, (GLsizei)w, (GLsizei)h);
    glDepthMask(GL_TRUE);
    glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
    clear_depth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);

    wxsky_gl_camera_matrices(&rec, !window, view, proj);
    if (terrain_m > 0.0) {
        /* the depth of eye-space z = -terrain_m under proj */
        double depth = 0.5 * (proj[10] * -terrain_m + proj[14]) / terrain_m + 0.5;
        glEnable(GL_SCISSOR_TEST);
        glScissor(0, 0, (GLsizei)(w / 2), (GLsizei)h);
        glClearColor(0.0f, 128.0f / 255.0f, 0.0f, 1.0f);
        clear_depth(depth);
        glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
        glDisable(GL_SCISSOR_TEST);
    }

    if (pbo && (st = wxsky_gl_set_streaming(gl, 1)) != WXSKY_OK) {
        printf("error streaming %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    if ((st = wxsky_gl_init(gl, seg)) != WXSKY_OK) {
        printf("error init %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    for (int n = 0; n < 1 + twice; ++n) {
        if (use_view) {
            /* the record was decoded from the copy above: the writer here publishes once, so
             * the view holds the same frame (checked) */
            wxsky_frame_view fv;
            if ((st = wxsky_frame_begin(seg, &fv)) != WXSKY_OK) {
                printf("error begin %s: %s\n", wxsky_status_name(st), wxsky_segment_error(seg));
                goto done;
            }
            if (fv.frame_number != copy.frame_number) {
                printf("error view: frame %llu, not %llu\n", (unsigned long long)fv.frame_number,
                       (unsigned long long)copy.frame_number);
                goto done;
            }
            st = wxsky_gl_upload_view(gl, &fv, &rec);
            if (wxsky_frame_end(seg, &fv) == WXSKY_ETORN) {
                wxsky_gl_invalidate(gl);
                printf("error view: torn\n");
                goto done;
            }
        } else {
            st = wxsky_gl_upload_copy(gl, &copy, &rec);
        }
        if (st != WXSKY_OK) {
            printf("error upload %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
            goto done;
        }
    }
    if ((st = wxsky_gl_draw_background(gl, view, proj)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near(gl)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near_front(gl)) != WXSKY_OK) {
        printf("error draw %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    pixels = malloc((size_t)w * h * 4);
    row = malloc((size_t)w * 4);
    if (!pixels || !row)
        goto done;
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glReadPixels(0, 0, (GLsizei)w, (GLsizei)h, GL_RGBA, GL_UNSIGNED_BYTE, pixels);
    if (glGetError() != GL_NO_ERROR) {
        printf("error readback: GL error\n");
        goto done;
    }
    if (window) /* row 0 read back is the picture's bottom row */
        for (uint32_t y = 0; y < h / 2; ++y) {
            memcpy(row, pixels + (size_t)y * w * 4, (size_t)w * 4);
            memcpy(pixels + (size_t)y * w * 4, pixels + (size_t)(h - 1 - y) * w * 4, (size_t)w * 4);
            memcpy(pixels + (size_t)(h - 1 - y) * w * 4, row, (size_t)w * 4);
        }
    f = fopen(out_path, "wb");
    if (!f || fwrite(pixels, 1, (size_t)w * h * 4, f) != (size_t)w * h * 4) {
        printf("error write: %s\n", out_path);
        if (f)
            fclose(f);
        goto done;
    }
    fclose(f);
    printf("ok %ux%u frame %llu renderer %s\n", w, h, (unsigned long long)copy.frame_number,
           (const char *)glGetString(GL_RENDERER));
    code = 0;
done:
    if (e.ctx) {
        wxsky_gl_free(gl);
        gl = NULL;
        if (fbo)
            glDeleteFramebuffers(1, &fbo);
        if (rb[0])
            glDeleteRenderbuffers(2, rb);
        eglMakeCurrent(e.dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        if (e.surf != EGL_NO_SURFACE)
            eglDestroySurface(e.dpy, e.surf);
        eglDestroyContext(e.dpy, e.ctx);
        eglTerminate(e.dpy);
        eglReleaseThread();
    }
    wxsky_gl_free(gl);
    free(pixels);
    free(row);
    for (int i = 0; i < WXSKY_MAX_LAYERS; ++i)
        free(copy.pixels[i]);
    free(copy.meta);
    wxsky_segment_free(seg);
    return code;
}
