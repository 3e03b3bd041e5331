/* wxsky_gl_zero_copy: a host that asks a running daemon for its layer textures (protocol §6),
 * imports them where the daemon exports and this GL imports dma-bufs, and otherwise falls back
 * to the shared-memory segment; then composites the latest frame, or times both paths. For
 * tests/test_zero_copy.py and tools/bench/bench_host_c.py --zero-copy.
 *
 *   wxsky_gl_zero_copy ADDR SEGMENT OUT.rgba [--require] [--wait-stdin]
 *   wxsky_gl_zero_copy ADDR SEGMENT --bench N [--require]
 *
 * Lines on stdout:
 *   textures STATUS supported 0|1 count N fds N reason TEXT   the export_textures answer
 *   import ok | import failed STATUS: MESSAGE                  only when supported
 *   ok WIDTHxHEIGHT frame N mode zero-copy|shm renderer R      the composite written
 * --wait-stdin: after the textures line, wait for a line on stdin before reading the frame
 * (the test stops the daemon in between, so both hosts read the same frame). --require: exit
 * 3 unless the frame went zero-copy. --bench N: instead of a picture, N frames of each path
 * (after 2 untimed), each timed to the end of its GPU work, as one JSON line {"mode",
 * "reason", "renderer", "width", "height", "stages": {"shm_view_upload": {...},
 * "zero_copy_import": {...}}} (zero_copy_import only when imported). Failure: one line
 * "error ..." and exit 1; exit 2 when no headless EGL/GL context could be made. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "app.h"
#include "gl_context.h"

/* One frame into the compositor: zero-copy or from the view, retried while torn. */
static int take_frame(wxsky_segment *seg, wxsky_gl_compositor *gl, int zero_copy,
                      wxsky_record *rec, uint64_t *frame) {
    char err[WXSKY_ERROR_MAX];
    for (int tries = 0; tries < 200; ++tries) {
        wxsky_frame_view v;
        int st = wxsky_frame_begin(seg, &v);
        if (st == WXSKY_AGAIN) {
            struct timespec ts = {0, 1000000};
            nanosleep(&ts, NULL);
            continue;
        }
        if (st != WXSKY_OK) {
            printf("error begin %s: %s\n", wxsky_status_name(st), wxsky_segment_error(seg));
            return st;
        }
        st = wxsky_record_decode(v.meta, v.meta_length, rec, err, sizeof err);
        if (st == WXSKY_OK)
            st = zero_copy ? wxsky_gl_import_view(gl, &v, rec) : wxsky_gl_upload_view(gl, &v, rec);
        if (wxsky_frame_end(seg, &v) == WXSKY_ETORN) {
            wxsky_gl_invalidate(gl);
            continue; /* the daemon came back to the slot: everything taken is void */
        }
        if (st != WXSKY_OK) {
            printf("error frame %s: %s\n", wxsky_status_name(st),
                   st == WXSKY_EFORMAT || st == WXSKY_EVERSION ? err : wxsky_gl_error(gl));
            return st;
        }
        *frame = v.frame_number;
        return WXSKY_OK;
    }
    printf("error frame: torn 200 times\n");
    return WXSKY_ETORN;
}

