/* wxsky-host-demo: a small host simulator: terrain with a runway, flown along a camera path,
 * sending its camera to the daemon every frame and compositing wxsky's clouds in front of and
 * behind its terrain with the GL compositor; writes the frames as a PNG strip.
 *
 *   wxsky-host-demo [--control ADDR] [--shm NAME] --out STRIP.png [--frames N] [--size WxH]
 *       [--time ISO8601] [--fov-deg D] [--debug-out DIR --debug-frame K] [--timeout-s S]
 *
 * The path takes off from the runway (3 km long, north-south through the observer) and climbs
 * north towards a ridge 7 km away that stands between the camera and the far clouds. For each
 * frame the camera goes to the daemon (set_camera), the demo waits for the frame drawn for it
 * once the ring has settled (a strip of stills; a live host would composite whatever frame is
 * newest), then draws, into one framebuffer: its terrain (writing depth), the sky and ring
 * (depth-tested: the ridge hides the clouds behind it, clouds in front of it stay), the near
 * layer, and the near_front layer. --time sets the daemon's clock first (it keeps running).
 *
 * --debug-out DIR --debug-frame K: also writes, for frame K, terrain.png (the terrain alone,
 * alpha 0 where there is none), distance.png (the terrain's distance from the camera: red in
 * 100 m steps, green the fraction; alpha 0 where there is none), clouds.png (the frame
 * composited without terrain), near.png and sky.png (those layers as the daemon sent them,
 * premultiplied) and final.png, for tests/test_host_c_demo.py.
 *
 * --window (built where pkg-config finds glfw3; Debian: libglfw3-dev): instead of the strip,
 * a window where the path is flown live, over and over, `--path-s` seconds a lap (default 40):
 * every frame sends the camera without waiting and composites the newest frame the daemon has
 * published, as a simulator would; Esc or closing the window ends it, or --duration-s.
 *
 * Prints one line per frame and "wrote STRIP (WxH, N frames)" (windowed: one summary line);
 * on failure one line "wxsky-host-demo: error: ..." and exit 1 (2: no headless GL or no
 * display; 64: bad arguments). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "app.h"
#include "demo_terrain.h"
#include "png_write.h"

#define PROG "wxsky-host-demo"
#define USAGE                                                                                  \
    "usage: " PROG " [--control ADDR] [--shm NAME] --out STRIP.png [--frames N] [--size WxH] "   \
    "[--time ISO8601] [--fov-deg D] [--debug-out DIR --debug-frame K] [--timeout-s S] "         \
    "[--window [--path-s S] [--duration-s S]]"
#define GAP_PX 4
#define MAX_FRAMES 32

typedef struct args {
    const char *control, *shm, *out, *time_utc, *debug_out;
    int frames, debug_frame, window;
    uint32_t width, height;
    double fov_deg, timeout_s, path_s, duration_s;
} args;

static int usage(const char *why) {
    fprintf(stderr, "%s: error: %s\n%s\n", PROG, why, USAGE);
    return 0;
}

static int parse(int argc, char **argv, args *a) {
    memset(a, 0, sizeof *a);
    a->frames = 6;
    a->debug_frame = -1;
    a->width = 480;
    a->height = 270;
    a->fov_deg = 70.0;
    a->timeout_s = 120.0;
    a->path_s = 40.0;
    for (int i = 1; i < argc; i += 2) {
        const char *f = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        char *end = NULL;
        if (!strcmp(f, "--window")) {
            a->window = 1;
            --i; /* a flag: no value */
            continue;
        }
        if (!v)
            return usage(f);
        errno = 0;
        if (!strcmp(f, "--control"))
            a->control = v;
        else if (!strcmp(f, "--shm"))
            a->shm = v;
        else if (!strcmp(f, "--out"))
            a->out = v;
        else if (!strcmp(f, "--time"))
            a->time_utc = v;
        else if (!strcmp(f, "--debug-out"))
            a->debug_out = v;
        else if (!strcmp(f, "--frames") || !strcmp(f, "--debug-frame")) {
            long n = strtol(v, &end, 10);
            int lo = !strcmp(f, "--frames") ? 1 : 0;
            if (errno || *end || n < lo || n > MAX_FRAMES) {
                fprintf(stderr, "%s: error: %s %s is not a whole number in %d..%d\n", PROG, f, v,
                        lo, MAX_FRAMES);
                return 0;
            }
            if (lo)
                a->frames = (int)n;
            else
                a->debug_frame = (int)n;
        } else if (!strcmp(f, "--fov-deg") || !strcmp(f, "--timeout-s") ||
                   !strcmp(f, "--path-s") || !strcmp(f, "--duration-s")) {
            double x;
            int fov = !strcmp(f, "--fov-deg");
            if (!app_parse_number(PROG, f, v, fov ? 1.0 : 0.1, fov ? 170.0 : 86400.0, &x))
                return 0;
            *(fov                          ? &a->fov_deg
              : !strcmp(f, "--timeout-s")  ? &a->timeout_s
              : !strcmp(f, "--path-s")     ? &a->path_s
                                           : &a->duration_s) = x;
        } else if (!strcmp(f, "--size")) {
            if (!app_parse_size(PROG, f, v, 4096, &a->width, &a->height))
                return 0;
        } else {
            return usage(f);
        }
    }
