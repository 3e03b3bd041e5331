/* wxsky_gl_bench: times the host side of a frame against a live daemon, on a headless EGL
 * context, for tools/bench/bench_host_c.py (and tests/test_host_c_bench.py).
 *
 *   wxsky_gl_bench SEGMENT [--frames N] [--warmup N] [--latency N --control ADDR]
 *
 * Stages, per frame (--frames N timed frames, after --warmup N untimed ones, default 2), each
 * timer stopped after glFinish so the GL work is in its own stage:
 *   read            wxsky_frame_read: a consistent copy of every layer and the record
 *                   (+ wxsky_record_decode)
 *   upload_plain    wxsky_gl_upload_copy, glTexSubImage from client memory
 *   composite_plain clear, wxsky_gl_draw_background, _draw_near, _draw_near_front
 *   background_plain  the part of composite_plain up to draw_background (sky and ring; a
 *                   glFinish after it), so composite_plain - background_plain is near's pass
 *   upload_pbo      the same upload on a second compositor streaming through pixel-unpack
 *                   buffers (wxsky_gl_set_streaming 1)
 *   composite_pbo   the composite of that compositor
 *   host_plain, host_pbo   upload + composite of each, per frame
 *   upload_rings_plain     the plain upload again after wxsky_gl_invalidate: every layer, the
 *                   ring images included (ring_in too while fading), as after a ring rebuild
 * The other uploads send the ring layers only when ring_version changed (the compositor's
 * rule), as a host's frame loop does; `ring_uploads` counts the timed frames where that
 * happened.
 *
 * Latency (--latency N, with --control ADDR: the daemon's control address): N times, send
 * set_camera (wxsky_client) with the current camera turned to a new heading, poll the segment
 * until a frame whose record's camera equals the one sent, read, upload and composite it
 * (glFinish): the time from the send to that point ("latency"), and from the send to the
 * moment that frame was seen in the segment ("latency_wait").
 *
 * Prints one line of JSON: {"renderer", "width", "height", "frames", "ring_uploads", "stages":
 * {NAME: {"n", "median_ms", "p95_ms", "mean_ms", "max_ms"}}, "latency": {the same},
 * "latency_wait": {the same}, "latency_camera_matched": true when every frame composited for the
 * latency had the camera sent, "latency_frames_waited_mean": frames published from the send to
 * that frame}; the latency keys only with --latency. On failure one line "error ..." and exit
 * 1 (exit 2 when no headless EGL/GL context could be made). Built twice, as wxsky_gl_composite
 * is: wxsky_gl_bench (OpenGL 3.3 core) and wxsky_gles_bench (OpenGL ES 3.0). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "app.h"
#include "gl_context.h"

typedef struct bench {
    wxsky_segment *seg;
    wxsky_frame_copy copy;
    wxsky_record rec;
    wxsky_gl_compositor *gl[2]; /* plain, pbo */
    uint32_t w, h;
} bench;

static int read_frame(bench *b) {
    char err[WXSKY_ERROR_MAX];
    int st = wxsky_frame_read(b->seg, &b->copy, 2000);
    if (st != WXSKY_OK) {
        printf("error read %s: %s\n", wxsky_status_name(st), wxsky_segment_error(b->seg));
        return 0;
    }
    st = wxsky_record_decode(b->copy.meta, b->copy.meta_length, &b->rec, err, sizeof err);
    if (st != WXSKY_OK) {
        printf("error record %s: %s\n", wxsky_status_name(st), err);
        return 0;
    }
    if (b->rec.width_px != b->w || b->rec.height_px != b->h) {
        printf("error size: the frame is %ux%u, the framebuffer %ux%u\n", b->rec.width_px,
               b->rec.height_px, b->w, b->h);
        return 0;
    }
    return 1;
}

static int upload(bench *b, int which) {
    int st = wxsky_gl_upload_copy(b->gl[which], &b->copy, &b->rec);
    glFinish();
    if (st != WXSKY_OK) {
        printf("error upload %s: %s\n", wxsky_status_name(st), wxsky_gl_error(b->gl[which]));
        return 0;
    }
    return 1;
}

