/* The headless EGL context and the few helpers the kit's GL programs share (the tests'
 * wxsky_gl_composite and wxsky_gl_bench, the apps' app.c). Included by exactly one source file
 * per program, so its functions are static; not part of the library. */
#ifndef WXSKY_APPS_GL_CONTEXT_H
#define WXSKY_APPS_GL_CONTEXT_H

#include <string.h>

#include "gl_api.h"

#include "wxsky_host.h"
#include "wxsky_host_gl.h"

#ifndef GL_CONTEXT_NO_DIE /* app.c reports its own errors */
static int die(int code, const char *what, const char *msg) {
    printf("error %s: %s\n", what, msg);
    return code;
}
#endif

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

/* Releases what make_context made (the context current on this thread). */
static void close_context(egl_state *e) {
    eglMakeCurrent(e->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (e->surf != EGL_NO_SURFACE)
        eglDestroySurface(e->dpy, e->surf);
    eglDestroyContext(e->dpy, e->ctx);
    eglTerminate(e->dpy);
    eglReleaseThread();
}

#endif
