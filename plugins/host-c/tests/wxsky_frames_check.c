/* wxsky_frames_check: the frames half of the host kit (segment, seqlock reads, frame record)
 * driven from the command line, for tests/test_host_c_frames.py and by hand.
 *
 *   wxsky_frames_check open NAME
 *       the header and layer table, one JSON object
 *   wxsky_frames_check read NAME [--frames N] [--timeout-ms T] [--pattern]
 *   wxsky_frames_check view NAME [--frames N] [--timeout-ms T] [--pattern]
 *       N distinct frames (waiting for newer ones with wxsky_segment_latest_frame), copied out
 *       with wxsky_frame_read (read) or used in place with wxsky_frame_begin/end (view): one
 *       JSON line per frame (frame number, the decoded record, each layer's size and FNV-1a 64
 *       of its pixels, and a consistency verdict), then a summary line
 *   wxsky_frames_check probe NAME...
 *       for each name one JSON line with the status and message of open, check, a read, the
 *       record decode, a view and its end: for bad segments; exits 0 unless it crashes
 *   wxsky_frames_check repl NAME
 *       one command a line on stdin (open, close, check, header, latest, read [TIMEOUT_MS],
 *       read_small LAYER, read_nobuf, begin, end, quit), one JSON line each on stdout
 *   wxsky_frames_check display EXPOSURE
 *       for each line "R G B" (straight scene-linear colour) on stdin, wxsky_display's
 *       display values "R G B" on stdout (%.9g): the HDR layers' tone map, for the tests to
 *       hold against wxsky/scene/exposure.py
 *   wxsky_frames_check half
 *       for each line of a binary16 value in hex on stdin, wxsky_half_to_float's value (%.17g)
 *   wxsky_frames_check fuzz SRC DST [--seed S] [--iterations N]
 *       copies segment SRC, and N times writes a randomly mutated copy (header, slot headers,
 *       layer tables and record bytes, or a truncation) to segment DST and opens and reads it
 *       with every call; prints the tally of statuses
 *
 * The consistency verdict: the record must decode and carry the slot's frame number; with
 * --pattern, every layer must also hold the test pattern of that frame number (the writer in
 * the tests draws it): width max_width - f % 7, height max_height - f % 5, and pixel i (as a
 * little-endian u32; u32 word i for an RGBA16F layer) f * 2654435761 + k * 40503 + i modulo
 * 2^32 in layer k. A torn frame that was not detected would mix two frames and fail it.
 *
 * Failure: exit status 1 and one line on stderr, "wxsky_frames_check: STATUS_NAME: message";
 * 2 for a usage error. */
#include "wxsky_host.h"

#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#define PATTERN_FRAME 2654435761u
#define PATTERN_LAYER 40503u

static const char *const prog = "wxsky_frames_check";

#if defined(__GNUC__)
#define CHECK_PRINTF(f, a) __attribute__((format(printf, f, a)))
#define CHECK_NORETURN __attribute__((noreturn))
#else
#define CHECK_PRINTF(f, a)
#define CHECK_NORETURN
#endif

/* ---- output ---------------------------------------------------------------------------- */

static void die(int status, const char *fmt, ...) CHECK_PRINTF(2, 3) CHECK_NORETURN;

static void die(int status, const char *fmt, ...) {
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    for (char *c = msg; *c != '\0'; c++) {
        if (*c == '\n' || *c == '\r') {
            *c = ' ';
        }
    }
    fflush(stdout);
    fprintf(stderr, "wxsky_frames_check: %s: %s\n", wxsky_status_name(status), msg);
    exit(1);
}

static void usage(void) CHECK_NORETURN;

static void usage(void) {
    fprintf(stderr,
            "usage: wxsky_frames_check open NAME\n"
            "       wxsky_frames_check read|view NAME [--frames N] [--timeout-ms T] [--pattern]\n"
            "       wxsky_frames_check probe NAME...\n"
            "       wxsky_frames_check repl NAME\n"
            "       wxsky_frames_check fuzz SRC DST [--seed S] [--iterations N]\n"
            "       wxsky_frames_check display EXPOSURE < lines of R G B\n"
            "       wxsky_frames_check half < lines of hex binary16\n");
    exit(2);
}

/* A JSON string: quotes, backslashes and every byte outside 0x20-0x7E escaped. */
static void js_str(const char *s) {
    putchar('"');
    for (const unsigned char *c = (const unsigned char *)s; *c != '\0'; c++) {
        if (*c == '"' || *c == '\\') {
            printf("\\%c", *c);
        } else if (*c < 0x20 || *c > 0x7e) {
            printf("\\u%04x", *c);
        } else {
            putchar(*c);
        }
    }
    putchar('"');
}

static void js_key(const char *key) {
    js_str(key);
    putchar(':');
}

static void js_double(double v) {
    printf("%.17g", v);
}

static void js_vec(const double *v, int n) {
    putchar('[');
    for (int i = 0; i < n; i++) {
        if (i > 0) {
            putchar(',');
        }
        js_double(v[i]);
    }
    putchar(']');
}