/* *background_ms (may be NULL): the clear and draw_background alone (a glFinish after it) */
static int composite(bench *b, int which, double *background_ms) {
    double view[16], proj[16], t0 = app_now_ms();
    int st;
    wxsky_gl_camera_matrices(&b->rec, 1, view, proj);
    glDepthMask(GL_TRUE);
    glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
    clear_depth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
    if ((st = wxsky_gl_draw_background(b->gl[which], view, proj)) == WXSKY_OK && background_ms) {
        glFinish();
        *background_ms = app_now_ms() - t0;
    }
    if (st != WXSKY_OK || (st = wxsky_gl_draw_near(b->gl[which])) != WXSKY_OK ||
        (st = wxsky_gl_draw_near_front(b->gl[which])) != WXSKY_OK) {
        printf("error draw %s: %s\n", wxsky_status_name(st), wxsky_gl_error(b->gl[which]));
        return 0;
    }
    glFinish();
    return 1;
}

enum { S_READ, S_UP0, S_COMP0, S_UP1, S_COMP1, S_HOST0, S_HOST1, S_RINGS0, S_BG0, S_COUNT };
static const char *const STAGE_NAMES[S_COUNT] = {
    "read",          "upload_plain", "composite_plain", "upload_pbo",
    "composite_pbo", "host_plain",   "host_pbo",        "upload_rings_plain",
    "background_plain"};

