/* wxsky-host-snapshot: a picture of a running daemon's sky, composited by the C host kit.
 *
 *   wxsky-host-snapshot [--control ADDR] [--shm NAME] [--time ISO8601] [--lat DEG --lon DEG]
 *       [--alt-m M] [--heading-deg D] [--pitch-deg D] [--fov-deg D] [--size WxH]
 *       --out FILE.png [--timeout-s S] [--exposure EV] [--linear-out FILE.pfm]
 *
 * Connects to the daemon at ADDR (protocol §2.1; default: the default address there), sets its clock (set_time) and camera
 * (set_camera) to what is given (anything not given stays as the daemon has it), waits for a
 * frame drawn for that camera once the ring has settled (§3.1), composites it on a headless
 * EGL context with the GL compositor and writes the PNG. --shm defaults to the segment the
 * daemon names in `scene`. For the same preset, time and camera the picture is the one
 * `wxsky snapshot` makes (tests/test_host_c_snapshot.py holds them together).
 *
 * A daemon with [output] layer_format = "rgba16f" publishes scene-linear RGBA16F layers: they
 * are composited in linear into a float framebuffer, which --linear-out writes as a PFM (the
 * scene-linear picture, as `wxsky snapshot --linear-out` does), and shown once through the
 * daemon's exposure and tone map at --exposure EV (-20..20, default 0: the daemon's EV 0) for
 * the PNG (wxsky_gl_tone_map). With RGBA8 layers --exposure does not apply and --linear-out
 * is an error (the layers are display values already).
 *
 * Prints "wrote FILE (WxH), frame N" on success; otherwise one line "wxsky-host-snapshot:
 * error: ..." and exits 1 (2: no headless GL context could be made; 64: bad arguments). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "png_write.h"

#define PROG "wxsky-host-snapshot"

typedef struct args {
    const char *control, *shm, *time_utc, *out, *linear_out;
    double lat, lon, alt_m, heading_deg, pitch_deg, fov_deg, timeout_s, exposure_ev;
    int has_lat, has_lon, has_alt, has_heading, has_pitch, has_fov;
    uint32_t width, height;
} args;

#define USAGE                                                                              \
    "usage: " PROG " [--control ADDR] [--shm NAME] [--time ISO8601] [--lat DEG --lon DEG] "  \
    "[--alt-m M] [--heading-deg D] [--pitch-deg D] [--fov-deg D] [--size WxH] "           \
    "--out FILE.png [--timeout-s S] [--exposure EV] [--linear-out FILE.pfm]"

static int usage(const char *why) {
    fprintf(stderr, "%s: error: %s\n%s\n", PROG, why, USAGE);
    return 64;
}

static int parse(int argc, char **argv, args *a) {
    memset(a, 0, sizeof *a);
    a->timeout_s = 60.0;
    for (int i = 1; i < argc; ++i) {
        const char *f = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!v)
            return usage(f), 0;
        ++i;
        if (!strcmp(f, "--control"))
            a->control = v;
        else if (!strcmp(f, "--shm"))
            a->shm = v;
        else if (!strcmp(f, "--time"))
            a->time_utc = v;
        else if (!strcmp(f, "--out"))
            a->out = v;
        else if (!strcmp(f, "--linear-out"))
            a->linear_out = v;
        else if (!strcmp(f, "--exposure")) {
            if (!app_parse_number(PROG, f, v, -20, 20, &a->exposure_ev))
                return 0;
        }
        else if (!strcmp(f, "--lat")) {
            if (!app_parse_number(PROG, f, v, -90, 90, &a->lat))
                return 0;
            a->has_lat = 1;
        } else if (!strcmp(f, "--lon")) {
            if (!app_parse_number(PROG, f, v, -180, 180, &a->lon))
                return 0;
            a->has_lon = 1;
        } else if (!strcmp(f, "--alt-m")) {
            if (!app_parse_number(PROG, f, v, -500, 100000, &a->alt_m))
                return 0;
            a->has_alt = 1;
        } else if (!strcmp(f, "--heading-deg")) {
            if (!app_parse_number(PROG, f, v, -360, 360, &a->heading_deg))
                return 0;
            a->has_heading = 1;
        } else if (!strcmp(f, "--pitch-deg")) {
            if (!app_parse_number(PROG, f, v, -90, 90, &a->pitch_deg))
                return 0;
            a->has_pitch = 1;
        } else if (!strcmp(f, "--fov-deg")) {
            if (!app_parse_number(PROG, f, v, 1, 170, &a->fov_deg))
                return 0;
            a->has_fov = 1;
        } else if (!strcmp(f, "--timeout-s")) {
            if (!app_parse_number(PROG, f, v, 0.1, 3600, &a->timeout_s))
                return 0;
        } else if (!strcmp(f, "--size")) {
            if (!app_parse_size(PROG, f, v, 8192, &a->width, &a->height))
                return 0;
        } else {
            return usage(f), 0;
        }
    }
    if (!a->out)
        return usage("--out FILE.png is required"), 0;
    if (a->has_lat != a->has_lon)
        return usage("--lat and --lon go together"), 0;
    return 1;
}

/* The set_camera params: only what was given. */
static void camera_params(const args *a, wxsky_mp_writer *w) {
    uint32_t n = (uint32_t)(2 * a->has_lat + a->has_alt + a->has_heading + a->has_pitch +
                            a->has_fov + 2 * (a->width != 0));
    wxsky_mp_write_map(w, n);
    if (a->has_lat) {
        wxsky_mp_write_cstr(w, "lat_deg");
        wxsky_mp_write_double(w, a->lat);
        wxsky_mp_write_cstr(w, "lon_deg");
        wxsky_mp_write_double(w, a->lon);
    }
    if (a->has_alt) {
        wxsky_mp_write_cstr(w, "alt_m");
        wxsky_mp_write_double(w, a->alt_m);
    }
    if (a->has_heading) {
        wxsky_mp_write_cstr(w, "heading_deg");
        wxsky_mp_write_double(w, a->heading_deg);
    }
    if (a->has_pitch) {
        wxsky_mp_write_cstr(w, "pitch_deg");
        wxsky_mp_write_double(w, a->pitch_deg);
    }
    if (a->has_fov) {
        wxsky_mp_write_cstr(w, "fov_deg");
        wxsky_mp_write_double(w, a->fov_deg);
    }
    if (a->width) {
        wxsky_mp_write_cstr(w, "width");
        wxsky_mp_write_uint(w, a->width);
        wxsky_mp_write_cstr(w, "height");
        wxsky_mp_write_uint(w, a->height);
    }
}