#ifndef WXSKY_DEMO_GLFW
    if (a->window)
        return usage("--window: this build has no GLFW (pkg-config finds no glfw3)");
#endif
    if (!a->out && !a->window)
        return usage("--out STRIP.png is required");
    if ((a->debug_out == NULL) != (a->debug_frame < 0))
        return usage("--debug-out and --debug-frame go together");
    if (a->debug_frame >= a->frames)
        return usage("--debug-frame is past the last frame");
    return 1;
}

/* The camera at u (0..1) along the path: off the runway's south end, climbing north. */
static void path_camera(double u, double ground_m, const args *a, wxsky_camera *cam) {
    double north = -1300.0 + 4300.0 * u, east = 0.0;
    double agl = 3.0 + 420.0 * pow(u, 1.5);
    memset(cam, 0, sizeof *cam);
    cam->position_m[0] = east;
    cam->position_m[1] = north;
    cam->position_m[2] = ground_m + terrain_height_m(east, north) + agl;
    cam->heading_deg = 6.0 * u;
    cam->pitch_deg = 3.0 - 1.5 * u;
    cam->fov_deg = a->fov_deg;
    cam->width = a->width;
    cam->height = a->height;
}

/* The observer's ground altitude, from `status` (weather.observer.alt_m). */
static int ground_alt(wxsky_client *c, int timeout_ms, double *alt_m, char *err) {
    wxsky_message res;
    wxsky_mp_reader r;
    uint32_t n;
    if (app_call(c, "status", NULL, timeout_ms, &res, err) != WXSKY_OK)
        return -1;
    wxsky_mp_reader_init(&r, res.body, res.body_len);
    if (wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "weather") != WXSKY_OK ||
        wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "observer") != WXSKY_OK ||
        wxsky_mp_read_map(&r, &n) != WXSKY_OK || wxsky_mp_find_key(&r, n, "alt_m") != WXSKY_OK ||
        wxsky_mp_read_double(&r, alt_m) != WXSKY_OK) {
        snprintf(err, APP_ERR, "status: no weather.observer.alt_m in the result");
        return -1;
    }
    return 0;
}

static void clear(float a) {
    glDepthMask(GL_TRUE);
    glClearColor(0.0f, 0.0f, 0.0f, a);
    clear_depth(1.0);
    glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
}

/* One picture of the frame: terrain (unless no_terrain), then the clouds (unless no_clouds).
 * distance: the terrain's distance instead of its colours. */