static void js_quads(const double q[8][4][3]) {
    putchar('[');
    for (int i = 0; i < 8; i++) {
        printf(i > 0 ? ",[" : "[");
        for (int j = 0; j < 4; j++) {
            if (j > 0) {
                putchar(',');
            }
            js_vec(q[i][j], 3);
        }
        putchar(']');
    }
    putchar(']');
}

static void js_status(const char *key, int status, const char *error) {
    js_key(key);
    js_str(wxsky_status_name(status));
    printf(",\"%s_error\":", key);
    js_str(status == WXSKY_OK ? "" : error);
}

static void print_header(const wxsky_segment *seg) {
    wxsky_segment_header h;
    if (wxsky_segment_get_header(seg, &h) != WXSKY_OK) {
        die(WXSKY_EINVAL, "no header: the segment is not open");
    }
    printf("{\"size\":%llu,\"version\":%u,\"header_size\":%u,\"slot_count\":%u,\"layer_count\":%u,"
           "\"slot_size\":%llu,\"meta_capacity\":%u,\"writer_pid\":%u,\"active_slot\":%u,"
           "\"state\":%u,\"latest_frame\":%llu,\"publish_count\":%llu,\"layers\":[",
           (unsigned long long)h.size, (unsigned)h.version, (unsigned)h.header_size,
           (unsigned)h.slot_count, (unsigned)h.layer_count, (unsigned long long)h.slot_size,
           (unsigned)h.meta_capacity, (unsigned)h.writer_pid, (unsigned)h.active_slot,
           (unsigned)h.state, (unsigned long long)h.latest_frame,
           (unsigned long long)h.publish_count);
    for (uint32_t k = 0; k < wxsky_segment_layer_count(seg); k++) {
        wxsky_layer_info info;
        wxsky_segment_layer(seg, k, &info);
        printf(k > 0 ? ",{" : "{");
        js_key("name");
        js_str(info.name);
        printf(",\"max_width\":%u,\"max_height\":%u,\"capacity\":%llu,\"format\":%u,"
               "\"bytes_per_pixel\":%u,\"index\":%d}",
               (unsigned)info.max_width, (unsigned)info.max_height,
               (unsigned long long)info.capacity, (unsigned)info.format,
               (unsigned)info.bytes_per_pixel, wxsky_segment_find_layer(seg, info.name));
    }
    printf("]}");
}

static void print_record(const wxsky_record *r) {
    printf("{\"record_version\":%u,\"frame_number\":%llu,\"ring_version\":%llu,",
           (unsigned)r->record_version, (unsigned long long)r->frame_number,
           (unsigned long long)r->ring_version);
    js_key("time_utc_unix_s");
    js_double(r->time_utc_unix_s);
    printf(",\"position_m\":");
    js_vec(r->position_m, 3);
    printf(",\"heading_deg\":");
    js_double(r->heading_deg);
    printf(",\"pitch_deg\":");
    js_double(r->pitch_deg);
    printf(",\"roll_deg\":");
    js_double(r->roll_deg);
    printf(",\"fov_deg\":");
    js_double(r->fov_deg);
    printf(",\"width_px\":%u,\"height_px\":%u,\"sun_direction_enu\":", (unsigned)r->width_px,
           (unsigned)r->height_px);
    js_vec(r->sun_direction_enu, 3);
    printf(",\"ring_centre_m\":");
    js_vec(r->ring_centre_m, 3);
    printf(",\"ring_radius_m\":");
    js_double(r->ring_radius_m);
    printf(",\"ring_quads_m\":");
    js_quads((const double(*)[4][3])r->ring_quads_m);
    printf(",\"ring_set\":%u,\"fading\":%u,\"ring_fade\":", (unsigned)r->ring_set,
           (unsigned)r->fading);
    js_double(r->ring_fade);
    printf(",\"ring_in_centre_m\":");
    js_vec(r->ring_in_centre_m, 3);
    printf(",\"ring_in_radius_m\":");
    js_double(r->ring_in_radius_m);
    printf(",\"ring_in_quads_m\":");
    js_quads((const double(*)[4][3])r->ring_in_quads_m);
    printf(",\"shadow_version\":%llu,\"shadow_centre_m\":",
           (unsigned long long)r->shadow_version);
    js_vec(r->shadow_centre_m, 3);
    printf(",\"shadow_size_m\":");
    js_double(r->shadow_size_m);
    printf(",\"shadow_sun_enu\":");
    js_vec(r->shadow_sun_enu, 3);
    putchar('}');
}

/* ---- one frame, wherever its bytes are -------------------------------------------------- */

static uint64_t fnv1a64(const uint8_t *p, size_t n) {
    uint64_t h = 0xcbf29ce484222325ull;
    for (size_t i = 0; i < n; i++) {
        h = (h ^ p[i]) * 0x100000001b3ull;
    }
    return h;
}

typedef struct frame_result {
    uint64_t frame_number;
    uint32_t meta_length;
    uint32_t layer_count;
    uint32_t width[WXSKY_MAX_LAYERS];
    uint32_t height[WXSKY_MAX_LAYERS];
    uint64_t fnv[WXSKY_MAX_LAYERS];
    int record_status;
    char record_error[WXSKY_ERROR_MAX];
    wxsky_record record;
    char inconsistency[256]; /* "" when consistent */
} frame_result;