static int bench(wxsky_segment *seg, wxsky_gl_compositor *gl, int zero_copy, int frames,
                 const char *why) {
    double *shm = calloc((size_t)frames, sizeof *shm), *zc = calloc((size_t)frames, sizeof *zc);
    wxsky_record rec;
    uint64_t frame;
    int st = WXSKY_OK;
    if (!shm || !zc) {
        free(shm);
        free(zc);
        printf("error alloc\n");
        return 1;
    }
    memset(&rec, 0, sizeof rec);
    for (int i = -2; i < frames && st == WXSKY_OK; ++i) {
        double t0 = app_now_ms();
        wxsky_gl_invalidate(gl); /* every layer, the ring's too: the full cost of a frame */
        st = take_frame(seg, gl, 0, &rec, &frame);
        glFinish();
        if (i >= 0)
            shm[i] = app_now_ms() - t0;
        if (st == WXSKY_OK && zero_copy) {
            t0 = app_now_ms();
            wxsky_gl_invalidate(gl);
            st = take_frame(seg, gl, 1, &rec, &frame);
            glFinish();
            if (i >= 0)
                zc[i] = app_now_ms() - t0;
        }
    }
    if (st == WXSKY_OK) {
        printf("{\"mode\":\"%s\",\"reason\":\"", zero_copy ? "zero-copy" : "shm");
        for (const char *p = why; *p; ++p)
            if (*p != '"' && *p != '\\')
                putchar(*p);
        printf("\",\"renderer\":\"%s\",\"width\":%u,\"height\":%u,\"stages\":{"
               "\"shm_view_upload\":",
               (const char *)glGetString(GL_RENDERER), rec.width_px, rec.height_px);
        app_print_stats(shm, frames);
        if (zero_copy) {
            printf(",\"zero_copy_import\":");
            app_print_stats(zc, frames);
        }
        printf("}}\n");
    }
    free(shm);
    free(zc);
    return st == WXSKY_OK ? 0 : 1;
}

