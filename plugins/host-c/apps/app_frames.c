/* The programs' GL-free plumbing (app.h): frame buffers, the control calls, waiting for the
 * daemon's frames, arguments. Linked by the GL test programs too, GL or GLES alike. */
#include "app.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

int app_copy_alloc(const wxsky_segment *seg, wxsky_frame_copy *copy) {
    memset(copy, 0, sizeof *copy);
    for (uint32_t i = 0; i < wxsky_segment_layer_count(seg); ++i) {
        wxsky_layer_info info;
        if (wxsky_segment_layer(seg, i, &info) != WXSKY_OK)
            return -1;
        copy->pixels[i] = malloc(info.capacity ? info.capacity : 1);
        copy->pixels_size[i] = info.capacity;
        if (!copy->pixels[i])
            return -1;
    }
    copy->meta_size = wxsky_segment_meta_capacity(seg);
    copy->meta = malloc(copy->meta_size ? copy->meta_size : 1);
    return copy->meta ? 0 : -1;
}

void app_copy_free(wxsky_frame_copy *copy) {
    for (int i = 0; i < WXSKY_MAX_LAYERS; ++i)
        free(copy->pixels[i]);
    free(copy->meta);
    memset(copy, 0, sizeof *copy);
}

double app_now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

void app_sleep_ms(double ms) {
    struct timespec ts;
    ts.tv_sec = (time_t)(ms / 1e3);
    ts.tv_nsec = (long)((ms - (double)ts.tv_sec * 1e3) * 1e6);
    nanosleep(&ts, NULL);
}

int app_segment_open(wxsky_segment *seg, const char *name, int timeout_ms, char *err) {
    double deadline = app_now_ms() + timeout_ms;
    int st;
    while ((st = wxsky_segment_open(seg, name)) == WXSKY_STARTING && app_now_ms() < deadline)
        app_sleep_ms(5.0);
    if (st != WXSKY_OK)
        snprintf(err, APP_ERR, "shared memory %s: %s: %s", name, wxsky_status_name(st),
                 wxsky_segment_error(seg));
    return st;
}

int app_call(wxsky_client *c, const char *method, const wxsky_mp_writer *w, int timeout_ms,
             wxsky_message *result, char *err) {
    int st;
    if (w && w->overflow) {
        snprintf(err, APP_ERR, "%s: the parameters do not fit the buffer", method);
        return WXSKY_ENOSPC;
    }
    st = wxsky_client_call(c, method, w ? w->buf : NULL, w ? w->len : 0, timeout_ms, result);
    if (st != WXSKY_OK)
        snprintf(err, APP_ERR, "%s: %s: %s", method, wxsky_status_name(st),
                 wxsky_client_error(c));
    return st;
}

int app_camera_from_result(const wxsky_message *result, wxsky_camera *cam) {
    wxsky_mp_reader r;
    uint32_t n, k, len;
    uint64_t u;
    const char *key;
    int seen = 0;
    memset(cam, 0, sizeof *cam);
    if (!result || !result->body)
        return WXSKY_EFORMAT;
    wxsky_mp_reader_init(&r, result->body, result->body_len);
    if (wxsky_mp_read_map(&r, &n) != WXSKY_OK)
        return WXSKY_EFORMAT;
    for (k = 0; k < n; ++k) {
        if (wxsky_mp_read_str(&r, &key, &len) != WXSKY_OK)
            return WXSKY_EFORMAT;
#define KEY(s) (len == sizeof(s) - 1 && !memcmp(key, s, len))
        if (KEY("position_m")) {
            uint32_t m;
            if (wxsky_mp_read_array(&r, &m) != WXSKY_OK || m != 3)
                return WXSKY_EFORMAT;
            for (uint32_t i = 0; i < 3; ++i)
                if (wxsky_mp_read_double(&r, &cam->position_m[i]) != WXSKY_OK)
                    return WXSKY_EFORMAT;
            seen |= 1;
        } else if (KEY("heading_deg")) {
            seen |= (wxsky_mp_read_double(&r, &cam->heading_deg) == WXSKY_OK) << 1;
        } else if (KEY("pitch_deg")) {
            seen |= (wxsky_mp_read_double(&r, &cam->pitch_deg) == WXSKY_OK) << 2;
        } else if (KEY("roll_deg")) {
            seen |= (wxsky_mp_read_double(&r, &cam->roll_deg) == WXSKY_OK) << 3;
        } else if (KEY("fov_deg")) {
            seen |= (wxsky_mp_read_double(&r, &cam->fov_deg) == WXSKY_OK) << 4;
        } else if (KEY("width")) {
            if (wxsky_mp_read_uint(&r, &u) != WXSKY_OK || u > UINT32_MAX)
                return WXSKY_EFORMAT;
            cam->width = (uint32_t)u;
            seen |= 1 << 5;
        } else if (KEY("height")) {
            if (wxsky_mp_read_uint(&r, &u) != WXSKY_OK || u > UINT32_MAX)
                return WXSKY_EFORMAT;
            cam->height = (uint32_t)u;
            seen |= 1 << 6;
        } else if (wxsky_mp_skip(&r) != WXSKY_OK) {
            return WXSKY_EFORMAT;
        }
#undef KEY
    }
    return seen == 0x7f ? WXSKY_OK : WXSKY_EFORMAT;
}

