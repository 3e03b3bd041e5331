/* The programs' GL plumbing (app.h): the headless context and its framebuffer, a composite. */
#include "app.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define GL_CONTEXT_NO_DIE
#include "gl_context.h"

int app_gl_open(app_gl *g, uint32_t width, uint32_t height, char *err) {
    egl_state *e = calloc(1, sizeof *e);
    memset(g, 0, sizeof *g);
    if (!e) {
        snprintf(err, APP_ERR, "out of memory");
        return -1;
    }
    if (!make_context(e)) {
        snprintf(err, APP_ERR, "no headless EGL display with a %s context (EGL error 0x%x)",
#ifdef WXSKY_GL_ES
                 "OpenGL ES 3.0",
#else
                 "OpenGL 3.3 core",
#endif
                 (unsigned)eglGetError());
        free(e);
        return -1;
    }
    g->egl_ = e;
    g->width = width;
    g->height = height;
    glGenFramebuffers(1, &g->fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, g->fbo);
    glGenRenderbuffers(1, &g->color);
    glBindRenderbuffer(GL_RENDERBUFFER, g->color);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, (GLsizei)width, (GLsizei)height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, g->color);
    glGenRenderbuffers(1, &g->depth);
    glBindRenderbuffer(GL_RENDERBUFFER, g->depth);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, (GLsizei)width,
                          (GLsizei)height);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g->depth);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
        snprintf(err, APP_ERR, "a %ux%u framebuffer is incomplete", width, height);
        app_gl_close(g);
        return -1;
    }
    glViewport(0, 0, (GLsizei)width, (GLsizei)height);
    return 0;
}

int app_gl_read(const app_gl *g, uint8_t *rgba, char *err) {
    GLenum code;
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glReadPixels(0, 0, (GLsizei)g->width, (GLsizei)g->height, GL_RGBA, GL_UNSIGNED_BYTE, rgba);
    if ((code = glGetError()) != GL_NO_ERROR) {
        snprintf(err, APP_ERR, "reading the picture back: GL error 0x%x", (unsigned)code);
        return -1;
    }
    return 0;
}

int app_gl_open_linear(app_gl *g, char *err) {
    glGenTextures(1, &g->linear_tex);
    glBindTexture(GL_TEXTURE_2D, g->linear_tex);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    /* 32-bit floats: the composite of half-float layers loses nothing to the blending */
    glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, (GLsizei)g->width, (GLsizei)g->height, 0, GL_RGBA,
                 GL_FLOAT, NULL);
    glGenFramebuffers(1, &g->linear_fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, g->linear_fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, g->linear_tex, 0);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, g->depth);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
        snprintf(err, APP_ERR, "a %ux%u RGBA32F framebuffer is incomplete", g->width, g->height);
        return -1;
    }
    glViewport(0, 0, (GLsizei)g->width, (GLsizei)g->height);
    return 0;
}

int app_gl_read_linear(const app_gl *g, float *rgba, char *err) {
    GLenum code;
    glBindFramebuffer(GL_FRAMEBUFFER, g->linear_fbo);
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glReadPixels(0, 0, (GLsizei)g->width, (GLsizei)g->height, GL_RGBA, GL_FLOAT, rgba);
    if ((code = glGetError()) != GL_NO_ERROR) {
        snprintf(err, APP_ERR, "reading the linear picture back: GL error 0x%x", (unsigned)code);
        return -1;
    }
    return 0;
}

int app_gl_tone_map(const app_gl *g, wxsky_gl_compositor *gl, float exposure, char *err) {
    int st;
    glBindFramebuffer(GL_FRAMEBUFFER, g->fbo);
    glViewport(0, 0, (GLsizei)g->width, (GLsizei)g->height);
    if ((st = wxsky_gl_tone_map(gl, g->linear_tex, exposure)) != WXSKY_OK) {
        snprintf(err, APP_ERR, "tone map: %s: %s", wxsky_status_name(st), wxsky_gl_error(gl));
        return -1;
    }
    return 0;
}

void app_gl_close(app_gl *g) {
    egl_state *e = g->egl_;
    if (!e)
        return;
    if (g->linear_fbo)
        glDeleteFramebuffers(1, &g->linear_fbo);
    if (g->linear_tex)
        glDeleteTextures(1, &g->linear_tex);
    if (g->fbo)
        glDeleteFramebuffers(1, &g->fbo);
    if (g->color)
        glDeleteRenderbuffers(1, &g->color);
    if (g->depth)
        glDeleteRenderbuffers(1, &g->depth);
    close_context(e);
    free(e);
    memset(g, 0, sizeof *g);
}

int app_composite(wxsky_gl_compositor *gl, const wxsky_frame_copy *copy, const wxsky_record *rec,
                  char *err) {
    double view[16], proj[16];
    int st;
    glDepthMask(GL_TRUE);
    glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
    clear_depth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    wxsky_gl_camera_matrices(rec, 1, view, proj);
    if ((st = wxsky_gl_upload_copy(gl, copy, rec)) != WXSKY_OK ||
        (st = wxsky_gl_draw_background(gl, view, proj)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near(gl)) != WXSKY_OK || (st = wxsky_gl_draw_near_front(gl)) != WXSKY_OK) {
        snprintf(err, APP_ERR, "compositing frame %llu: %s: %s",
                 (unsigned long long)rec->frame_number, wxsky_status_name(st), wxsky_gl_error(gl));
        return st;
    }
    return WXSKY_OK;
}