int main(int argc, char **argv) {
    char why[APP_ERR];
    const char *name, *control = NULL;
    int frames = 20, warmup = 2, latency_n = 0, st, code = 1, ring_uploads = 0, matched = 0;
    double *samples[S_COUNT] = {NULL}, *lat = NULL, *lat_wait = NULL, *waited = NULL;
    uint64_t last_ring = 0;
    bench b;
    egl_state e;
    wxsky_client *client = NULL;
    GLuint fbo = 0, rb[2] = {0, 0};

    if (argc < 2)
        return die(1, "usage",
                   "wxsky_gl_bench SEGMENT [--frames N] [--warmup N] [--latency N --control "
                   "ADDR]");
    name = argv[1];
    for (int i = 2; i < argc; ++i) {
        if (!strcmp(argv[i], "--frames") && i + 1 < argc && atoi(argv[i + 1]) >= 1)
            frames = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--warmup") && i + 1 < argc && atoi(argv[i + 1]) >= 0)
            warmup = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--latency") && i + 1 < argc && atoi(argv[i + 1]) >= 0)
            latency_n = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--control") && i + 1 < argc)
            control = argv[++i];
        else
            return die(1, "usage", argv[i]);
    }
    if (latency_n > 0 && !control)
        return die(1, "usage", "--latency needs --control ADDR");
    memset(&b, 0, sizeof b);
    memset(&e, 0, sizeof e);
    for (int s = 0; s < S_COUNT; ++s)
        if (!(samples[s] = calloc((size_t)frames, sizeof(double))))
            return die(1, "alloc", "out of memory");
    lat = calloc((size_t)(latency_n ? latency_n : 1), sizeof(double));
    waited = calloc((size_t)(latency_n ? latency_n : 1), sizeof(double));
    lat_wait = calloc((size_t)(latency_n ? latency_n : 1), sizeof(double));
    b.seg = wxsky_segment_new();
    b.gl[0] = wxsky_gl_new();
    b.gl[1] = wxsky_gl_new();
    if (!lat || !waited || !lat_wait || !b.seg || !b.gl[0] || !b.gl[1]) {
        printf("error alloc: out of memory\n");
        goto done;
    }
    if ((st = app_segment_open(b.seg, name, 1000, why)) != WXSKY_OK) {
        printf("error open %s\n", why);
        goto done;
    }
    if (app_copy_alloc(b.seg, &b.copy) != 0) {
        printf("error alloc: frame buffers\n");
        goto done;
    }
    for (uint32_t i = 0; i < wxsky_segment_layer_count(b.seg); ++i) /* touch the pages before timing */
        memset(b.copy.pixels[i], 0, b.copy.pixels_size[i]);
    /* the framebuffer takes the first frame's size; every frame timed must have it */
    {
        char err[WXSKY_ERROR_MAX];
        st = wxsky_frame_read(b.seg, &b.copy, 5000);
        if (st != WXSKY_OK) {
            printf("error read %s: %s\n", wxsky_status_name(st), wxsky_segment_error(b.seg));
            goto done;
        }
        st = wxsky_record_decode(b.copy.meta, b.copy.meta_length, &b.rec, err, sizeof err);
        if (st != WXSKY_OK) {
            printf("error record %s: %s\n", wxsky_status_name(st), err);
            goto done;
        }
        b.w = b.rec.width_px;
        b.h = b.rec.height_px;
    }

    if (!make_context(&e)) {
        printf("error egl: no headless EGL display with a GL context (0x%x)\n",
               (unsigned)eglGetError());
        code = 2;
        goto done;
    }
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glGenRenderbuffers(2, rb);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[0]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, (GLsizei)b.w, (GLsizei)b.h);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, rb[0]);
    glBindRenderbuffer(GL_RENDERBUFFER, rb[1]);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT24, (GLsizei)b.w, (GLsizei)b.h);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, rb[1]);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
        printf("error fbo: incomplete framebuffer\n");
        goto done;
    }
    glViewport(0, 0, (GLsizei)b.w, (GLsizei)b.h);
    if ((st = wxsky_gl_set_streaming(b.gl[1], 1)) != WXSKY_OK) {
        printf("error streaming %s: %s\n", wxsky_status_name(st), wxsky_gl_error(b.gl[1]));
        goto done;
    }
    for (int k = 0; k < 2; ++k)
        if ((st = wxsky_gl_init(b.gl[k], b.seg)) != WXSKY_OK) {
            printf("error init %s: %s\n", wxsky_status_name(st), wxsky_gl_error(b.gl[k]));
            goto done;
        }

    /* the stages: plain and PBO side by side on the same frame */
    for (int i = -warmup; i < frames; ++i) {
        double t0, t1, t2, t3, t4, t5, t6, bg = 0.0;
        glFinish();
        t0 = app_now_ms();
        if (!read_frame(&b))
            goto done;
        t1 = app_now_ms();
        if (!upload(&b, 0))
            goto done;
        t2 = app_now_ms();
        if (!composite(&b, 0, &bg))
            goto done;
        t3 = app_now_ms();
        if (!upload(&b, 1))
            goto done;
        t4 = app_now_ms();
        if (!composite(&b, 1, NULL))
            goto done;
        t5 = app_now_ms();
        /* once more with every ring layer, as after a ring rebuild (ring_version changed) */
        wxsky_gl_invalidate(b.gl[0]);
        if (!upload(&b, 0))
            goto done;
        t6 = app_now_ms();
        if (i >= 0) {
            samples[S_READ][i] = t1 - t0;
            samples[S_UP0][i] = t2 - t1;
            samples[S_COMP0][i] = t3 - t2;
            samples[S_UP1][i] = t4 - t3;
            samples[S_COMP1][i] = t5 - t4;
            samples[S_HOST0][i] = t3 - t1;
            samples[S_HOST1][i] = t5 - t3;
            samples[S_RINGS0][i] = t6 - t5;
            samples[S_BG0][i] = bg;
            if (i == -warmup || b.rec.ring_version != last_ring)
                ++ring_uploads; /* the compositor's rule: the first upload, then a change */
        }
        last_ring = b.rec.ring_version;
    }

    /* latency: set_camera -> a composited frame for that camera */
    if (latency_n > 0) {
        client = wxsky_client_new(0, 0);
        if (!client) {
            printf("error alloc: client\n");
            goto done;
        }
        if ((st = wxsky_client_connect(client, control)) != WXSKY_OK) {
            printf("error connect %s: %s\n", wxsky_status_name(st), wxsky_client_error(client));
            goto done;
        }
    }
    for (int i = 0; i < latency_n; ++i) {
        wxsky_camera cam;
        wxsky_message msg;
        uint64_t seen = wxsky_segment_latest_frame(b.seg);
        uint64_t first = seen;
        double t0, deadline;
        int got = 0;
        memset(&cam, 0, sizeof cam);
        memcpy(cam.position_m, b.rec.position_m, sizeof cam.position_m);
        cam.heading_deg = fmod(b.rec.heading_deg + 37.0, 360.0);
        cam.pitch_deg = b.rec.pitch_deg;
        cam.roll_deg = b.rec.roll_deg;
        cam.fov_deg = b.rec.fov_deg;
        t0 = app_now_ms();
        deadline = t0 + 30000.0;
        if ((st = wxsky_set_camera(client, &cam, NULL)) != WXSKY_OK) {
            printf("error set_camera %s: %s\n", wxsky_status_name(st),
                   wxsky_client_error(client));
            goto done;
        }
        while (!got) {
            uint64_t latest;
            while ((st = wxsky_client_poll(client, &msg)) == WXSKY_OK)
                if (msg.kind == WXSKY_RESPONSE && msg.error) {
                    printf("error set_camera: %.*s\n", (int)msg.error_len, msg.error);
                    goto done;
                }
            if (st != WXSKY_AGAIN) {
                printf("error poll %s: %s\n", wxsky_status_name(st), wxsky_client_error(client));
                goto done;
            }
            latest = wxsky_segment_latest_frame(b.seg);
            if (latest > seen) {
                /* a cheap look at the record first (zero-copy), the copy only when it matches */
                wxsky_frame_view fv;
                wxsky_record r;
                char err[WXSKY_ERROR_MAX];
                if (wxsky_frame_begin(b.seg, &fv) == WXSKY_OK) {
                    int ok = wxsky_record_decode(fv.meta, fv.meta_length, &r, err, sizeof err) ==
                                 WXSKY_OK && app_same_camera(&r, &cam);
                    if (wxsky_frame_end(b.seg, &fv) == WXSKY_OK) {
                        seen = fv.frame_number;
                        if (ok) {
                            lat_wait[i] = app_now_ms() - t0;
                            if (!read_frame(&b) || !app_same_camera(&b.rec, &cam))
                                goto done;
                            if (!upload(&b, 0) || !composite(&b, 0, NULL))
                                goto done;
                            lat[i] = app_now_ms() - t0;
                            waited[i] = (double)(b.copy.frame_number - first);
                            got = 1;
                            ++matched;
                        }
                    }
                }
            }
            if (!got) {
                if (app_now_ms() > deadline) {
                    printf("error latency: no frame for the camera sent within 30 s\n");
                    goto done;
                }
                app_sleep_ms(0.2);
            }
        }
    }

    printf("{\"renderer\":\"%s\",\"width\":%u,\"height\":%u,\"frames\":%d,\"ring_uploads\":%d,"
           "\"stages\":{",
           (const char *)glGetString(GL_RENDERER), b.w, b.h, frames, ring_uploads);
    for (int s = 0; s < S_COUNT; ++s) {
        printf("%s\"%s\":", s ? "," : "", STAGE_NAMES[s]);
        app_print_stats(samples[s], frames);
    }
    printf("}");
    if (latency_n > 0) {
        double wsum = 0.0;
        for (int i = 0; i < latency_n; ++i)
            wsum += waited[i];
        printf(",\"latency\":");
        app_print_stats(lat, latency_n);
        printf(",\"latency_wait\":");
        app_print_stats(lat_wait, latency_n);
        printf(",\"latency_camera_matched\":%s,\"latency_frames_waited_mean\":%.3f",
               matched == latency_n ? "true" : "false", wsum / latency_n);
    }
    printf("}\n");
    code = 0;
done:
    if (e.ctx) {
        wxsky_gl_free(b.gl[0]);
        wxsky_gl_free(b.gl[1]);
        b.gl[0] = b.gl[1] = NULL;
        if (fbo)
            glDeleteFramebuffers(1, &fbo);
        if (rb[0])
            glDeleteRenderbuffers(2, rb);
        close_context(&e);
    }
    wxsky_gl_free(b.gl[0]);
    wxsky_gl_free(b.gl[1]);
    wxsky_client_free(client);
    for (int s = 0; s < S_COUNT; ++s)
        free(samples[s]);
    free(lat);
    free(waited);
    free(lat_wait);
    for (int i = 0; i < WXSKY_MAX_LAYERS; ++i)
        free(b.copy.pixels[i]);
    free(b.copy.meta);
    wxsky_segment_free(b.seg);
    return code;
}