static void analyse(const wxsky_segment *seg, uint64_t frame_number, const uint8_t *meta,
                    uint32_t meta_length, const uint32_t *width, const uint32_t *height,
                    const uint8_t *const *pixels, int pattern, frame_result *r) {
    r->frame_number = frame_number;
    r->meta_length = meta_length;
    r->layer_count = wxsky_segment_layer_count(seg);
    r->inconsistency[0] = '\0';
    r->record_status = wxsky_record_decode(meta, meta_length, &r->record, r->record_error,
                                           sizeof r->record_error);
    if (r->record_status == WXSKY_OK && r->record.frame_number != frame_number) {
        snprintf(r->inconsistency, sizeof r->inconsistency,
                 "record frame_number %llu, slot frame_number %llu",
                 (unsigned long long)r->record.frame_number, (unsigned long long)frame_number);
    }
    for (uint32_t k = 0; k < r->layer_count; k++) {
        wxsky_layer_info li;
        wxsky_segment_layer(seg, k, &li);
        size_t n = (size_t)width[k] * height[k] * li.bytes_per_pixel;
        r->width[k] = width[k];
        r->height[k] = height[k];
        r->fnv[k] = fnv1a64(pixels[k], pixels[k] == NULL ? 0 : n);
        if (!pattern || r->inconsistency[0] != '\0') {
            continue;
        }
        wxsky_layer_info info;
        wxsky_segment_layer(seg, k, &info);
        uint32_t ew = info.max_width - (uint32_t)(frame_number % 7);
        uint32_t eh = info.max_height - (uint32_t)(frame_number % 5);
        if (width[k] != ew || height[k] != eh || pixels[k] == NULL) {
            snprintf(r->inconsistency, sizeof r->inconsistency,
                     "frame %llu layer %u is %ux%u, the pattern says %ux%u",
                     (unsigned long long)frame_number, (unsigned)k, (unsigned)width[k],
                     (unsigned)height[k], (unsigned)ew, (unsigned)eh);
            continue;
        }
        uint32_t seed = (uint32_t)frame_number * PATTERN_FRAME + k * PATTERN_LAYER;
        const uint8_t *p = pixels[k];
        for (size_t i = 0; i < n / 4; i++, p += 4) {
            uint32_t v = (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 |
                         (uint32_t)p[3] << 24;
            if (v != seed + (uint32_t)i) {
                snprintf(r->inconsistency, sizeof r->inconsistency,
                         "frame %llu layer %u pixel %zu is 0x%08x, the pattern says 0x%08x",
                         (unsigned long long)frame_number, (unsigned)k, i, (unsigned)v,
                         (unsigned)(seed + (uint32_t)i));
                break;
            }
        }
    }
}

static void print_layers(const wxsky_segment *seg, const frame_result *r) {
    printf("\"layers\":[");
    for (uint32_t k = 0; k < r->layer_count; k++) {
        wxsky_layer_info info;
        wxsky_segment_layer(seg, k, &info);
        printf(k > 0 ? ",{" : "{");
        js_key("name");
        js_str(info.name);
        printf(",\"width\":%u,\"height\":%u,\"fnv\":\"%016llx\"}", (unsigned)r->width[k],
               (unsigned)r->height[k], (unsigned long long)r->fnv[k]);
    }
    putchar(']');
}

static void print_frame(const wxsky_segment *seg, const frame_result *r) {
    printf("{\"frame_number\":%llu,\"meta_length\":%u,", (unsigned long long)r->frame_number,
           (unsigned)r->meta_length);
    printf("\"record_status\":");
    js_str(wxsky_status_name(r->record_status));
    printf(",\"record_error\":");
    js_str(r->record_error);
    if (r->record_status == WXSKY_OK) {
        printf(",\"record\":");
        print_record(&r->record);
    }
    putchar(',');
    print_layers(seg, r);
    printf(",\"consistent\":%s,\"inconsistency\":", r->inconsistency[0] ? "false" : "true");
    js_str(r->inconsistency);
    printf("}\n");
}

/* ---- buffers and calls ------------------------------------------------------------------ */

typedef struct buffers {
    wxsky_frame_copy copy;
} buffers;

static void buffers_init(buffers *b, const wxsky_segment *seg) {
    memset(b, 0, sizeof *b);
    for (uint32_t k = 0; k < wxsky_segment_layer_count(seg); k++) {
        wxsky_layer_info info;
        wxsky_segment_layer(seg, k, &info);
        b->copy.pixels_size[k] = (size_t)info.capacity;
        b->copy.pixels[k] = malloc(info.capacity > 0 ? (size_t)info.capacity : 1);
        if (b->copy.pixels[k] == NULL) {
            die(WXSKY_ENOSPC, "out of memory for layer %u (%llu bytes)", (unsigned)k,
                (unsigned long long)info.capacity);
        }
    }
    b->copy.meta_size = wxsky_segment_meta_capacity(seg);
    b->copy.meta = malloc(b->copy.meta_size > 0 ? b->copy.meta_size : 1);
    if (b->copy.meta == NULL) {
        die(WXSKY_ENOSPC, "out of memory for the metadata");
    }
}

static void buffers_free(buffers *b) {
    for (int k = 0; k < WXSKY_MAX_LAYERS; k++) {
        free(b->copy.pixels[k]);
    }
    free(b->copy.meta);
    memset(b, 0, sizeof *b);
}

static void analyse_copy(const wxsky_segment *seg, const buffers *b, int pattern,
                         frame_result *r) {
    const uint8_t *pixels[WXSKY_MAX_LAYERS];
    for (int k = 0; k < WXSKY_MAX_LAYERS; k++) {
        pixels[k] = b->copy.pixels[k];
    }
    analyse(seg, b->copy.frame_number, b->copy.meta, b->copy.meta_length, b->copy.width,
            b->copy.height, pixels, pattern, r);
}

static void analyse_view(const wxsky_segment *seg, const wxsky_frame_view *v, int pattern,
                         frame_result *r) {
    const uint8_t *pixels[WXSKY_MAX_LAYERS];
    uint32_t width[WXSKY_MAX_LAYERS];
    uint32_t height[WXSKY_MAX_LAYERS];
    for (int k = 0; k < WXSKY_MAX_LAYERS; k++) {
        pixels[k] = v->layers[k].pixels;
        width[k] = v->layers[k].width;
        height[k] = v->layers[k].height;
    }
    analyse(seg, v->frame_number, v->meta, v->meta_length, width, height, pixels, pattern, r);
}

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

static void pause_us(long us) {
    struct timespec ts = {us / 1000000, (us % 1000000) * 1000};
    nanosleep(&ts, NULL);
}

static void open_or_die(wxsky_segment *seg, const char *name, int timeout_ms) {
    double deadline = now_ms() + timeout_ms;
    for (;;) {
        int rc = wxsky_segment_open(seg, name);
        if (rc == WXSKY_OK) {
            return;
        }
        if (rc != WXSKY_STARTING || now_ms() >= deadline) {
            die(rc, "%s", wxsky_segment_error(seg));
        }
        pause_us(1000);
    }
}

static long parse_long(const char *s, const char *what) {
    char *end = NULL;
    errno = 0;
    long v = strtol(s, &end, 10);
    if (errno != 0 || end == s || *end != '\0' || v < 0) {
        fprintf(stderr, "%s: bad %s '%s'\n", prog, what, s);
        usage();
    }
    return v;
}

/* ---- commands --------------------------------------------------------------------------- */

static int cmd_open(const char *name) {
    wxsky_segment *seg = wxsky_segment_new();
    if (seg == NULL) {
        die(WXSKY_ENOSPC, "out of memory");
    }
    open_or_die(seg, name, 0);
    print_header(seg);
    putchar('\n');
    wxsky_segment_free(seg);
    return 0;
}

static int cmd_frames(const char *name, int view, long frames, int timeout_ms, int pattern) {
    wxsky_segment *seg = wxsky_segment_new();
    if (seg == NULL) {
        die(WXSKY_ENOSPC, "out of memory");
    }
    open_or_die(seg, name, timeout_ms);
    buffers b;
    buffers_init(&b, seg);
    frame_result *r = malloc(sizeof *r);
    if (r == NULL) {
        die(WXSKY_ENOSPC, "out of memory");
    }
    uint64_t last = 0;
    long torn = 0, again = 0, bad = 0;
    for (long i = 0; i < frames; i++) {
        double deadline = now_ms() + timeout_ms;
        if (i > 0) {
            while (wxsky_segment_latest_frame(seg) <= last) {
                if (now_ms() >= deadline) {
                    die(WXSKY_ETIMEDOUT, "segment '%s': no frame newer than %llu within %d ms",
                        name, (unsigned long long)last, timeout_ms);
                }
                pause_us(100);
            }
        }
        if (!view) {
            int rc = wxsky_frame_read(seg, &b.copy, timeout_ms);
            if (rc != WXSKY_OK) {
                die(rc, "%s", wxsky_segment_error(seg));
            }
            analyse_copy(seg, &b, pattern, r);
        } else {
            for (;;) {
                wxsky_frame_view v;
                int rc = wxsky_frame_begin(seg, &v);
                if (rc == WXSKY_AGAIN) {
                    again++;
                    if (now_ms() >= deadline) {
                        die(WXSKY_ETIMEDOUT, "segment '%s': no view within %d ms: %s", name,
                            timeout_ms, wxsky_segment_error(seg));
                    }
                    pause_us(50);
                    continue;
                }
                if (rc != WXSKY_OK) {
                    die(rc, "%s", wxsky_segment_error(seg));
                }
                analyse_view(seg, &v, pattern, r);
                rc = wxsky_frame_end(seg, &v);
                if (rc == WXSKY_OK) {
                    break;
                }
                if (rc != WXSKY_ETORN) {
                    die(rc, "%s", wxsky_segment_error(seg));
                }
                torn++;
                if (now_ms() >= deadline) {
                    die(WXSKY_ETIMEDOUT,
                        "segment '%s': every view was torn for %d ms (%ld so far): this check "
                        "takes longer than two publishes",
                        name, timeout_ms, torn);
                }
            }
        }
        if (i > 0 && r->frame_number <= last && r->inconsistency[0] == '\0') {
            snprintf(r->inconsistency, sizeof r->inconsistency,
                     "frame %llu after frame %llu: not increasing",
                     (unsigned long long)r->frame_number, (unsigned long long)last);
        }
        bad += r->inconsistency[0] != '\0';
        print_frame(seg, r);
        if (r->record_status != WXSKY_OK) {
            die(r->record_status, "%s", r->record_error);
        }
        last = r->frame_number;
    }
    printf("{\"summary\":{\"frames\":%ld,\"torn\":%ld,\"again\":%ld,\"inconsistent\":%ld}}\n",
           frames, torn, again, bad);
    free(r);
    buffers_free(&b);
    wxsky_segment_free(seg);
    return bad > 0 ? 1 : 0;
}

/* Every call on one segment, each status and message reported: never dies on a bad segment. */
static void probe_one(wxsky_segment *seg, const char *name, int with_header) {
    printf("{");
    js_key("name");
    js_str(name);
    putchar(',');
    int rc = wxsky_segment_open(seg, name);
    js_status("open", rc, wxsky_segment_error(seg));
    if (rc == WXSKY_OK) {
        if (with_header) {
            printf(",\"header\":");
            print_header(seg);
        }
        putchar(',');
        js_status("check", wxsky_segment_check(seg), wxsky_segment_error(seg));
        printf(",\"latest_frame\":%llu,",
               (unsigned long long)wxsky_segment_latest_frame(seg));
        buffers b;
        buffers_init(&b, seg);
        rc = wxsky_frame_read(seg, &b.copy, 0);
        js_status("read", rc, wxsky_segment_error(seg));
        if (rc == WXSKY_OK) {
            char err[WXSKY_ERROR_MAX];
            wxsky_record rec;
            printf(",\"frame_number\":%llu,", (unsigned long long)b.copy.frame_number);
            js_status("record", wxsky_record_decode(b.copy.meta, b.copy.meta_length, &rec, err,
                                                    sizeof err),
                      err);
        }
        buffers_free(&b);
        wxsky_frame_view v;
        putchar(',');
        rc = wxsky_frame_begin(seg, &v);
        js_status("view", rc, wxsky_segment_error(seg));
        if (rc == WXSKY_OK) {
            char err[WXSKY_ERROR_MAX];
            wxsky_record rec;
            int rec_rc = wxsky_record_decode(v.meta, v.meta_length, &rec, err, sizeof err);
            uint64_t sum = 0;
            for (uint32_t k = 0; k < v.layer_count; k++) {
                sum += fnv1a64(v.layers[k].pixels, v.layers[k].pixels == NULL
                                                        ? 0
                                                        : (size_t)v.layers[k].width *
                                                              v.layers[k].height * 4);
            }
            putchar(',');
            js_status("view_record", rec_rc, err);
            printf(",\"view_sum\":\"%016llx\",", (unsigned long long)sum);
            rc = wxsky_frame_end(seg, &v);
            js_status("end", rc, wxsky_segment_error(seg));
        }
    }
    printf("}\n");
    fflush(stdout);
    wxsky_segment_close(seg);
}

static int cmd_probe(int argc, char **argv) {
    wxsky_segment *seg = wxsky_segment_new();
    if (seg == NULL) {
        die(WXSKY_ENOSPC, "out of memory");
    }
    for (int i = 0; i < argc; i++) {
        probe_one(seg, argv[i], 0);
    }
    wxsky_segment_free(seg);
    return 0;
}

static void repl_reply(const char *cmd, int rc, const wxsky_segment *seg) {
    printf("{\"cmd\":");
    js_str(cmd);
    putchar(',');
    js_status("status", rc, wxsky_segment_error(seg));
}

static int cmd_repl(const char *name) {
    wxsky_segment *seg = wxsky_segment_new();
    frame_result *r = malloc(sizeof *r);
    if (seg == NULL || r == NULL) {
        die(WXSKY_ENOSPC, "out of memory");
    }
    buffers b;
    memset(&b, 0, sizeof b);
    wxsky_frame_view v;
    memset(&v, 0, sizeof v);
    char line[256];
    while (fgets(line, sizeof line, stdin) != NULL) {
        line[strcspn(line, "\r\n")] = '\0';
        char *arg = strchr(line, ' ');
        if (arg != NULL) {
            *arg++ = '\0';
        }
        const char *cmd = line;
        if (strcmp(cmd, "quit") == 0) {
            break;
        } else if (strcmp(cmd, "open") == 0) {
            buffers_free(&b);
            int rc = wxsky_segment_open(seg, name);
            repl_reply(cmd, rc, seg);
            if (rc == WXSKY_OK) {
                buffers_init(&b, seg);
                printf(",\"header\":");
                print_header(seg);
            }
        } else if (strcmp(cmd, "close") == 0) {
            buffers_free(&b);
            wxsky_segment_close(seg);
            repl_reply(cmd, WXSKY_OK, seg);
        } else if (strcmp(cmd, "check") == 0) {
            repl_reply(cmd, wxsky_segment_check(seg), seg);
        } else if (strcmp(cmd, "header") == 0) {
            wxsky_segment_header h;
            int rc = wxsky_segment_get_header(seg, &h);
            repl_reply(cmd, rc, seg);
            if (rc == WXSKY_OK) {
                printf(",\"header\":");
                print_header(seg);
            }
        } else if (strcmp(cmd, "latest") == 0) {
            repl_reply(cmd, WXSKY_OK, seg);
            printf(",\"latest_frame\":%llu", (unsigned long long)wxsky_segment_latest_frame(seg));
        } else if (strcmp(cmd, "read") == 0 || strcmp(cmd, "read_small") == 0 ||
                   strcmp(cmd, "read_nobuf") == 0) {
            buffers c = b; /* the same buffers; the variants change only this copy */
            int timeout = 0;
            int nobuf = strcmp(cmd, "read_nobuf") == 0;
            if (strcmp(cmd, "read") == 0 && arg != NULL) {
                timeout = (int)parse_long(arg, "timeout");
            }
            if (strcmp(cmd, "read_small") == 0) {
                long k = arg != NULL ? parse_long(arg, "layer") : 0;
                if (k < WXSKY_MAX_LAYERS && c.copy.pixels_size[k] > 0) {
                    c.copy.pixels_size[k]--;
                }
            } else if (nobuf) {
                memset(c.copy.pixels, 0, sizeof c.copy.pixels);
                c.copy.meta = NULL;
            }
            double t0 = now_ms();
            int rc = wxsky_frame_read(seg, &c.copy, timeout);
            double elapsed = now_ms() - t0;
            repl_reply(cmd, rc, seg);
            printf(",\"elapsed_ms\":%.3f", elapsed);
            if (rc == WXSKY_OK && nobuf) {
                printf(",\"frame_number\":%llu,\"meta_length\":%u,\"sizes\":[",
                       (unsigned long long)c.copy.frame_number, (unsigned)c.copy.meta_length);
                for (uint32_t k = 0; k < wxsky_segment_layer_count(seg); k++) {
                    printf(k > 0 ? ",[%u,%u]" : "[%u,%u]", (unsigned)c.copy.width[k],
                           (unsigned)c.copy.height[k]);
                }
                putchar(']');
            } else if (rc == WXSKY_OK) {
                analyse_copy(seg, &c, 0, r);
                printf(",\"frame_number\":%llu,", (unsigned long long)r->frame_number);
                printf("\"record_status\":");
                js_str(wxsky_status_name(r->record_status));
                putchar(',');
                print_layers(seg, r);
            }
        } else if (strcmp(cmd, "begin") == 0) {
            int rc = wxsky_frame_begin(seg, &v);
            repl_reply(cmd, rc, seg);
            if (rc == WXSKY_OK) {
                analyse_view(seg, &v, 0, r);
                printf(",\"slot\":%u,\"frame_number\":%llu,", (unsigned)v.slot_,
                       (unsigned long long)v.frame_number);
                print_layers(seg, r);
            }
        } else if (strcmp(cmd, "end") == 0) {
            int rc = wxsky_frame_end(seg, &v);
            repl_reply(cmd, rc, seg);
            if (rc == WXSKY_OK || rc == WXSKY_ETORN) {
                /* what the view's pixels hold now, to show a torn view really changed */
                analyse_view(seg, &v, 0, r);
                putchar(',');
                print_layers(seg, r);
            }
        } else {
            repl_reply(cmd, WXSKY_EINVAL, seg);
            printf(",\"unknown\":true");
        }
        printf("}\n");
        fflush(stdout);
    }
    buffers_free(&b);
    free(r);
    wxsky_segment_free(seg);
    return 0;
}

/* ---- fuzz ------------------------------------------------------------------------------- */

static uint64_t rng_state;

static uint64_t rng(void) { /* splitmix64 */
    uint64_t z = (rng_state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static uint64_t rng_below(uint64_t n) {
    return n == 0 ? 0 : rng() % n;
}

static void put32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; i++) {
        p[i] = (uint8_t)(v >> (8 * i));
    }
}

static void put64(uint8_t *p, uint64_t v) {
    for (int i = 0; i < 8; i++) {
        p[i] = (uint8_t)(v >> (8 * i));
    }
}

static uint32_t get32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint64_t get64(const uint8_t *p) {
    return (uint64_t)get32(p) | (uint64_t)get32(p + 4) << 32;
}

static uint64_t interesting(uint64_t size, uint64_t old) {
    const uint64_t values[] = {0,          1,          2,           3,          7,
                               8,          15,         16,          24,         63,
                               64,         65,         1736,        1799,       4095,
                               4096,       4097,       8192,        0x7fffffff, 0x80000000,
                               0xffffffff, 0x100000000, 1ull << 63, UINT64_MAX, UINT64_MAX - 7};
    size_t n = sizeof values / sizeof values[0];
    uint64_t pick = rng_below(n + 6);
    if (pick < n) {
        return values[pick];
    }
    switch (pick - n) {
    case 0: return size;
    case 1: return size - 1;
    case 2: return size + 1;
    case 3: return old + 1;
    case 4: return old - 1;
    default: return rng_below(size * 2 + 1);
    }
}

typedef struct tally {
    const char *what;
    int counts[32]; /* status + 16 */
} tally;

static void count(tally *t, int status) {
    int i = status + 16;
    if (i >= 0 && i < 32) {
        t->counts[i]++;
    }
}

static void print_tally(const tally *t) {
    js_key(t->what);
    putchar('{');
    int first = 1;
    for (int i = 0; i < 32; i++) {
        if (t->counts[i] > 0) {
            printf(first ? "" : ",");
            js_key(wxsky_status_name(i - 16));
            printf("%d", t->counts[i]);
            first = 0;
        }
    }
    putchar('}');
}

static void write_segment(const char *name, const uint8_t *data, size_t size) {
    char path[256];
    snprintf(path, sizeof path, "/%s", name);
    shm_unlink(path);
    int fd = shm_open(path, O_CREAT | O_EXCL | O_RDWR, 0600);
    if (fd < 0) {
        die(WXSKY_ESYS, "shm_open('%s'): %s", path, strerror(errno));
    }
    if (ftruncate(fd, (off_t)size) != 0) {
        die(WXSKY_ESYS, "ftruncate('%s', %zu): %s", path, size, strerror(errno));
    }
    size_t done = 0;
    while (done < size) {
        ssize_t n = write(fd, data + done, size - done);
        if (n <= 0) {
            die(WXSKY_ESYS, "write('%s'): %s", path, strerror(errno));
        }
        done += (size_t)n;
    }
    close(fd);
}

static int cmd_fuzz(const char *src, const char *dst, uint64_t seed, long iterations) {
    char path[256];
    snprintf(path, sizeof path, "/%s", src);
    int fd = shm_open(path, O_RDONLY, 0);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0) {
        die(WXSKY_ENOENT, "segment '%s': %s", src, strerror(errno));
    }
    size_t size = (size_t)st.st_size;
    uint8_t *orig = malloc(size);
    uint8_t *data = malloc(size);
    if (orig == NULL || data == NULL) {
        die(WXSKY_ENOSPC, "out of memory for %zu bytes", size);
    }
    size_t done = 0;
    while (done < size) {
        ssize_t n = pread(fd, orig + done, size - done, (off_t)done);
        if (n <= 0) {
            die(WXSKY_ESYS, "read('%s'): %s", path, strerror(errno));
        }
        done += (size_t)n;
    }
    close(fd);
    /* the original's layout, to aim mutations at the header, slot headers and records */
    uint32_t header_size = get32(orig + 12);
    uint32_t layer_count = get32(orig + 20);
    uint64_t slot_size = get64(orig + 24);
    uint32_t active = get32(orig + 40);
    if (size < 64 || layer_count < 1 || layer_count > 64 || header_size + 2 * slot_size > size ||
        active > 1) {
        die(WXSKY_EFORMAT, "fuzz: '%s' is not a valid segment to start from", src);
    }
    uint64_t slot_header = 24 + 16 * (uint64_t)layer_count;
    tally t_open = {"open", {0}}, t_read = {"read", {0}}, t_view = {"view", {0}},
          t_record = {"record", {0}}, t_check = {"check", {0}};
    rng_state = seed;
    wxsky_segment *seg = wxsky_segment_new();
    if (seg == NULL) {
        die(WXSKY_ENOSPC, "out of memory");
    }
    for (long it = 0; it < iterations; it++) {
        memcpy(data, orig, size);
        size_t out_size = size;
        int mutations = 1 + (int)rng_below(4);
        for (int m = 0; m < mutations; m++) {
            uint64_t region = rng_below(100);
            uint64_t start, length;
            if (region < 45) {
                start = 0;
                length = 64 + 32 * (uint64_t)layer_count;
            } else if (region < 80) {
                start = header_size + rng_below(2) * slot_size;
                length = slot_header;
            } else if (region < 95) {
                uint64_t base = header_size + (uint64_t)active * slot_size;
                start = base + get32(orig + base + 20);
                length = WXSKY_RECORD_SIZE;
            } else {
                out_size = (size_t)rng_below(size);
                continue;
            }
            if (start + length > size) {
                continue;
            }
            uint64_t kind = rng_below(4);
            if (kind == 0) {
                data[start + rng_below(length)] = (uint8_t)rng();
            } else if (kind == 1) {
                data[start + rng_below(length)] ^= (uint8_t)(1u << rng_below(8));
            } else if (kind == 2) {
                uint64_t at = start + rng_below(length / 4) * 4;
                put32(data + at, (uint32_t)interesting(size, get32(data + at)));
            } else {
                uint64_t at = start + rng_below(length / 8) * 8;
                put64(data + at, interesting(size, get64(data + at)));
            }
        }
        write_segment(dst, data, out_size);
        int rc = wxsky_segment_open(seg, dst);
        count(&t_open, rc);
        if (rc == WXSKY_OK) {
            count(&t_check, wxsky_segment_check(seg));
            (void)wxsky_segment_latest_frame(seg);
            for (uint32_t k = 0; k < wxsky_segment_layer_count(seg); k++) {
                wxsky_layer_info info;
                wxsky_segment_layer(seg, k, &info);
                if (wxsky_segment_find_layer(seg, info.name) != (int)k) {
                    die(WXSKY_EFORMAT, "fuzz: find_layer('%s') is not %u", info.name,
                        (unsigned)k);
                }
            }
            buffers b;
            buffers_init(&b, seg);
            rc = wxsky_frame_read(seg, &b.copy, 0);
            count(&t_read, rc);
            if (rc == WXSKY_OK) {
                wxsky_record rec;
                char err[WXSKY_ERROR_MAX];
                count(&t_record, wxsky_record_decode(b.copy.meta, b.copy.meta_length, &rec, err,
                                                     sizeof err));
                for (uint32_t k = 0; k < wxsky_segment_layer_count(seg); k++) {
                    (void)fnv1a64(b.copy.pixels[k], (size_t)b.copy.width[k] * b.copy.height[k] * 4);
                }
            }
            buffers_free(&b);
            wxsky_frame_view v;
            rc = wxsky_frame_begin(seg, &v);
            count(&t_view, rc);
            if (rc == WXSKY_OK) {
                wxsky_record rec;
                (void)wxsky_record_decode(v.meta, v.meta_length, &rec, NULL, 0);
                for (uint32_t k = 0; k < v.layer_count; k++) {
                    if (v.layers[k].pixels != NULL) {
                        (void)fnv1a64(v.layers[k].pixels,
                                      (size_t)v.layers[k].width * v.layers[k].height * 4);
                    }
                }
                if (wxsky_frame_end(seg, &v) != WXSKY_OK) {
                    die(WXSKY_ETORN, "fuzz: a view of a segment nobody writes was torn");
                }
            }
            wxsky_segment_close(seg);
        }
        const char *msg = wxsky_segment_error(seg);
        if (strchr(msg, '\n') != NULL) {
            die(WXSKY_EFORMAT, "fuzz: a message has a newline: %s", msg);
        }
    }
    snprintf(path, sizeof path, "/%s", dst);
    shm_unlink(path);
    printf("{\"iterations\":%ld,", iterations);
    print_tally(&t_open);
    putchar(',');
    print_tally(&t_check);
    putchar(',');
    print_tally(&t_read);
    putchar(',');
    print_tally(&t_view);
    putchar(',');
    print_tally(&t_record);
    printf("}\n");
    wxsky_segment_free(seg);
    free(orig);
    free(data);
    return 0;
}

