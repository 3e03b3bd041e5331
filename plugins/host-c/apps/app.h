/* What the kit's programs (wxsky-host-snapshot, wxsky-host-demo) share: a headless EGL
 * context with an offscreen framebuffer, frame buffers sized to a segment, a blocking control
 * call with a map of parameters, and waiting for the daemon's frame drawn for a camera.
 * Not part of the library: a simulator has its own window, loop and error reporting. */
#ifndef WXSKY_APPS_APP_H
#define WXSKY_APPS_APP_H

#include <stddef.h>
#include <stdint.h>

#include "gl_api.h"
#include "wxsky_host.h"
#include "wxsky_host_gl.h"

#define APP_ERR 512

/* A headless GL context (surfaceless Mesa, an EGL device, or the default display) with an
 * RGBA8 + 24-bit depth framebuffer object of width x height bound and its viewport set. */
typedef struct app_gl {
    void *egl_; /* private */
    GLuint fbo, color, depth;
    uint32_t width, height;
    /* app_gl_open_linear's float framebuffer (RGBA32F texture, the same depth buffer): where
     * HDR layers are composited in linear; 0 until then */
    GLuint linear_fbo, linear_tex;
} app_gl;

/* 0 on success; -1 with err when GL or the framebuffer could not be made (exit code 2 for the
 * programs: no headless GL here). */
int app_gl_open(app_gl *g, uint32_t width, uint32_t height, char *err);
/* Reads the framebuffer into rgba (width * height * 4), top row first when the frame was
 * drawn with wxsky_gl_camera_matrices(..., flip_y 1, ...). 0 or -1 with err. */
int app_gl_read(const app_gl *g, uint8_t *rgba, char *err);
void app_gl_close(app_gl *g);
/* For RGBA16F layers: adds a float framebuffer of the same size (an RGBA32F texture and the
 * depth buffer) and binds it, so a composite that follows is scene-linear and unclipped.
 * 0 or -1 with err. */
int app_gl_open_linear(app_gl *g, char *err);
/* Reads the float framebuffer into rgba (width * height * 4 floats), rows as app_gl_read. */
int app_gl_read_linear(const app_gl *g, float *rgba, char *err);
/* Binds the RGBA8 framebuffer and draws the float one's composite into it through the
 * daemon's exposure and tone map (wxsky_gl_tone_map): app_gl_read then reads display values. */
int app_gl_tone_map(const app_gl *g, wxsky_gl_compositor *gl, float exposure, char *err);

/* Buffers for every layer of an open segment at its capacity, and its metadata. */
int app_copy_alloc(const wxsky_segment *seg, wxsky_frame_copy *copy);
void app_copy_free(wxsky_frame_copy *copy);

/* Opens a segment, waiting up to timeout_ms while the daemon is still making it. */
int app_segment_open(wxsky_segment *seg, const char *name, int timeout_ms, char *err);

/* Connects c to the daemon at `control` (NULL: the default address, §2.1), opens its segment
 * `shm` (NULL: the one `scene` names) and allocates copy for it. 0, or -1 with err. */
int app_attach(wxsky_client *c, wxsky_segment *seg, wxsky_frame_copy *copy, const char *control,
               const char *shm, int timeout_ms, char *err);

/* Command-line values: "WxH" with each 16..max_px, and a finite number in lo..hi. 1 on
 * success; 0 after printing "PROG: error: FLAG TEXT is not ..." on stderr. */
int app_parse_size(const char *prog, const char *flag, const char *text, uint32_t max_px,
                   uint32_t *width, uint32_t *height);
int app_parse_number(const char *prog, const char *flag, const char *text, double lo, double hi,
                     double *out);

/* One line of timing figures for the benchmarks: {"n", "median_ms", "p95_ms" (nearest rank),
 * "mean_ms", "max_ms"} on stdout, no newline; sorts v (n >= 1). */
void app_print_stats(double *v, int n);

/* Milliseconds on the monotonic clock; a sleep. */
double app_now_ms(void);
void app_sleep_ms(double ms);

/* One blocking call whose params the caller has written into w (a map); the result (may be
 * NULL) stays valid until the next call on the client. WXSKY_OK or the status with err. */
int app_call(wxsky_client *c, const char *method, const wxsky_mp_writer *w, int timeout_ms,
             wxsky_message *result, char *err);

/* The camera a set_camera result describes (§5: position_m, heading_deg, pitch_deg, roll_deg,
 * fov_deg, width, height). WXSKY_OK or WXSKY_EFORMAT. */
int app_camera_from_result(const wxsky_message *result, wxsky_camera *cam);
/* The record was drawn for that camera (exactly: the daemon echoes what it draws with). */
int app_same_camera(const wxsky_record *rec, const wxsky_camera *cam);

/* Copies the first frame published after frame `after` whose record is for `cam` (NULL: any
 * camera) into copy and rec. WXSKY_OK, or WXSKY_ETIMEDOUT / another status with err. */
int app_wait_frame(wxsky_segment *seg, wxsky_frame_copy *copy, wxsky_record *rec,
                   uint64_t after, const wxsky_camera *cam, int timeout_ms, char *err);

/* Waits until the daemon's ring has settled for what it was last told (`scene` says
 * ring_busy false, §3.1: no rebuild building, rendering or fading), then copies the next frame
 * for `cam` as app_wait_frame does. The frames after a set_time or set_camera must be waited
 * for first (a frame after the requests were answered), so the rebuild they cause has begun. */
int app_wait_settled_frame(wxsky_client *c, wxsky_segment *seg, wxsky_frame_copy *copy,
                           wxsky_record *rec, const wxsky_camera *cam, int timeout_ms,
                           char *err);

/* Composites the frame in copy/rec into the bound framebuffer for the record's camera
 * (sky and ring, near, near_front), clearing colour to opaque black and depth to 1 first. */
int app_composite(wxsky_gl_compositor *gl, const wxsky_frame_copy *copy, const wxsky_record *rec,
                  char *err);

#endif