int app_same_camera(const wxsky_record *rec, const wxsky_camera *cam) {
    for (int k = 0; k < 3; ++k)
        if (fabs(rec->position_m[k] - cam->position_m[k]) > 1e-6)
            return 0;
    return fabs(rec->heading_deg - cam->heading_deg) < 1e-9 &&
           fabs(rec->pitch_deg - cam->pitch_deg) < 1e-9 &&
           fabs(rec->roll_deg - cam->roll_deg) < 1e-9 &&
           fabs(rec->fov_deg - cam->fov_deg) < 1e-9 &&
           (cam->width == 0 || rec->width_px == cam->width) &&
           (cam->height == 0 || rec->height_px == cam->height);
}

int app_wait_frame(wxsky_segment *seg, wxsky_frame_copy *copy, wxsky_record *rec,
                   uint64_t after, const wxsky_camera *cam, int timeout_ms, char *err) {
    double deadline = app_now_ms() + timeout_ms;
    char why[WXSKY_ERROR_MAX];
    int st;
    for (;;) {
        if (wxsky_segment_latest_frame(seg) > after) {
            st = wxsky_frame_read(seg, copy, 1000);
            if (st != WXSKY_OK && st != WXSKY_AGAIN && st != WXSKY_ETIMEDOUT) {
                snprintf(err, APP_ERR, "reading a frame: %s: %s", wxsky_status_name(st),
                         wxsky_segment_error(seg));
                return st;
            }
            if (st == WXSKY_OK && copy->frame_number > after) {
                st = wxsky_record_decode(copy->meta, copy->meta_length, rec, why, sizeof why);
                if (st != WXSKY_OK) {
                    snprintf(err, APP_ERR, "frame %llu: %s",
                             (unsigned long long)copy->frame_number, why);
                    return st;
                }
                if (!cam || app_same_camera(rec, cam))
                    return WXSKY_OK;
                after = copy->frame_number;
            }
        }
        if (app_now_ms() > deadline) {
            snprintf(err, APP_ERR, "no frame %s after #%llu within %d ms",
                     cam ? "for the camera set" : "published", (unsigned long long)after,
                     timeout_ms);
            return WXSKY_ETIMEDOUT;
        }
        app_sleep_ms(2.0);
    }
}

/* `scene`'s ring_busy: 1, 0, or -1 with err. */
static int ring_busy(wxsky_client *c, int timeout_ms, char *err) {
    wxsky_message res;
    wxsky_mp_reader r;
    uint32_t n;
    int busy = 0;
    if (app_call(c, "scene", NULL, timeout_ms, &res, err) != WXSKY_OK)
        return -1;
    wxsky_mp_reader_init(&r, res.body, res.body_len);
    if (wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "ring_busy") != WXSKY_OK ||
        wxsky_mp_read_bool(&r, &busy) != WXSKY_OK) {
        snprintf(err, APP_ERR, "scene: no ring_busy in the result");
        return -1;
    }
    return busy;
}

