/* wxsky_gl_composite: composites the latest frame of a segment with the GL compositor on a
 * headless EGL context and writes the picture as raw RGBA8, top row first (what the Python
 * reference compositor returns), for tests/test_host_c_gl.py.
 *
 *   wxsky_gl_composite SEGMENT OUT.rgba [--window] [--twice] [--view] [--pbo]
 *                      [--terrain-m D] [--scale S] [--linear-out OUT.f32] [--exposure EV]
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
 * HDR layers (RGBA16F, wxsky_gl_layer_format): the composite goes into an RGBA32F texture,
 * which --linear-out writes as raw float32 RGBA, top row first (the Python reference's
 * composite_linear); OUT.rgba is then that composite through wxsky_gl_tone_map at --exposure
 * EV (default 0), drawn into the RGBA8 framebuffer. --linear-out with RGBA8 layers fails.
 * Built twice: wxsky_gl_composite (OpenGL 3.3 core, libwxsky_host_gl) and, where pkg-config
 * finds glesv2, wxsky_gles_composite (-DWXSKY_GL_ES: OpenGL ES 3.0, libwxsky_host_gles).
 * Prints one line "ok WIDTHxHEIGHT frame N renderer R"; on failure one line and exit 1 (exit
 * 2 when no headless EGL/GL 3.3 context could be made, so the test can skip). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "app.h"
#include "gl_context.h"

int main(int argc, char **argv) {
    char why[APP_ERR];
    const char *name, *out_path, *linear_path = NULL;
    double exposure_ev = 0.0;
    int hdr = 0;
    GLuint lin_fbo = 0, lin_tex = 0;
    float *linear = NULL;
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
        else if (!strcmp(argv[i], "--linear-out") && i + 1 < argc)
            linear_path = argv[++i];
        else if (!strcmp(argv[i], "--exposure") && i + 1 < argc)
            exposure_ev = atof(argv[++i]);
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
    if ((st = app_segment_open(seg, name, 1000, why)) != WXSKY_OK) {
        printf("error open %s\n", why);
        goto done;
    }
    if (app_copy_alloc(seg, &copy) != 0) {
        printf("error alloc: frame buffers\n");
        goto done;
    }
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
    hdr = wxsky_gl_layer_format(gl) == WXSKY_FORMAT_RGBA16F;
    if (linear_path && !hdr) {
        printf("error linear: the segment's layers are RGBA8\n");
        goto done;
    }
    if (hdr) {
        /* the linear composite: an RGBA32F texture with the same depth buffer, cleared alike */
        glGenTextures(1, &lin_tex);
        glBindTexture(GL_TEXTURE_2D, lin_tex);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
        glTexParameteri(GL_TEXTURE_2D, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
        glTexImage2D(GL_TEXTURE_2D, 0, GL_RGBA32F, (GLsizei)w, (GLsizei)h, 0, GL_RGBA, GL_FLOAT,
                     NULL);
        glGenFramebuffers(1, &lin_fbo);
        glBindFramebuffer(GL_FRAMEBUFFER, lin_fbo);
        glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, lin_tex, 0);
        glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, rb[1]);
        if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
            printf("error fbo: incomplete RGBA32F framebuffer\n");
            goto done;
        }
        glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
        glClear(GL_COLOR_BUFFER_BIT);
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
    if (hdr) {
        linear = malloc((size_t)w * h * 4 * sizeof *linear);
        if (!linear)
            goto done;
        glPixelStorei(GL_PACK_ALIGNMENT, 4);
        glReadPixels(0, 0, (GLsizei)w, (GLsizei)h, GL_RGBA, GL_FLOAT, linear);
        if (glGetError() != GL_NO_ERROR) {
            printf("error readback: GL error reading the linear composite\n");
            goto done;
        }
        if (linear_path) {
            f = fopen(linear_path, "wb");
            if (!f || fwrite(linear, sizeof *linear, (size_t)w * h * 4, f) != (size_t)w * h * 4) {
                printf("error write: %s\n", linear_path);
                if (f)
                    fclose(f);
                goto done;
            }
            fclose(f);
        }
        /* once through the daemon's exposure and tone map, into the RGBA8 framebuffer */
        glBindFramebuffer(GL_FRAMEBUFFER, fbo);
        if ((st = wxsky_gl_tone_map(gl, lin_tex, (float)pow(2.0, exposure_ev))) != WXSKY_OK) {
            printf("error tone map %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
            goto done;
        }
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
        if (lin_fbo)
            glDeleteFramebuffers(1, &lin_fbo);
        if (lin_tex)
            glDeleteTextures(1, &lin_tex);
        if (rb[0])
            glDeleteRenderbuffers(2, rb);
        close_context(&e);
    }
    wxsky_gl_free(gl);
    free(pixels);
    free(linear);
    free(row);
    for (int i = 0; i < WXSKY_MAX_LAYERS; ++i)
        free(copy.pixels[i]);
    free(copy.meta);
    wxsky_segment_free(seg);
    return code;
}