static int draw(demo_terrain *t, wxsky_gl_compositor *gl, const wxsky_record *rec,
                int no_terrain, int no_clouds, int distance, char *err) {
    double view[16], proj[16];
    int st;
    clear(no_clouds ? 0.0f : 1.0f);
    wxsky_gl_camera_matrices(rec, 1, view, proj);
    if (!no_terrain && demo_terrain_draw(t, gl, rec, view, proj, distance) != 0) {
        snprintf(err, APP_ERR, "%s", t->error);
        return -1;
    }
    if (no_clouds)
        return 0;
    if ((st = wxsky_gl_draw_background(gl, view, proj)) != WXSKY_OK ||
        (st = wxsky_gl_draw_near(gl)) != WXSKY_OK || (st = wxsky_gl_draw_near_front(gl)) != WXSKY_OK) {
        snprintf(err, APP_ERR, "compositing: %s: %s", wxsky_status_name(st), wxsky_gl_error(gl));
        return -1;
    }
    return 0;
}

#ifdef WXSKY_DEMO_GLFW
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

/* Flies the path live in a window until it is closed (Esc), or for --duration-s: each frame
 * sends the camera (not waiting for the answer), takes whatever newest frame the daemon has,
 * and composites it. Returns the exit code; *gl is freed here, in the window's context. */