/* The daemon's clock rate, from `status`. */
static int clock_rate(wxsky_client *c, int timeout_ms, double *rate, char *err) {
    wxsky_message res;
    wxsky_mp_reader r;
    uint32_t n;
    if (app_call(c, "status", NULL, timeout_ms, &res, err) != WXSKY_OK)
        return -1;
    wxsky_mp_reader_init(&r, res.body, res.body_len);
    if (wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "clock_rate") != WXSKY_OK ||
        wxsky_mp_read_double(&r, rate) != WXSKY_OK) {
        snprintf(err, APP_ERR, "status: no clock_rate in the result");
        return -1;
    }
    return 0;
}

static int restart_clock(wxsky_client *c, double rate, int timeout_ms, char *err) {
    uint8_t buf[64];
    wxsky_mp_writer w;
    wxsky_message res;
    wxsky_mp_writer_init(&w, buf, sizeof buf);
    wxsky_mp_write_map(&w, 1);
    wxsky_mp_write_cstr(&w, "rate");
    wxsky_mp_write_double(&w, rate);
    return app_call(c, "set_time", &w, timeout_ms, &res, err) == WXSKY_OK ? 0 : -1;
}

int main(int argc, char **argv) {
    args a;
    char err[APP_ERR] = "";
    uint8_t params[512], *pixels = NULL;
    float *linear = NULL;
    int hdr;
    wxsky_mp_writer w;
    wxsky_message res;
    wxsky_client *client = NULL;
    wxsky_segment *seg = NULL;
    wxsky_gl_compositor *gl = NULL;
    wxsky_frame_copy copy;
    wxsky_record rec;
    wxsky_camera cam;
    app_gl g;
    int code = 1, st, timeout_ms, frozen = 0;
    double rate = 1.0;
    uint64_t after;
    double deadline;

    memset(&copy, 0, sizeof copy);
    memset(&g, 0, sizeof g);
    if (argc == 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        printf("%s\n", USAGE);
        return 0;
    }
    if (!parse(argc, argv, &a))
        return 64;
    timeout_ms = (int)(a.timeout_s * 1000.0);
    deadline = app_now_ms() + timeout_ms;

    client = wxsky_client_new(0, 0);
    seg = wxsky_segment_new();
    gl = wxsky_gl_new();
    if (!client || !seg || !gl) {
        snprintf(err, sizeof err, "out of memory");
        goto done;
    }
    if (app_attach(client, seg, &copy, a.control, a.shm, timeout_ms, err) != 0)
        goto done;

    if (a.time_utc) {
        /* The picture is of that very moment: the clock stands still there while the frame is
         * drawn (else the clouds move on and the sun too while the ring is rebuilt), then runs
         * on from it at the rate it had. */
        if (clock_rate(client, timeout_ms, &rate, err) != 0)
            goto done;
        wxsky_mp_writer_init(&w, params, sizeof params);
        wxsky_mp_write_map(&w, 2);
        wxsky_mp_write_cstr(&w, "time_utc");
        wxsky_mp_write_cstr(&w, a.time_utc);
        wxsky_mp_write_cstr(&w, "rate");
        wxsky_mp_write_double(&w, 0.0);
        if (app_call(client, "set_time", &w, timeout_ms, &res, err) != WXSKY_OK)
            goto done;
        frozen = 1;
    }
    wxsky_mp_writer_init(&w, params, sizeof params);
    camera_params(&a, &w);
    if (app_call(client, "set_camera", &w, timeout_ms, &res, err) != WXSKY_OK)
        goto done;
    if (app_camera_from_result(&res, &cam) != WXSKY_OK) {
        snprintf(err, sizeof err, "set_camera: the result is not a camera");
        goto done;
    }
    /* A frame whose drawing began after both requests were answered: the one published now
     * may have been started before them. */
    after = wxsky_segment_latest_frame(seg) + 1;
    if (app_wait_frame(seg, &copy, &rec, after, &cam, (int)(deadline - app_now_ms()), err) !=
            WXSKY_OK ||
        app_wait_settled_frame(client, seg, &copy, &rec, &cam,
                               (int)fmax(1000.0, deadline - app_now_ms()), err) != WXSKY_OK)
        goto done;

    if (frozen) {
        if (restart_clock(client, rate, timeout_ms, err) != 0)
            goto done;
        frozen = 0;
    }
    if (app_gl_open(&g, rec.width_px, rec.height_px, err) != 0) {
        code = 2;
        goto done;
    }
    if ((st = wxsky_gl_init(gl, seg)) != WXSKY_OK) {
        snprintf(err, sizeof err, "GL compositor: %s: %s", wxsky_status_name(st),
                 wxsky_gl_error(gl));
        goto done;
    }
    /* RGBA16F layers: composite in linear into a float framebuffer, tone-map once below */
    hdr = wxsky_gl_layer_format(gl) == WXSKY_FORMAT_RGBA16F;
    if (a.linear_out && !hdr) {
        snprintf(err, sizeof err,
                 "--linear-out: the daemon publishes rgba8 layers (display values); start it "
                 "with [output] layer_format = \"rgba16f\" for scene-linear ones");
        goto done;
    }
    if (hdr && app_gl_open_linear(&g, err) != 0)
        goto done;
    if (app_composite(gl, &copy, &rec, err) != WXSKY_OK)
        goto done;
    if (hdr && a.linear_out) {
        linear = malloc((size_t)rec.width_px * rec.height_px * 4 * sizeof *linear);
        if (!linear) {
            snprintf(err, sizeof err, "out of memory for the linear picture");
            goto done;
        }
        if (app_gl_read_linear(&g, linear, err) != 0 ||
            pfm_write_rgb(a.linear_out, linear, rec.width_px, rec.height_px, err, sizeof err) != 0)
            goto done;
    }
    if (hdr && app_gl_tone_map(&g, gl, (float)pow(2.0, a.exposure_ev), err) != 0)
        goto done;
    pixels = malloc((size_t)rec.width_px * rec.height_px * 4);
    if (!pixels) {
        snprintf(err, sizeof err, "out of memory for the picture");
        goto done;
    }
    if (app_gl_read(&g, pixels, err) != 0 ||
        png_write_rgba(a.out, pixels, rec.width_px, rec.height_px, err, sizeof err) != 0)
        goto done;
    printf("wrote %s (%ux%u), frame %llu\n", a.out, rec.width_px, rec.height_px,
           (unsigned long long)rec.frame_number);
    if (linear)
        printf("wrote %s (scene-linear)\n", a.linear_out);
    code = 0;
done:
    if (code != 0)
        fprintf(stderr, "%s: error: %s\n", PROG, err[0] ? err : "failed");
    if (frozen && restart_clock(client, rate, 2000, err) != 0)
        fprintf(stderr, "%s: error: %s\n", PROG, err);
    if (g.egl_) {
        wxsky_gl_free(gl); /* its GL objects need the context */
        gl = NULL;
        app_gl_close(&g);
    }
    wxsky_gl_free(gl);
    free(pixels);
    free(linear);
    app_copy_free(&copy);
    wxsky_segment_free(seg);
    wxsky_client_free(client);
    return code;
}