int main(int argc, char **argv) {
    char open_err[APP_ERR];
    const char *address, *name, *out_path = NULL;
    int require = 0, wait_stdin = 0, frames = 0, st, code = 1, zero_copy = 0;
    wxsky_client *client = NULL;
    wxsky_segment *seg = NULL;
    wxsky_gl_compositor *gl = NULL;
    wxsky_textures *tex = NULL;
    wxsky_record rec;
    egl_state e;
    GLuint fbo = 0, rb = 0;
    double view[16], proj[16];
    uint64_t frame = 0;
    uint8_t *pixels = NULL;
    char why[WXSKY_ERROR_MAX] = "-"; /* why not zero-copy */
    FILE *f;

    if (argc < 3)
        return die(1, "usage", "wxsky_gl_zero_copy ADDR SEGMENT (OUT.rgba | --bench N) "
                               "[--require] [--wait-stdin]");
    address = argv[1];
    name = argv[2];
    for (int i = 3; i < argc; ++i) {
        if (!strcmp(argv[i], "--require"))
            require = 1;
        else if (!strcmp(argv[i], "--wait-stdin"))
            wait_stdin = 1;
        else if (!strcmp(argv[i], "--bench") && i + 1 < argc && atoi(argv[i + 1]) > 0)
            frames = atoi(argv[++i]);
        else if (argv[i][0] != '-' && !out_path)
            out_path = argv[i];
        else
            return die(1, "usage", argv[i]);
    }
    if (!out_path && !frames)
        return die(1, "usage", "give OUT.rgba or --bench N");
    memset(&e, 0, sizeof e);
    client = wxsky_client_new(0, 0);
    seg = wxsky_segment_new();
    gl = wxsky_gl_new();
    tex = malloc(sizeof *tex);
    if (!client || !seg || !gl || !tex) {
        printf("error alloc: out of memory\n");
        goto done;
    }
    wxsky_textures_init(tex);

    /* 1. ask; any answer but supported 1 means: the segment */
    if ((st = wxsky_client_connect(client, address)) != WXSKY_OK) {
        printf("error connect %s: %s\n", wxsky_status_name(st), wxsky_client_error(client));
        goto done;
    }
    st = wxsky_request_textures(client, 10000, tex);
    if (st == WXSKY_EREMOTE)
        snprintf(tex->reason, sizeof tex->reason, "%s", wxsky_client_error(client));
    else if (st != WXSKY_OK) {
        printf("error textures %s: %s\n", wxsky_status_name(st), wxsky_client_error(client));
        goto done;
    }
    if (!tex->supported)
        snprintf(why, sizeof why, "%s", tex->reason);
    printf("textures %s supported %d count %u fds %u reason %s\n", wxsky_status_name(st),
           tex->supported, tex->count, tex->fd_count, why);
    fflush(stdout);
    if (wait_stdin) {
        char line[16];
        if (!fgets(line, sizeof line, stdin)) {
            printf("error stdin: closed\n");
            goto done;
        }
    }

    /* 2. the segment and the GL context */
    if ((st = app_segment_open(seg, name, 1000, open_err)) != WXSKY_OK) {
        printf("error open %s\n", open_err);
        goto done;
    }
    if (!make_context(&e)) {
        printf("error egl: no headless EGL display with a GL context (0x%x)\n",
               (unsigned)eglGetError());
        code = 2;
        goto done;
    }
    if ((st = wxsky_gl_init(gl, seg)) != WXSKY_OK) {
        printf("error init %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    if (tex->supported) {
        st = wxsky_gl_import_textures(gl, seg, tex, e.dpy, (wxsky_gl_get_proc)eglGetProcAddress);
        if (st == WXSKY_OK)
            printf("import ok\n");
        else {
            printf("import failed %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
            snprintf(why, sizeof why, "%s", wxsky_gl_error(gl));
        }
        zero_copy = wxsky_gl_zero_copy(gl);
    }
    wxsky_textures_close(tex); /* imported images keep their own references */
    if (require && !zero_copy) {
        printf("error require: not zero-copy\n");
        code = 3;
        goto done;
    }
    if (frames) {
        code = bench(seg, gl, zero_copy, frames, why);
        goto done;
    }

    /* 3. one frame, composited */
    if (take_frame(seg, gl, zero_copy, &rec, &frame) != WXSKY_OK)
        goto done;
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glGenRenderbuffers(1, &rb);
    glBindRenderbuffer(GL_RENDERBUFFER, rb);
    glRenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, (GLsizei)rec.width_px,
                          (GLsizei)rec.height_px);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, rb);
    if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
        printf("error fbo: incomplete framebuffer\n");
        goto done;
    }
    glViewport(0, 0, (GLsizei)rec.width_px, (GLsizei)rec.height_px);
    glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
    glClear(GL_COLOR_BUFFER_BIT);
    wxsky_gl_camera_matrices(&rec, 1, view, proj);
    if ((st = wxsky_gl_draw_background(gl, view, proj)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near(gl)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near_front(gl)) != WXSKY_OK) {
        printf("error draw %s: %s\n", wxsky_status_name(st), wxsky_gl_error(gl));
        goto done;
    }
    pixels = malloc((size_t)rec.width_px * rec.height_px * 4);
    if (!pixels)
        goto done;
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glReadPixels(0, 0, (GLsizei)rec.width_px, (GLsizei)rec.height_px, GL_RGBA, GL_UNSIGNED_BYTE,
                 pixels);
    f = fopen(out_path, "wb");
    if (!f || fwrite(pixels, 1, (size_t)rec.width_px * rec.height_px * 4, f) !=
                  (size_t)rec.width_px * rec.height_px * 4) {
        printf("error write: %s\n", out_path);
        if (f)
            fclose(f);
        goto done;
    }
    fclose(f);
    printf("ok %ux%u frame %llu mode %s renderer %s\n", rec.width_px, rec.height_px,
           (unsigned long long)frame, zero_copy ? "zero-copy" : "shm",
           (const char *)glGetString(GL_RENDERER));
    code = 0;
done:
    if (e.ctx) {
        wxsky_gl_free(gl);
        gl = NULL;
        if (fbo)
            glDeleteFramebuffers(1, &fbo);
        if (rb)
            glDeleteRenderbuffers(1, &rb);
        close_context(&e);
    }
    wxsky_gl_free(gl);
    wxsky_textures_close(tex);
    free(tex);
    free(pixels);
    wxsky_segment_free(seg);
    wxsky_client_free(client);
    return code;
}