static int fly_window(const args *a, wxsky_client *client, wxsky_segment *seg,
                      wxsky_frame_copy *copy, wxsky_gl_compositor **gl, double ground_m,
                      char *err) {
    GLFWwindow *win;
    demo_terrain terrain;
    wxsky_record rec;
    wxsky_message msg;
    uint64_t shown = 0;
    long drawn = 0, composited = 0;
    int code = 1, st, have = 0, kept = 0;
    double t0, now;
    char why[WXSKY_ERROR_MAX];
    uint8_t *shot = malloc((size_t)a->width * a->height * 4);

    memset(&terrain, 0, sizeof terrain);
    if (!shot) {
        snprintf(err, APP_ERR, "out of memory");
        return 1;
    }
    if (!glfwInit()) {
        free(shot);
        snprintf(err, APP_ERR, "no display for a window (GLFW could not start)");
        return 2;
    }
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);
    win = glfwCreateWindow((int)a->width, (int)a->height, PROG, NULL, NULL);
    if (!win) {
        snprintf(err, APP_ERR, "no OpenGL 3.3 core window on this display");
        glfwTerminate();
        free(shot);
        return 2;
    }
    glfwMakeContextCurrent(win);
    glfwSwapInterval(1);
    if ((st = wxsky_gl_init(*gl, seg)) != WXSKY_OK) {
        snprintf(err, APP_ERR, "GL compositor: %s: %s", wxsky_status_name(st),
                 wxsky_gl_error(*gl));
        goto done;
    }
    if (demo_terrain_init(&terrain, ground_m) != 0) {
        snprintf(err, APP_ERR, "%s", terrain.error);
        goto done;
    }
    t0 = app_now_ms();
    while (!glfwWindowShouldClose(win)) {
        wxsky_camera cam;
        int fb_w, fb_h;
        now = app_now_ms();
        if (a->duration_s > 0.0 && now - t0 > a->duration_s * 1000.0)
            break;
        if (glfwGetKey(win, GLFW_KEY_ESCAPE) == GLFW_PRESS)
            break;
        path_camera(fmod((now - t0) / (a->path_s * 1000.0), 1.0), ground_m, a, &cam);
        if ((st = wxsky_set_camera(client, &cam, NULL)) != WXSKY_OK && st != WXSKY_AGAIN) {
            snprintf(err, APP_ERR, "set_camera: %s: %s", wxsky_status_name(st),
                     wxsky_client_error(client));
            goto done;
        }
        while ((st = wxsky_client_poll(client, &msg)) == WXSKY_OK)
            if (msg.kind == WXSKY_RESPONSE && msg.error) {
                snprintf(err, APP_ERR, "the daemon: %.*s", (int)msg.error_len, msg.error);
                goto done;
            }
        if (st != WXSKY_AGAIN) {
            snprintf(err, APP_ERR, "control: %s: %s", wxsky_status_name(st),
                     wxsky_client_error(client));
            goto done;
        }
        if (wxsky_segment_latest_frame(seg) > shown &&
            wxsky_frame_read(seg, copy, 0) == WXSKY_OK &&
            wxsky_record_decode(copy->meta, copy->meta_length, &rec, why, sizeof why) ==
                WXSKY_OK &&
            wxsky_gl_upload_copy(*gl, copy, &rec) == WXSKY_OK) {
            shown = copy->frame_number;
            have = 1;
            ++composited;
        }
        glfwGetFramebufferSize(win, &fb_w, &fb_h);
        glBindFramebuffer(GL_FRAMEBUFFER, 0);
        glViewport(0, 0, fb_w, fb_h);
        if (have) {
            double view[16], proj[16];
            glDepthMask(GL_TRUE);
            glClearColor(0.0f, 0.0f, 0.0f, 1.0f);
            clear_depth(1.0);
            glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
            /* the record's camera for everything: the terrain then matches the clouds drawn
             * for it, whatever the lag behind the camera sent */
            wxsky_gl_camera_matrices(&rec, 0, view, proj);
            if (demo_terrain_draw(&terrain, *gl, &rec, view, proj, 0) != 0) {
                snprintf(err, APP_ERR, "%s", terrain.error);
                goto done;
            }
            if ((st = wxsky_gl_draw_background(*gl, view, proj)) != WXSKY_OK ||
                (st = wxsky_gl_draw_near(*gl)) != WXSKY_OK ||
                (st = wxsky_gl_draw_near_front(*gl)) != WXSKY_OK) {
                snprintf(err, APP_ERR, "compositing: %s: %s", wxsky_status_name(st),
                         wxsky_gl_error(*gl));
                goto done;
            }
        }
        if (a->out && have) { /* keep the latest picture shown, for --out */
            glPixelStorei(GL_PACK_ALIGNMENT, 4);
            glReadPixels(0, 0, (GLsizei)a->width, (GLsizei)a->height, GL_RGBA, GL_UNSIGNED_BYTE,
                         shot);
            kept = 1;
        }
        glfwSwapBuffers(win);
        glfwPollEvents();
        ++drawn;
    }
    printf("flew %ld frames in %.1f s, %ld of them with a new frame from the daemon\n", drawn,
           (app_now_ms() - t0) / 1000.0, composited);
    if (a->out) {
        size_t row = (size_t)a->width * 4;
        if (!kept) {
            snprintf(err, APP_ERR, "no frame from the daemon was shown");
            goto done;
        }
        for (uint32_t y = 0; y < a->height / 2; ++y) { /* the window's rows run bottom up */
            uint8_t *top = shot + (size_t)y * row, *bottom = shot + (size_t)(a->height - 1 - y) * row;
            for (size_t i = 0; i < row; ++i) {
                uint8_t t = top[i];
                top[i] = bottom[i];
                bottom[i] = t;
            }
        }
        if (png_write_rgba(a->out, shot, a->width, a->height, err, APP_ERR) != 0)
            goto done;
        printf("wrote %s (%ux%u, the last frame shown)\n", a->out, a->width, a->height);
    }
    code = 0;
done:
    demo_terrain_free(&terrain);
    wxsky_gl_free(*gl);
    *gl = NULL;
    glfwDestroyWindow(win);
    glfwTerminate();
    free(shot);
    return code;
}
#endif

static int save(const char *dir, const char *name, const app_gl *g, uint8_t *pixels, char *err) {
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    if (app_gl_read(g, pixels, err) != 0)
        return -1;
    return png_write_rgba(path, pixels, g->width, g->height, err, APP_ERR);
}