int app_wait_settled_frame(wxsky_client *c, wxsky_segment *seg, wxsky_frame_copy *copy,
                           wxsky_record *rec, const wxsky_camera *cam, int timeout_ms,
                           char *err) {
    double deadline = app_now_ms() + timeout_ms;
    int busy, st;
    for (;;) {
        int left = (int)(deadline - app_now_ms());
        if ((busy = ring_busy(c, left > 100 ? left : 100, err)) < 0)
            return WXSKY_EFORMAT;
        if (!busy)
            break;
        if (app_now_ms() > deadline) {
            snprintf(err, APP_ERR, "the ring did not settle within %d ms", timeout_ms);
            return WXSKY_ETIMEDOUT;
        }
        /* a ring takes seconds: asked often, `scene` only takes the daemon's time */
        app_sleep_ms(50.0);
    }
    /* a frame drawn after the ring was seen settled */
    st = app_wait_frame(seg, copy, rec, wxsky_segment_latest_frame(seg), cam,
                        (int)fmax(1000.0, deadline - app_now_ms()), err);
    if (st == WXSKY_OK && rec->fading) {
        snprintf(err, APP_ERR, "frame %llu is still fading in a ring",
                 (unsigned long long)rec->frame_number);
        return WXSKY_EFORMAT;
    }
    return st;
}

/* The segment's name from `scene` into name (size bytes). */
static int scene_shm_name(wxsky_client *c, int timeout_ms, char *name, size_t size, char *err) {
    wxsky_message res;
    wxsky_mp_reader r;
    uint32_t n, len;
    const char *s;
    if (app_call(c, "scene", NULL, timeout_ms, &res, err) != WXSKY_OK)
        return -1;
    wxsky_mp_reader_init(&r, res.body, res.body_len);
    if (wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "shm_name") != WXSKY_OK ||
        wxsky_mp_read_str(&r, &s, &len) != WXSKY_OK || len + 1 > size) {
        snprintf(err, APP_ERR, "scene: no usable shm_name in the result");
        return -1;
    }
    memcpy(name, s, len);
    name[len] = '\0';
    return 0;
}

int app_attach(wxsky_client *c, wxsky_segment *seg, wxsky_frame_copy *copy, const char *control,
               const char *shm, int timeout_ms, char *err) {
    char name[256];
    int st;
    if ((st = wxsky_client_connect(c, control)) != WXSKY_OK) {
        snprintf(err, APP_ERR, "%s: %s", control ? control : "the default address",
                 wxsky_client_error(c));
        return -1;
    }
    if (!shm) {
        if (scene_shm_name(c, timeout_ms, name, sizeof name, err) != 0)
            return -1;
        shm = name;
    }
    if (app_segment_open(seg, shm, timeout_ms, err) != WXSKY_OK)
        return -1;
    if (app_copy_alloc(seg, copy) != 0) {
        snprintf(err, APP_ERR, "out of memory for the frame buffers");
        return -1;
    }
    return 0;
}

int app_parse_size(const char *prog, const char *flag, const char *text, uint32_t max_px,
                   uint32_t *width, uint32_t *height) {
    unsigned w = 0, h = 0;
    char x = 0, extra = 0;
    if (sscanf(text, "%u%c%u%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X') || w < 16 ||
        h < 16 || w > max_px || h > max_px) {
        fprintf(stderr, "%s: error: %s %s is not WxH with each 16..%u\n", prog, flag, text,
                max_px);
        return 0;
    }
    *width = w;
    *height = h;
    return 1;
}

int app_parse_number(const char *prog, const char *flag, const char *text, double lo, double hi,
                     double *out) {
    char *end;
    errno = 0;
    *out = strtod(text, &end);
    if (errno || end == text || *end || !isfinite(*out) || *out < lo || *out > hi) {
        fprintf(stderr, "%s: error: %s %s is not a number in %g..%g\n", prog, flag, text, lo, hi);
        return 0;
    }
    return 1;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* {"n":..,"median_ms":..,"p95_ms":..,"mean_ms":..,"max_ms":..}; sorts v */
void app_print_stats(double *v, int n) {
    double sum = 0.0, median, p95;
    int k;
    qsort(v, (size_t)n, sizeof *v, cmp_double);
    for (int i = 0; i < n; ++i)
        sum += v[i];
    median = n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
    k = (int)ceil(0.95 * n) - 1; /* nearest rank */
    p95 = v[k < 0 ? 0 : k];
    printf("{\"n\":%d,\"median_ms\":%.4f,\"p95_ms\":%.4f,\"mean_ms\":%.4f,\"max_ms\":%.4f}", n,
           median, p95, sum / n, v[n - 1]);
}