/* ---- HDR helpers ---------------------------------------------------------------------- */

static int cmd_display(const char *exposure_text) {
    char *end = NULL;
    float exposure = strtof(exposure_text, &end);
    if (end == exposure_text || *end != '\0') {
        usage();
    }
    float in[3], out[3];
    while (scanf("%f %f %f", &in[0], &in[1], &in[2]) == 3) {
        wxsky_display(in, exposure, out);
        printf("%.9g %.9g %.9g\n", (double)out[0], (double)out[1], (double)out[2]);
    }
    return 0;
}

static int cmd_half(void) {
    unsigned value;
    while (scanf("%x", &value) == 1) {
        if (value > 0xffffu) {
            die(WXSKY_EINVAL, "half: 0x%x is not a 16-bit value", value);
        }
        printf("%.17g\n", (double)wxsky_half_to_float((uint16_t)value));
    }
    return 0;
}

int main(int argc, char **argv) {
    if (argc == 2 && strcmp(argv[1], "half") == 0) {
        return cmd_half();
    }
    if (argc < 3) {
        usage();
    }
    const char *cmd = argv[1];
    if (strcmp(cmd, "display") == 0 && argc == 3) {
        return cmd_display(argv[2]);
    }
    if (strcmp(cmd, "open") == 0 && argc == 3) {
        return cmd_open(argv[2]);
    }
    if (strcmp(cmd, "probe") == 0) {
        return cmd_probe(argc - 2, argv + 2);
    }
    if (strcmp(cmd, "repl") == 0 && argc == 3) {
        return cmd_repl(argv[2]);
    }
    if (strcmp(cmd, "read") == 0 || strcmp(cmd, "view") == 0) {
        long frames = 1, timeout_ms = 2000;
        int pattern = 0;
        for (int i = 3; i < argc; i++) {
            if (strcmp(argv[i], "--frames") == 0 && i + 1 < argc) {
                frames = parse_long(argv[++i], "--frames");
            } else if (strcmp(argv[i], "--timeout-ms") == 0 && i + 1 < argc) {
                timeout_ms = parse_long(argv[++i], "--timeout-ms");
            } else if (strcmp(argv[i], "--pattern") == 0) {
                pattern = 1;
            } else {
                usage();
            }
        }
        if (timeout_ms > 3600000) {
            usage();
        }
        return cmd_frames(argv[2], cmd[0] == 'v', frames, (int)timeout_ms, pattern);
    }
    if (strcmp(cmd, "fuzz") == 0 && argc >= 4) {
        uint64_t seed = 1;
        long iterations = 300;
        for (int i = 4; i < argc; i++) {
            if (strcmp(argv[i], "--seed") == 0 && i + 1 < argc) {
                seed = (uint64_t)parse_long(argv[++i], "--seed");
            } else if (strcmp(argv[i], "--iterations") == 0 && i + 1 < argc) {
                iterations = parse_long(argv[++i], "--iterations");
            } else {
                usage();
            }
        }
        return cmd_fuzz(argv[2], argv[3], seed, iterations);
    }
    usage();
}