static int debug_pictures(const args *a, const app_gl *g, demo_terrain *t,
                          wxsky_gl_compositor *gl, const wxsky_segment *seg,
                          const wxsky_frame_copy *copy, const wxsky_record *rec, uint8_t *pixels,
                          char *err) {
    const char *const dumped[2] = {"near", "sky"};
    char path[1024];
    if (draw(t, gl, rec, 0, 1, 0, err) || save(a->debug_out, "terrain.png", g, pixels, err) ||
        draw(t, gl, rec, 0, 1, 1, err) || save(a->debug_out, "distance.png", g, pixels, err) ||
        draw(t, gl, rec, 1, 0, 0, err) || save(a->debug_out, "clouds.png", g, pixels, err))
        return -1;
    for (int i = 0; i < 2; ++i) {
        /* Each at its own size: the near layer is drawn at a fraction of the picture. */
        int layer = wxsky_segment_find_layer(seg, dumped[i]);
        if (layer < 0 || !copy->width[layer] || !copy->height[layer]) {
            snprintf(err, APP_ERR, "the frame has no %s layer", dumped[i]);
            return -1;
        }
        snprintf(path, sizeof path, "%s/%s.png", a->debug_out, dumped[i]);
        if (png_write_rgba(path, copy->pixels[layer], copy->width[layer], copy->height[layer],
                           err, APP_ERR) != 0)
            return -1;
    }
    return 0;
}

int main(int argc, char **argv) {
    args a;
    char err[APP_ERR] = "";
    uint8_t params[256], *pixels = NULL, *strip = NULL;
    wxsky_mp_writer w;
    wxsky_message res;
    wxsky_client *client = NULL;
    wxsky_segment *seg = NULL;
    wxsky_gl_compositor *gl = NULL;
    wxsky_frame_copy copy;
    wxsky_record rec;
    demo_terrain terrain;
    app_gl g;
    int code = 1, st, timeout_ms, cols, rows;
    uint32_t strip_w, strip_h;
    double ground_m = 0.0;

    memset(&copy, 0, sizeof copy);
    memset(&g, 0, sizeof g);
    memset(&terrain, 0, sizeof terrain);
    if (argc == 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) {
        printf("%s\n", USAGE);
        return 0;
    }
    if (!parse(argc, argv, &a))
        return 64;
    timeout_ms = (int)(a.timeout_s * 1000.0);
    cols = a.frames > 1 ? 2 : 1;
    rows = (a.frames + cols - 1) / cols;
    strip_w = (uint32_t)cols * a.width + (uint32_t)(cols - 1) * GAP_PX;
    strip_h = (uint32_t)rows * a.height + (uint32_t)(rows - 1) * GAP_PX;

    client = wxsky_client_new(0, 0);
    seg = wxsky_segment_new();
    gl = wxsky_gl_new();
    pixels = malloc((size_t)a.width * a.height * 4);
    strip = calloc((size_t)strip_w * strip_h, 4);
    if (!client || !seg || !gl || !pixels || !strip) {
        snprintf(err, sizeof err, "out of memory");
        goto done;
    }
    memset(strip, 255, (size_t)strip_w * strip_h * 4);
    if (app_attach(client, seg, &copy, a.control, a.shm, timeout_ms, err) != 0)
        goto done;
    if (a.time_utc) {
        wxsky_mp_writer_init(&w, params, sizeof params);
        wxsky_mp_write_map(&w, 1);
        wxsky_mp_write_cstr(&w, "time_utc");
        wxsky_mp_write_cstr(&w, a.time_utc);
        if (app_call(client, "set_time", &w, timeout_ms, &res, err) != WXSKY_OK)
            goto done;
    }
    if (ground_alt(client, timeout_ms, &ground_m, err) != 0)
        goto done;
#ifdef WXSKY_DEMO_GLFW
    if (a.window) {
        code = fly_window(&a, client, seg, &copy, &gl, ground_m, err);
        goto done;
    }
#endif
    if (app_gl_open(&g, a.width, a.height, err) != 0) {
        code = 2;
        goto done;
    }
    if ((st = wxsky_gl_init(gl, seg)) != WXSKY_OK) {
        snprintf(err, sizeof err, "GL compositor: %s: %s", wxsky_status_name(st),
                 wxsky_gl_error(gl));
        goto done;
    }
    if (demo_terrain_init(&terrain, ground_m) != 0) {
        snprintf(err, sizeof err, "%s", terrain.error);
        goto done;
    }

    for (int k = 0; k < a.frames; ++k) {
        wxsky_camera want, cam;
        uint32_t x0, y0;
        path_camera(a.frames > 1 ? (double)k / (a.frames - 1) : 0.0, ground_m, &a, &want);
        uint32_t id;
        if ((st = wxsky_set_camera(client, &want, &id)) != WXSKY_OK ||
            (st = wxsky_client_wait(client, id, timeout_ms, &res)) != WXSKY_OK) {
            snprintf(err, sizeof err, "set_camera: %s: %s", wxsky_status_name(st),
                     wxsky_client_error(client));
            goto done;
        }
        if (app_camera_from_result(&res, &cam) != WXSKY_OK) {
            snprintf(err, sizeof err, "set_camera: the result is not a camera");
            goto done;
        }
        if (app_wait_frame(seg, &copy, &rec, wxsky_segment_latest_frame(seg) + 1, &cam,
                           timeout_ms, err) != WXSKY_OK ||
            app_wait_settled_frame(client, seg, &copy, &rec, &cam, timeout_ms, err) != WXSKY_OK)
            goto done;
        if ((st = wxsky_gl_upload_copy(gl, &copy, &rec)) != WXSKY_OK) {
            snprintf(err, sizeof err, "upload: %s: %s", wxsky_status_name(st), wxsky_gl_error(gl));
            goto done;
        }
        if (k == a.debug_frame &&
            debug_pictures(&a, &g, &terrain, gl, seg, &copy, &rec, pixels, err) != 0)
            goto done;
        if (draw(&terrain, gl, &rec, 0, 0, 0, err) != 0 || app_gl_read(&g, pixels, err) != 0)
            goto done;
        if (k == a.debug_frame) {
            char path[1024];
            snprintf(path, sizeof path, "%s/final.png", a.debug_out);
            if (png_write_rgba(path, pixels, a.width, a.height, err, sizeof err) != 0)
                goto done;
        }
        x0 = (uint32_t)(k % cols) * (a.width + GAP_PX);
        y0 = (uint32_t)(k / cols) * (a.height + GAP_PX);
        for (uint32_t y = 0; y < a.height; ++y)
            memcpy(strip + ((size_t)(y0 + y) * strip_w + x0) * 4, pixels + (size_t)y * a.width * 4,
                   (size_t)a.width * 4);
        printf("frame %d: camera (%.0f, %.0f, %.0f) m heading %.1f pitch %.1f, daemon frame %llu\n",
               k, rec.position_m[0], rec.position_m[1], rec.position_m[2], rec.heading_deg,
               rec.pitch_deg, (unsigned long long)rec.frame_number);
    }
    if (png_write_rgba(a.out, strip, strip_w, strip_h, err, sizeof err) != 0)
        goto done;
    printf("wrote %s (%ux%u, %d frames)\n", a.out, strip_w, strip_h, a.frames);
    code = 0;
done:
    if (code != 0)
        fprintf(stderr, "%s: error: %s\n", PROG, err[0] ? err : "failed");
    if (g.egl_) {
        demo_terrain_free(&terrain);
        wxsky_gl_free(gl);
        gl = NULL;
        app_gl_close(&g);
    }
    wxsky_gl_free(gl);
    free(pixels);
    free(strip);
    app_copy_free(&copy);
    wxsky_segment_free(seg);
    wxsky_client_free(client);
    return code;
}
