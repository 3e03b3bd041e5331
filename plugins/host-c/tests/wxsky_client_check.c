/*
 * wxsky_client_check: drives the host kit's MessagePack code and control-channel client for
 * tests/test_host_c_client.py. Every line on stdout is one JSON object; on failure the last
 * line on stderr is "wxsky_client_check: STEP: WXSKY_NAME: message" and the exit status is 1
 * (2: bad usage, 3: an internal check failed, 4: the --no-network sandbox could not be set).
 *
 *   session [--buffer B] [--queue Q] [--timeout MS] [--no-network] ADDR STEP...
 *       ADDR is unix:PATH, tcp:HOST:PORT or "default". Steps, in order:
 *         sub:T1,T2   unsub:T1,T2       (un)subscribe and wait for the answer
 *         call:METHOD[:HEX]             wxsky_client_call; HEX: the params as msgpack
 *         send:METHOD[:HEX]             wxsky_client_request only (prints the msgid)
 *         wait:MSGID[:MS]               wxsky_client_wait (with MS, a timeout is printed and
 *                                       the script goes on)
 *         status  camera:E,N,U,H,P,R,FOV[,W,H]  aircraft:E,N,U|none  time:ISO[,RATE]
 *         rate:R  preset:NAME  metar:REPORT  release[:SOURCE]     typed request + wait
 *         radar:RANGE_NM,TILT_DEG,SIZE_PX   wxsky_request_radar + wait + wxsky_radar_decode
 *         poll:N                        the next N messages
 *         note:TOPIC                    messages until a notification TOPIC
 *         expect:WXSKY_NAME             messages until poll returns that (negative) status
 *         drain:MS                      every message for MS milliseconds
 *         reconnect:TRIES               wxsky_client_reconnect, every 20 ms until it works
 *         sleep:MS  dropped  close
 *         textures                      wxsky_request_textures (§6): the answer, and each
 *                                       descriptor's first 16 bytes (pread) and st_ino
 *         fds                           how many descriptors this process has open
 *       A WXSKY_EREMOTE answer is printed and the script goes on; any other error ends it.
 *   mp-encode TOKEN...     one msgpack object from tokens (n t f u:N i:N d:HEX64 s:HEX b:HEX
 *                          a:COUNT m:COUNT); prints {"hex": ...}
 *   mp-decode HEX...       for each: {"size": object_size, "value": the object as JSON}
 *   mp-selftest            encode/decode round trips, boundaries, refusals, every prefix
 *   mp-fuzz FILE [SOCKET]  FILE: records (u32 little-endian length, bytes); each goes through
 *                          object_size (every prefix), a reader walk and, with SOCKET (a path
 *                          for a unix socket), a client that receives it from a server.
 * JSON: floats always carry a '.' or an exponent (NaN, Infinity as Python's json reads them),
 * bin is {"$bin": "hex"}.
 */
#include "wxsky_host.h"

#include <dirent.h>
#include <fcntl.h>
#include <errno.h>
#include <math.h>
#include <poll.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#ifdef __linux__
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <stddef.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#endif

static int64_t now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

static void sleep_ms(int ms) {
    struct timespec ts = {ms / 1000, (long)(ms % 1000) * 1000000L};
    nanosleep(&ts, NULL);
}

static void die_usage(const char *what) {
    fprintf(stderr, "wxsky_client_check: usage: %s (see the comment at the top)\n", what);
    exit(2);
}

static void check(int cond, const char *what) {
    if (!cond) {
        fprintf(stderr, "wxsky_client_check: check failed: %s\n", what);
        exit(3);
    }
}

/* ---------------------------------------------------------------------------------------
 * Hex and JSON
 * ------------------------------------------------------------------------------------- */

static int hexval(char ch) {
    if (ch >= '0' && ch <= '9') return ch - '0';
    if (ch >= 'a' && ch <= 'f') return ch - 'a' + 10;
    if (ch >= 'A' && ch <= 'F') return ch - 'A' + 10;
    return -1;
}

/* Decodes hex into a malloc'd buffer (never NULL for valid hex). */
static uint8_t *unhex(const char *hex, size_t *len) {
    size_t n = strlen(hex);
    if (n % 2) die_usage("odd-length hex");
    uint8_t *out = malloc(n / 2 + 1);
    check(out != NULL, "malloc");
    for (size_t i = 0; i < n / 2; i++) {
        int a = hexval(hex[2 * i]), b = hexval(hex[2 * i + 1]);
        if (a < 0 || b < 0) die_usage("bad hex digit");
        out[i] = (uint8_t)(a * 16 + b);
    }
    *len = n / 2;
    return out;
}

static void put_hex(FILE *f, const uint8_t *p, size_t n) {
    for (size_t i = 0; i < n; i++) fprintf(f, "%02x", p[i]);
}

static void put_json_str(FILE *f, const char *s, size_t n) {
    fputc('"', f);
    for (size_t i = 0; i < n; i++) {
        unsigned char ch = (unsigned char)s[i];
        if (ch == '"' || ch == '\\') fprintf(f, "\\%c", ch);
        else if (ch < 0x20 || ch == 0x7f) fprintf(f, "\\u%04x", ch);
        else fputc(ch, f);
    }
    fputc('"', f);
}

static void put_double(FILE *f, double v) {
    if (isnan(v)) { fputs("NaN", f); return; }
    if (isinf(v)) { fputs(v > 0 ? "Infinity" : "-Infinity", f); return; }
    char buf[64];
    snprintf(buf, sizeof buf, "%.17g", v);
    fputs(buf, f);
    if (strpbrk(buf, ".e") == NULL) fputs(".0", f);
}

/* Prints one item as JSON; iterative over containers (any depth) with an explicit stack. */
static int put_json(FILE *f, wxsky_mp_reader *r) {
    struct level { uint32_t left; int map; int first; } stack[WXSKY_MP_MAX_DEPTH + 2];
    int depth = 0;
    for (;;) {
        if (depth > 0) {
            struct level *l = &stack[depth - 1];
            if (l->left == 0) {
                fputc(l->map ? '}' : ']', f);
                depth--;
                if (depth == 0) return 0;
                continue;
            }
            int value = l->map && l->left % 2 == 1;
            if (value) fputc(':', f);
            else if (!l->first) fputc(',', f);
            l->first = 0;
            l->left--;
        }
        wxsky_mp_type t = wxsky_mp_peek(r);
        switch (t) {
        case WXSKY_MP_NIL: wxsky_mp_read_nil(r); fputs("null", f); break;
        case WXSKY_MP_BOOL: {
            int b;
            wxsky_mp_read_bool(r, &b);
            fputs(b ? "true" : "false", f);
            break;
        }
        case WXSKY_MP_INT: {
            int64_t v;
            wxsky_mp_read_int(r, &v);
            fprintf(f, "%lld", (long long)v);
            break;
        }
        case WXSKY_MP_UINT: {
            uint64_t v;
            wxsky_mp_read_uint(r, &v);
            fprintf(f, "%llu", (unsigned long long)v);
            break;
        }
        case WXSKY_MP_FLOAT: {
            double v;
            wxsky_mp_read_double(r, &v);
            put_double(f, v);
            break;
        }
        case WXSKY_MP_STR: {
            const char *s;
            uint32_t n;
            wxsky_mp_read_str(r, &s, &n);
            put_json_str(f, s, n);
            break;
        }
        case WXSKY_MP_BIN: {
            const uint8_t *b;
            uint32_t n;
            wxsky_mp_read_bin(r, &b, &n);
            fputs("{\"$bin\":\"", f);
            put_hex(f, b, n);
            fputs("\"}", f);
            break;
        }
        case WXSKY_MP_ARRAY:
        case WXSKY_MP_MAP: {
            uint32_t n;
            if (t == WXSKY_MP_ARRAY) wxsky_mp_read_array(r, &n);
            else wxsky_mp_read_map(r, &n);
            if (depth >= WXSKY_MP_MAX_DEPTH + 1) return -1;
            fputc(t == WXSKY_MP_MAP ? '{' : '[', f);
            stack[depth].left = t == WXSKY_MP_MAP ? 2 * n : n;
            stack[depth].map = t == WXSKY_MP_MAP;
            stack[depth].first = 1;
            depth++;
            continue;
        }
        default: return -1;
        }
        if (depth == 0) return 0;
    }
}

/* ---------------------------------------------------------------------------------------
 * session
 * ------------------------------------------------------------------------------------- */

typedef struct session {
    wxsky_client *c;
    int timeout_ms;
    const char *step;
} session;

static void fail_step(const session *s, int st) {
    printf("{\"step\":");
    put_json_str(stdout, s->step, strlen(s->step));
    printf(",\"status\":\"%s\",\"message\":", wxsky_status_name(st));
    const char *m = wxsky_client_error(s->c);
    put_json_str(stdout, m, strlen(m));
    printf("}\n");
    fprintf(stderr, "wxsky_client_check: %s: %s: %s\n", s->step, wxsky_status_name(st), m);
    wxsky_client_free(s->c);
    exit(1);
}

static void print_message(const session *s, int st, const wxsky_message *m) {
    printf("{\"step\":");
    put_json_str(stdout, s->step, strlen(s->step));
    printf(",\"status\":\"%s\"", wxsky_status_name(st));
    if (m->kind == WXSKY_RESPONSE) {
        printf(",\"kind\":\"response\",\"msgid\":");
        if (m->has_msgid) printf("%lu", (unsigned long)m->msgid);
        else printf("null");
        printf(",\"error\":");
        if (m->error) put_json_str(stdout, m->error, m->error_len);
        else printf("null");
        printf(",\"result\":");
    } else {
        printf(",\"kind\":\"notification\",\"method\":");
        put_json_str(stdout, m->method, m->method_len);
        printf(",\"params\":");
    }
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, m->body, m->body_len);
    check(put_json(stdout, &r) == 0 && r.p == r.end, "a message body is one msgpack item");
    printf("}\n");
}

/* The answer to msgid: printed; EREMOTE is an answer too. */
static void finish(session *s, int st, uint32_t msgid) {
    if (st != WXSKY_OK) fail_step(s, st);
    wxsky_message m;
    st = wxsky_client_wait(s->c, msgid, s->timeout_ms, &m);
    if (st != WXSKY_OK && st != WXSKY_EREMOTE) fail_step(s, st);
    print_message(s, st, &m);
}

/* poll, waiting on the socket while it says WXSKY_AGAIN; the status (never AGAIN unless the
 * deadline passed). */
static int poll_wait(session *s, wxsky_message *m, int64_t deadline) {
    for (;;) {
        int st = wxsky_client_poll(s->c, m);
        if (st != WXSKY_AGAIN) return st;
        int left = (int)(deadline - now_ms());
        if (left <= 0) return WXSKY_AGAIN;
        struct pollfd p = {wxsky_client_fd(s->c), POLLIN, 0};
        (void)poll(&p, 1, left);
    }
}

static int open_fds(void) {
    int n = 0;
    DIR *d = opendir("/proc/self/fd");
    if (d == NULL) return -1;
    for (struct dirent *e = readdir(d); e != NULL; e = readdir(d))
        if (e->d_name[0] != '.') n++;
    closedir(d);
    return n - 1; /* the directory's own */
}

static void print_textures(session *s, int st, const wxsky_textures *t) {
    printf("{\"step\":");
    put_json_str(stdout, s->step, strlen(s->step));
    printf(",\"status\":\"%s\",\"supported\":%s,\"reason\":", wxsky_status_name(st),
           t->supported ? "true" : "false");
    put_json_str(stdout, st == WXSKY_OK ? t->reason : wxsky_client_error(s->c),
                 strlen(st == WXSKY_OK ? t->reason : wxsky_client_error(s->c)));
    printf(",\"slot_count\":%u,\"fd_count\":%u,\"fds\":[", t->slot_count, t->fd_count);
    for (uint32_t i = 0; i < t->fd_count; i++) {
        uint8_t head[16];
        struct stat sb;
        ssize_t n = pread(t->fds[i], head, sizeof head, 0);
        int cloexec = (fcntl(t->fds[i], F_GETFD) & FD_CLOEXEC) != 0;
        printf("%s{\"head\":\"", i ? "," : "");
        if (n > 0) put_hex(stdout, head, (size_t)n);
        printf("\",\"ino\":%llu,\"cloexec\":%s}",
               fstat(t->fds[i], &sb) == 0 ? (unsigned long long)sb.st_ino : 0ull,
               cloexec ? "true" : "false");
    }
    printf("],\"textures\":[");
    for (uint32_t i = 0; i < t->count; i++) {
        const wxsky_texture *x = &t->textures[i];
        printf("%s{\"layer\":", i ? "," : "");
        put_json_str(stdout, x->layer, strlen(x->layer));
        printf(",\"slot\":%u,\"width\":%u,\"height\":%u,\"fourcc\":%u,\"modifier\":%llu,"
               "\"planes\":[", x->slot, x->width, x->height, x->fourcc,
               (unsigned long long)x->modifier);
        for (uint32_t p = 0; p < x->plane_count; p++) {
            int index = -1;
            for (uint32_t k = 0; k < t->fd_count; k++)
                if (t->fds[k] == x->planes[p].fd) index = (int)k;
            printf("%s{\"fd\":%d,\"stride\":%u,\"offset\":%u}", p ? "," : "", index,
                   x->planes[p].stride, x->planes[p].offset);
        }
        printf("]}");
    }
    printf("]}\n");
}

static size_t split(char *text, const char **parts, size_t max) {
    size_t n = 0;
    char *save = NULL;
    for (char *t = strtok_r(text, ",", &save); t && n < max; t = strtok_r(NULL, ",", &save))
        parts[n++] = t;
    return n;
}

static void install_no_network(void) {
#if defined(__linux__) && defined(SECCOMP_MODE_FILTER)
#ifdef SECCOMP_RET_KILL_PROCESS
#define KILL SECCOMP_RET_KILL_PROCESS
#else
#define KILL SECCOMP_RET_KILL
#endif
    /* Test-only sandbox: any attempt to make a socket or send kills the process (SIGSYS), so
     * a refused address provably sent nothing. */
    struct sock_filter f[] = {
        BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(struct seccomp_data, nr)),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, __NR_socket, 0, 1),
        BPF_STMT(BPF_RET | BPF_K, KILL),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, __NR_connect, 0, 1),
        BPF_STMT(BPF_RET | BPF_K, KILL),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, __NR_sendto, 0, 1),
        BPF_STMT(BPF_RET | BPF_K, KILL),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, __NR_sendmsg, 0, 1),
        BPF_STMT(BPF_RET | BPF_K, KILL),
        BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW),
    };
    struct sock_fprog prog = {(unsigned short)(sizeof f / sizeof f[0]), f};
    if (prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0 ||
        prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, &prog) != 0) {
        fprintf(stderr, "wxsky_client_check: seccomp unavailable: %s\n", strerror(errno));
        exit(4);
    }
#else
    fprintf(stderr, "wxsky_client_check: seccomp unavailable on this system\n");
    exit(4);
#endif
}

static int run_session(int argc, char **argv) {
    size_t buffer = 0, queued = 0;
    int timeout = 5000, no_network = 0, i = 0;
    for (; i < argc && strncmp(argv[i], "--", 2) == 0; i++) {
        if (strcmp(argv[i], "--no-network") == 0) no_network = 1;
        else if (i + 1 < argc && strcmp(argv[i], "--buffer") == 0)
            buffer = strtoul(argv[++i], NULL, 10);
        else if (i + 1 < argc && strcmp(argv[i], "--queue") == 0)
            queued = strtoul(argv[++i], NULL, 10);
        else if (i + 1 < argc && strcmp(argv[i], "--timeout") == 0)
            timeout = atoi(argv[++i]);
        else die_usage("session: unknown option");
    }
    if (i >= argc) die_usage("session ADDR STEP...");
    session s = {wxsky_client_new(buffer, queued), timeout, "connect"};
    check(s.c != NULL, "wxsky_client_new");
    if (no_network) install_no_network();
    const char *addr = strcmp(argv[i], "default") == 0 ? NULL : argv[i];
    int st = wxsky_client_connect(s.c, addr);
    if (st != WXSKY_OK) fail_step(&s, st);
    printf("{\"step\":\"connect\",\"status\":\"WXSKY_OK\"}\n");
    for (i++; i < argc; i++) {
        char text[4096];
        snprintf(text, sizeof text, "%s", argv[i]);
        s.step = argv[i];
        char *colon = strchr(text, ':');
        char *arg = colon ? colon + 1 : NULL;
        if (colon) *colon = '\0';
        const char *verb = text;
        uint32_t id = 0;
        if (strcmp(verb, "sub") == 0 || strcmp(verb, "unsub") == 0) {
            const char *topics[64];
            size_t n = arg ? split(arg, topics, 64) : 0;
            st = verb[0] == 's' ? wxsky_subscribe(s.c, topics, n, &id)
                                : wxsky_unsubscribe(s.c, topics, n, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "call") == 0 || strcmp(verb, "send") == 0) {
            if (!arg) die_usage("call:METHOD[:HEX]");
            char *hex = strchr(arg, ':');
            uint8_t *params = NULL;
            size_t plen = 0;
            if (hex) {
                *hex++ = '\0';
                params = unhex(hex, &plen);
            }
            if (verb[0] == 'c') {
                wxsky_message m;
                st = wxsky_client_call(s.c, arg, params, plen, s.timeout_ms, &m);
                free(params);
                if (st != WXSKY_OK && st != WXSKY_EREMOTE) fail_step(&s, st);
                print_message(&s, st, &m);
            } else {
                st = wxsky_client_request(s.c, arg, params, plen, &id);
                free(params);
                if (st != WXSKY_OK) fail_step(&s, st);
                printf("{\"step\":");
                put_json_str(stdout, s.step, strlen(s.step));
                printf(",\"status\":\"WXSKY_OK\",\"msgid\":%lu}\n", (unsigned long)id);
            }
        } else if (strcmp(verb, "wait") == 0) {
            if (!arg) die_usage("wait:MSGID[:MS]");
            char *ms = strchr(arg, ':');
            int timeout_ms = ms ? atoi(ms + 1) : s.timeout_ms;
            wxsky_message m;
            st = wxsky_client_wait(s.c, (uint32_t)strtoul(arg, NULL, 10), timeout_ms, &m);
            if (st == WXSKY_ETIMEDOUT && ms) {
                printf("{\"step\":");
                put_json_str(stdout, s.step, strlen(s.step));
                printf(",\"status\":\"WXSKY_ETIMEDOUT\"}\n");
                continue;
            }
            if (st != WXSKY_OK && st != WXSKY_EREMOTE) fail_step(&s, st);
            print_message(&s, st, &m);
        } else if (strcmp(verb, "status") == 0) {
            st = wxsky_request_status(s.c, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "camera") == 0) {
            const char *p[9];
            size_t n = arg ? split(arg, p, 9) : 0;
            if (n != 7 && n != 9) die_usage("camera:E,N,U,H,P,R,FOV[,W,H]");
            wxsky_camera cam;
            memset(&cam, 0, sizeof cam);
            for (int k = 0; k < 3; k++) cam.position_m[k] = strtod(p[k], NULL);
            cam.heading_deg = strtod(p[3], NULL);
            cam.pitch_deg = strtod(p[4], NULL);
            cam.roll_deg = strtod(p[5], NULL);
            cam.fov_deg = strtod(p[6], NULL);
            if (n == 9) {
                cam.width = (uint32_t)strtoul(p[7], NULL, 10);
                cam.height = (uint32_t)strtoul(p[8], NULL, 10);
            }
            st = wxsky_set_camera(s.c, &cam, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "aircraft") == 0) {
            if (!arg) die_usage("aircraft:E,N,U|none");
            if (strcmp(arg, "none") == 0) {
                st = wxsky_set_aircraft(s.c, NULL, &id);
                finish(&s, st, id);
            } else {
                const char *p[3];
                if (split(arg, p, 3) != 3) die_usage("aircraft:E,N,U");
                double pos[3] = {strtod(p[0], NULL), strtod(p[1], NULL), strtod(p[2], NULL)};
                st = wxsky_set_aircraft(s.c, pos, &id);
                finish(&s, st, id);
            }
        } else if (strcmp(verb, "time") == 0) {
            if (!arg) die_usage("time:ISO[,RATE]");
            char *comma = strchr(arg, ',');
            double rate = 0;
            if (comma) {
                *comma = '\0';
                rate = strtod(comma + 1, NULL);
            }
            st = wxsky_set_time(s.c, arg, comma ? &rate : NULL, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "rate") == 0) {
            if (!arg) die_usage("rate:R");
            double rate = strtod(arg, NULL);
            st = wxsky_set_time(s.c, NULL, &rate, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "preset") == 0) {
            if (!arg) die_usage("preset:NAME");
            st = wxsky_apply_preset(s.c, arg, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "metar") == 0) {
            if (!arg) die_usage("metar:REPORT");
            st = wxsky_apply_metar(s.c, arg, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "release") == 0) {
            st = wxsky_release(s.c, arg, &id);
            finish(&s, st, id);
        } else if (strcmp(verb, "radar") == 0) {
            if (!arg) die_usage("radar:RANGE_NM,TILT_DEG,SIZE_PX");
            double range_nm = 0, tilt_deg = 0;
            unsigned size_px = 0;
            if (sscanf(arg, "%lf,%lf,%u", &range_nm, &tilt_deg, &size_px) != 3)
                die_usage("radar:RANGE_NM,TILT_DEG,SIZE_PX");
            st = wxsky_request_radar(s.c, range_nm, tilt_deg, size_px, &id);
            if (st != WXSKY_OK) fail_step(&s, st);
            wxsky_message m;
            st = wxsky_client_wait(s.c, id, s.timeout_ms, &m);
            if (st != WXSKY_OK && st != WXSKY_EREMOTE) fail_step(&s, st);
            if (st == WXSKY_EREMOTE) {
                print_message(&s, st, &m);
            } else {
                wxsky_radar radar;
                st = wxsky_radar_decode(m.body, m.body_len, &radar);
                if (st != WXSKY_OK) fail_step(&s, st);
                unsigned max_byte = 0;
                uint64_t n = radar.pending ? 0 : (uint64_t)radar.size_px * radar.size_px;
                for (uint64_t k = 0; k < n; k++)
                    if (radar.pixels[k] > max_byte) max_byte = radar.pixels[k];
                printf("{\"radar\": {\"pending\": %s, \"size_px\": %u, \"range_nm\": %.17g, "
                       "\"tilt_deg\": %.17g, \"max_dbz\": %.17g, \"bytes\": %llu}}\n",
                       radar.pending ? "true" : "false", radar.size_px, radar.range_nm,
                       radar.tilt_deg,
                       radar.pending ? -32.0 : max_byte * radar.dbz_step + radar.dbz_offset,
                       (unsigned long long)n);
                fflush(stdout);
            }
        } else if (strcmp(verb, "poll") == 0 || strcmp(verb, "note") == 0) {
            long want = verb[0] == 'p' ? (arg ? atol(arg) : 1) : -1;
            if (want < 0 && !arg) die_usage("note:TOPIC");
            int64_t deadline = now_ms() + s.timeout_ms;
            for (long got = 0; want < 0 || got < want; got++) {
                wxsky_message m;
                st = poll_wait(&s, &m, deadline);
                if (st == WXSKY_AGAIN) {
                    fprintf(stderr, "wxsky_client_check: %s: timed out\n", s.step);
                    wxsky_client_free(s.c);
                    return 1;
                }
                if (st != WXSKY_OK) fail_step(&s, st);
                print_message(&s, st, &m);
                if (want < 0 && m.kind == WXSKY_NOTIFICATION && m.method_len == strlen(arg) &&
                    memcmp(m.method, arg, m.method_len) == 0)
                    break;
            }
        } else if (strcmp(verb, "expect") == 0) {
            if (!arg) die_usage("expect:WXSKY_NAME");
            int64_t deadline = now_ms() + s.timeout_ms;
            for (;;) {
                wxsky_message m;
                st = poll_wait(&s, &m, deadline);
                if (st == WXSKY_OK) {
                    print_message(&s, st, &m);
                    continue;
                }
                if (st == WXSKY_AGAIN) {
                    fprintf(stderr, "wxsky_client_check: %s: timed out\n", s.step);
                    wxsky_client_free(s.c);
                    return 1;
                }
                if (strcmp(wxsky_status_name(st), arg) != 0) fail_step(&s, st);
                printf("{\"step\":");
                put_json_str(stdout, s.step, strlen(s.step));
                printf(",\"status\":\"%s\",\"message\":", wxsky_status_name(st));
                put_json_str(stdout, wxsky_client_error(s.c), strlen(wxsky_client_error(s.c)));
                printf("}\n");
                break;
            }
        } else if (strcmp(verb, "drain") == 0) {
            int64_t deadline = now_ms() + (arg ? atoi(arg) : 200);
            for (;;) {
                wxsky_message m;
                st = poll_wait(&s, &m, deadline);
                if (st == WXSKY_AGAIN) break;
                if (st != WXSKY_OK) fail_step(&s, st);
                print_message(&s, st, &m);
            }
        } else if (strcmp(verb, "reconnect") == 0) {
            long tries = arg ? atol(arg) : 100;
            for (long k = 1;; k++) {
                st = wxsky_client_reconnect(s.c);
                if (st == WXSKY_OK) {
                    printf("{\"step\":\"reconnect\",\"status\":\"WXSKY_OK\",\"tries\":%ld}\n",
                           k);
                    break;
                }
                if (k >= tries) fail_step(&s, st);
                sleep_ms(20);
            }
        } else if (strcmp(verb, "sleep") == 0) {
            sleep_ms(arg ? atoi(arg) : 100);
        } else if (strcmp(verb, "textures") == 0) {
            wxsky_textures *t = malloc(sizeof *t);
            check(t != NULL, "malloc");
            wxsky_textures_init(t);
            st = wxsky_request_textures(s.c, s.timeout_ms, t);
            if (st != WXSKY_OK && st != WXSKY_EREMOTE && st != WXSKY_ESYS &&
                st != WXSKY_EFORMAT) {
                free(t);
                fail_step(&s, st);
            }
            print_textures(&s, st, t);
            wxsky_textures_close(t);
            free(t);
        } else if (strcmp(verb, "fds") == 0) {
            printf("{\"step\":\"fds\",\"open\":%d}\n", open_fds());
        } else if (strcmp(verb, "dropped") == 0) {
            printf("{\"step\":\"dropped\",\"dropped\":%llu}\n",
                   (unsigned long long)wxsky_client_dropped(s.c));
        } else if (strcmp(verb, "close") == 0) {
            wxsky_client_close(s.c);
            printf("{\"step\":\"close\",\"status\":\"WXSKY_OK\"}\n");
        } else {
            die_usage("unknown step");
        }
    }
    wxsky_client_free(s.c);
    return 0;
}

/* ---------------------------------------------------------------------------------------
 * mp-encode, mp-decode
 * ------------------------------------------------------------------------------------- */

static void fill_bytes(const char *spec, uint8_t **out, size_t *len) {
    /* "HEX" or "LEN:BYTEHEX" (LEN copies of one byte) */
    const char *colon = strchr(spec, ':');
    if (colon == NULL) {
        *out = unhex(spec, len);
        return;
    }
    size_t n = strtoul(spec, NULL, 10), one;
    uint8_t *b = unhex(colon + 1, &one);
    check(one == 1, "LEN:BYTEHEX takes one byte");
    *out = malloc(n + 1);
    check(*out != NULL, "malloc");
    memset(*out, b[0], n);
    free(b);
    *len = n;
}

static int run_encode(int argc, char **argv) {
    size_t cap = 16u * 1024u * 1024u;
    uint8_t *buf = malloc(cap);
    check(buf != NULL, "malloc");
    wxsky_mp_writer w;
    wxsky_mp_writer_init(&w, buf, cap);
    for (int i = 0; i < argc; i++) {
        const char *t = argv[i], *v = t[0] && t[1] == ':' ? t + 2 : "";
        uint8_t *bytes = NULL;
        size_t n = 0;
        switch (t[0]) {
        case 'n': wxsky_mp_write_nil(&w); break;
        case 't': wxsky_mp_write_bool(&w, 1); break;
        case 'f': wxsky_mp_write_bool(&w, 0); break;
        case 'u': wxsky_mp_write_uint(&w, strtoull(v, NULL, 10)); break;
        case 'i': wxsky_mp_write_int(&w, strtoll(v, NULL, 10)); break;
        case 'd': {
            bytes = unhex(v, &n);
            check(n == 8, "d:HEX takes 8 bytes");
            uint64_t bits = 0;
            for (int k = 0; k < 8; k++) bits = (bits << 8) | bytes[k];
            double d;
            memcpy(&d, &bits, sizeof d);
            wxsky_mp_write_double(&w, d);
            break;
        }
        case 's': fill_bytes(v, &bytes, &n); wxsky_mp_write_str(&w, (const char *)bytes, n); break;
        case 'b': fill_bytes(v, &bytes, &n); wxsky_mp_write_bin(&w, bytes, n); break;
        case 'a': wxsky_mp_write_array(&w, (uint32_t)strtoul(v, NULL, 10)); break;
        case 'm': wxsky_mp_write_map(&w, (uint32_t)strtoul(v, NULL, 10)); break;
        default: die_usage("mp-encode: unknown token");
        }
        free(bytes);
    }
    check(!w.overflow, "mp-encode fits");
    printf("{\"hex\":\"");
    put_hex(stdout, buf, w.len);
    printf("\"}\n");
    free(buf);
    return 0;
}

static uint8_t *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (f == NULL) {
        fprintf(stderr, "wxsky_client_check: %s: %s\n", path, strerror(errno));
        exit(2);
    }
    size_t cap = 1 << 16, n = 0;
    uint8_t *buf = malloc(cap);
    check(buf != NULL, "malloc");
    for (;;) {
        if (n == cap) {
            uint8_t *bigger = realloc(buf, cap *= 2);
            check(bigger != NULL, "realloc");
            buf = bigger;
        }
        size_t got = fread(buf + n, 1, cap - n, f);
        if (got == 0) break;
        n += got;
    }
    fclose(f);
    *len = n;
    return buf;
}

static int run_decode(int argc, char **argv) {
    for (int i = 0; i < argc; i++) {
        size_t n;
        uint8_t *buf = argv[i][0] == '@' ? read_file(argv[i] + 1, &n) : unhex(argv[i], &n);
        long size = wxsky_mp_object_size(buf, n);
        printf("{\"size\":%ld,\"value\":", size);
        if (size > 0) {
            wxsky_mp_reader r;
            wxsky_mp_reader_init(&r, buf, (size_t)size);
            check(put_json(stdout, &r) == 0 && r.p == r.end, "a validated object reads whole");
        } else {
            printf("null");
        }
        printf("}\n");
        free(buf);
    }
    return 0;
}

/* ---------------------------------------------------------------------------------------
 * mp-selftest
 * ------------------------------------------------------------------------------------- */

static int failures = 0;

static void expect(int cond, const char *what, long detail) {
    if (!cond) {
        fprintf(stderr, "mp-selftest: %s (%ld)\n", what, detail);
        failures++;
    }
}

/* Every proper prefix needs more bytes; the whole is its size; extra bytes are not looked at. */
static void check_prefixes(const uint8_t *buf, size_t n, const char *what) {
    for (size_t p = 0; p < n; p++) expect(wxsky_mp_object_size(buf, p) == 0, what, (long)p);
    expect(wxsky_mp_object_size(buf, n) == (long)n, what, (long)n);
}

static void test_int(int64_t v, size_t want_len, uint8_t want_first) {
    uint8_t buf[16];
    wxsky_mp_writer w;
    wxsky_mp_writer_init(&w, buf, sizeof buf);
    wxsky_mp_write_int(&w, v);
    expect(!w.overflow && w.len == want_len && buf[0] == want_first, "int encoding", (long)v);
    check_prefixes(buf, w.len, "int prefix");
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, buf, w.len);
    int64_t back = 0;
    expect(wxsky_mp_peek(&r) == WXSKY_MP_INT, "int peek", (long)v);
    expect(wxsky_mp_read_int(&r, &back) == 0 && back == v && r.p == r.end, "int back", (long)v);
    wxsky_mp_reader_init(&r, buf, w.len);
    uint64_t u = 0;
    int st = wxsky_mp_read_uint(&r, &u);
    expect(v < 0 ? st == WXSKY_EFORMAT && r.error : st == 0 && u == (uint64_t)v, "int as uint",
           (long)v);
    wxsky_mp_reader_init(&r, buf, w.len);
    double d = 0;
    expect(wxsky_mp_read_double(&r, &d) == 0 && d == (double)v, "int as double", (long)v);
    /* one byte short: overflow, nothing written */
    wxsky_mp_writer_init(&w, buf, want_len - 1);
    wxsky_mp_write_int(&w, v);
    expect(w.overflow && w.len == 0, "int overflow", (long)v);
}

static void test_uint(uint64_t v, size_t want_len, uint8_t want_first) {
    uint8_t buf[16];
    wxsky_mp_writer w;
    wxsky_mp_writer_init(&w, buf, sizeof buf);
    wxsky_mp_write_uint(&w, v);
    expect(!w.overflow && w.len == want_len && buf[0] == want_first, "uint encoding", (long)v);
    check_prefixes(buf, w.len, "uint prefix");
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, buf, w.len);
    uint64_t back = 0;
    expect(wxsky_mp_peek(&r) == (v > (uint64_t)INT64_MAX ? WXSKY_MP_UINT : WXSKY_MP_INT),
           "uint peek", (long)v);
    expect(wxsky_mp_read_uint(&r, &back) == 0 && back == v, "uint back", (long)v);
    wxsky_mp_reader_init(&r, buf, w.len);
    int64_t i = 0;
    int st = wxsky_mp_read_int(&r, &i);
    expect(v > (uint64_t)INT64_MAX ? st != 0 : st == 0 && (uint64_t)i == v, "uint as int",
           (long)v);
}

static void test_sized(int kind, size_t n, size_t want_hdr, uint8_t want_first) {
    size_t cap = n + 16;
    uint8_t *data = malloc(n + 1), *buf = malloc(cap);
    check(data && buf, "malloc");
    memset(data, 'x', n);
    wxsky_mp_writer w;
    wxsky_mp_writer_init(&w, buf, cap);
    if (kind == 's') wxsky_mp_write_str(&w, (const char *)data, n);
    else wxsky_mp_write_bin(&w, data, n);
    expect(!w.overflow && w.len == n + want_hdr && buf[0] == want_first, "str/bin encoding",
           (long)n);
    if (n <= 300) check_prefixes(buf, w.len, "str/bin prefix");
    else expect(wxsky_mp_object_size(buf, w.len - 1) == 0 &&
                wxsky_mp_object_size(buf, w.len) == (long)w.len, "str/bin size", (long)n);
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, buf, w.len);
    const uint8_t *p = NULL;
    uint32_t len = 0;
    int st = kind == 's' ? wxsky_mp_read_str(&r, (const char **)&p, &len)
                         : wxsky_mp_read_bin(&r, &p, &len);
    expect(st == 0 && len == n && (n == 0 || memcmp(p, data, n) == 0) && r.p == r.end,
           "str/bin back", (long)n);
    /* truncated payload: refused by the reader, never read past the end */
    wxsky_mp_reader_init(&r, buf, w.len - 1);
    if (n > 0) expect(wxsky_mp_skip(&r) != 0 && r.error, "truncated str/bin", (long)n);
    wxsky_mp_writer_init(&w, buf, n + want_hdr - 1);
    if (kind == 's') wxsky_mp_write_str(&w, (const char *)data, n);
    else wxsky_mp_write_bin(&w, data, n);
    expect(w.overflow && w.len == 0, "str/bin overflow", (long)n);
    free(data);
    free(buf);
}

static void test_container(int map, uint32_t n, size_t want_hdr, uint8_t want_first) {
    size_t cap = (size_t)n * 3 + 16;
    uint8_t *buf = malloc(cap);
    check(buf != NULL, "malloc");
    wxsky_mp_writer w;
    wxsky_mp_writer_init(&w, buf, cap);
    if (map) wxsky_mp_write_map(&w, n);
    else wxsky_mp_write_array(&w, n);
    expect(w.len == want_hdr && buf[0] == want_first, "container header", (long)n);
    for (uint32_t i = 0; i < n; i++) {
        if (map) wxsky_mp_write_str(&w, "k", 1);
        wxsky_mp_write_nil(&w);
    }
    expect(!w.overflow, "container fits", (long)n);
    expect(wxsky_mp_object_size(buf, w.len) == (long)w.len, "container size", (long)n);
    expect(wxsky_mp_object_size(buf, w.len - 1) == 0 || w.len == want_hdr, "container part",
           (long)n);
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, buf, w.len);
    uint32_t count = 0;
    int st = map ? wxsky_mp_read_map(&r, &count) : wxsky_mp_read_array(&r, &count);
    expect(st == 0 && count == n, "container back", (long)n);
    wxsky_mp_reader_init(&r, buf, w.len);
    expect(wxsky_mp_skip(&r) == 0 && r.p == r.end, "container skip", (long)n);
    free(buf);
}

static void test_double(double v) {
    uint8_t buf[9];
    wxsky_mp_writer w;
    wxsky_mp_writer_init(&w, buf, sizeof buf);
    wxsky_mp_write_double(&w, v);
    expect(w.len == 9 && buf[0] == 0xcb, "double encoding", 0);
    check_prefixes(buf, 9, "double prefix");
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, buf, 9);
    double back;
    expect(wxsky_mp_peek(&r) == WXSKY_MP_FLOAT && wxsky_mp_read_double(&r, &back) == 0 &&
           memcmp(&back, &v, sizeof v) == 0, "double back", 0);
}

static void refused(const uint8_t *buf, size_t n, const char *what) {
    expect(wxsky_mp_object_size(buf, n) < 0, what, (long)n);
}

static void nested(size_t depth, int ok_expected) {
    uint8_t buf[256];
    for (size_t i = 0; i < depth; i++) buf[i] = 0x91;
    buf[depth] = 0xc0;
    long got = wxsky_mp_object_size(buf, depth + 1);
    expect(ok_expected ? got == (long)depth + 1 : got < 0, "nesting", (long)depth);
    /* an empty container as the innermost level counts as a level too */
    buf[depth - 1] = 0x90;
    got = wxsky_mp_object_size(buf, depth);
    expect(ok_expected ? got == (long)depth : got < 0, "nesting (empty innermost)", (long)depth);
}

static int run_selftest(void) {
    static const struct { int64_t v; size_t len; uint8_t first; } ints[] = {
        {0, 1, 0x00}, {1, 1, 0x01}, {127, 1, 0x7f}, {128, 2, 0xcc}, {255, 2, 0xcc},
        {256, 3, 0xcd}, {65535, 3, 0xcd}, {65536, 5, 0xce}, {4294967295LL, 5, 0xce},
        {4294967296LL, 9, 0xcf}, {INT64_MAX, 9, 0xcf}, {-1, 1, 0xff}, {-32, 1, 0xe0},
        {-33, 2, 0xd0}, {-128, 2, 0xd0}, {-129, 3, 0xd1}, {-32768, 3, 0xd1},
        {-32769, 5, 0xd2}, {INT32_MIN, 5, 0xd2}, {(int64_t)INT32_MIN - 1, 9, 0xd3},
        {INT64_MIN, 9, 0xd3},
    };
    for (size_t i = 0; i < sizeof ints / sizeof ints[0]; i++)
        test_int(ints[i].v, ints[i].len, ints[i].first);
    test_uint((uint64_t)INT64_MAX + 1, 9, 0xcf);
    test_uint(UINT64_MAX, 9, 0xcf);
    test_uint(4294967295u, 5, 0xce);

    test_sized('s', 0, 1, 0xa0);
    test_sized('s', 31, 1, 0xbf);
    test_sized('s', 32, 2, 0xd9);
    test_sized('s', 255, 2, 0xd9);
    test_sized('s', 256, 3, 0xda);
    test_sized('s', 65535, 3, 0xda);
    test_sized('s', 65536, 5, 0xdb);
    test_sized('b', 0, 2, 0xc4);
    test_sized('b', 255, 2, 0xc4);
    test_sized('b', 256, 3, 0xc5);
    test_sized('b', 65535, 3, 0xc5);
    test_sized('b', 65536, 5, 0xc6);
    for (int map = 0; map < 2; map++) {
        test_container(map, 0, 1, map ? 0x80 : 0x90);
        test_container(map, 15, 1, map ? 0x8f : 0x9f);
        test_container(map, 16, 3, map ? 0xde : 0xdc);
        test_container(map, 65535, 3, map ? 0xde : 0xdc);
        test_container(map, 65536, 5, map ? 0xdf : 0xdd);
    }
    double doubles[] = {0.0, -0.0, 1.5, -2.25e-300, 1e300, NAN, INFINITY, -INFINITY, 5e-324};
    for (size_t i = 0; i < sizeof doubles / sizeof doubles[0]; i++) test_double(doubles[i]);

    /* nil, bools, float32 */
    {
        static const uint8_t b[] = {0x94, 0xc0, 0xc2, 0xc3, 0xca, 0x3f, 0xc0, 0x00, 0x00};
        check_prefixes(b, sizeof b, "scalars prefix");
        wxsky_mp_reader r;
        wxsky_mp_reader_init(&r, b, sizeof b);
        uint32_t n;
        int f = -1, t = -1;
        double d = 0;
        expect(wxsky_mp_read_array(&r, &n) == 0 && n == 4 && wxsky_mp_read_nil(&r) == 0 &&
               wxsky_mp_read_bool(&r, &f) == 0 && f == 0 && wxsky_mp_read_bool(&r, &t) == 0 &&
               t == 1 && wxsky_mp_peek(&r) == WXSKY_MP_FLOAT &&
               wxsky_mp_read_double(&r, &d) == 0 && d == 1.5 && r.p == r.end &&
               wxsky_mp_peek(&r) == WXSKY_MP_NONE, "scalars", 0);
    }
    /* a whole message, and the protocol's own example (§2.2) */
    {
        static const uint8_t ex[] = {0x94, 0x00, 0x01, 0xa6, 's', 't', 'a', 't', 'u', 's', 0x80};
        uint8_t buf[64];
        wxsky_mp_writer w;
        wxsky_mp_writer_init(&w, buf, sizeof buf);
        wxsky_mp_write_array(&w, 4);
        wxsky_mp_write_uint(&w, 0);
        wxsky_mp_write_uint(&w, 1);
        wxsky_mp_write_cstr(&w, "status");
        wxsky_mp_write_map(&w, 0);
        expect(w.len == sizeof ex && memcmp(buf, ex, sizeof ex) == 0, "§2.2 example", 0);
        check_prefixes(ex, sizeof ex, "example prefix");
    }
    /* find_key, and the sticky error */
    {
        static const uint8_t m[] = {0x83, 0xa1, 'a', 0x01, 0xa1, 'b', 0x92, 0x01, 0x02,
                                    0xa1, 'c', 0xa1, 'x', 0xc0};
        wxsky_mp_reader r;
        uint32_t n;
        const char *s;
        uint32_t len;
        wxsky_mp_reader_init(&r, m, sizeof m);
        expect(wxsky_mp_read_map(&r, &n) == 0 && n == 3 && wxsky_mp_find_key(&r, n, "c") == 0 &&
               wxsky_mp_read_str(&r, &s, &len) == 0 && len == 1 && s[0] == 'x', "find_key", 0);
        wxsky_mp_reader_init(&r, m, sizeof m);
        wxsky_mp_read_map(&r, &n);
        expect(wxsky_mp_find_key(&r, n, "z") == WXSKY_AGAIN && r.p == m + sizeof m - 1 &&
               wxsky_mp_read_nil(&r) == 0, "find_key absent", 0);
        wxsky_mp_reader_init(&r, m, sizeof m);
        int64_t i;
        expect(wxsky_mp_read_str(&r, &s, &len) == WXSKY_EFORMAT && r.p == m &&
               wxsky_mp_read_map(&r, &n) == WXSKY_EFORMAT && wxsky_mp_read_int(&r, &i) != 0 &&
               wxsky_mp_peek(&r) == WXSKY_MP_NONE, "sticky error", 0);
        static const uint8_t intkey[] = {0x81, 0x01, 0x02};
        wxsky_mp_reader_init(&r, intkey, sizeof intkey);
        wxsky_mp_read_map(&r, &n);
        expect(wxsky_mp_find_key(&r, n, "a") == WXSKY_EFORMAT, "find_key int key", 0);
    }
    /* refusals */
    {
        static const uint8_t c1[] = {0xc1};
        refused(c1, 1, "0xc1");
        static const uint8_t exts[][3] = {{0xc7, 0x00, 0x01}, {0xc8, 0x00, 0x00}, {0xc9, 0, 0},
                                          {0xd4, 0x01, 0x00}, {0xd5, 0, 0}, {0xd6, 0, 0},
                                          {0xd7, 0, 0}, {0xd8, 0, 0}};
        for (size_t i = 0; i < sizeof exts / sizeof exts[0]; i++) refused(exts[i], 3, "ext");
        static const uint8_t in_array[] = {0x92, 0x01, 0xd6, 0xff, 0, 0, 0, 0};
        refused(in_array, sizeof in_array, "timestamp in an array");
        static const uint8_t intkey[] = {0x81, 0x01, 0x01};
        refused(intkey, sizeof intkey, "int key");
        static const uint8_t binkey[] = {0x81, 0xc4, 0x01, 'a', 0x01};
        refused(binkey, sizeof binkey, "bin key");
        static const uint8_t nilkey[] = {0x92, 0x80, 0x81, 0xc0, 0x01};
        refused(nilkey, sizeof nilkey, "nil key in a nested map");
        static const uint8_t arrkey[] = {0x81, 0x90, 0x01};
        refused(arrkey, sizeof arrkey, "array key");
        static const uint8_t big_str[] = {0xdb, 0x00, 0x90, 0x00, 0x00};
        refused(big_str, sizeof big_str, "9 MiB str header");
        static const uint8_t big_bin[] = {0xc6, 0x00, 0x80, 0x00, 0x00};
        refused(big_bin, sizeof big_bin, "8 MiB bin + header");
        static const uint8_t big_array[] = {0xdd, 0x00, 0x90, 0x00, 0x00};
        refused(big_array, sizeof big_array, "9M-element array header");
        static const uint8_t big_map[] = {0xdf, 0x00, 0x48, 0x00, 0x00};
        refused(big_map, sizeof big_map, "4.5M-pair map header (9M items)");
        static const uint8_t fit_bin[] = {0xc6, 0x00, 0x7f, 0xff, 0xfb};
        expect(wxsky_mp_object_size(fit_bin, sizeof fit_bin) == 0, "8 MiB exactly: wait", 0);
        static const uint8_t bad_utf8[][5] = {
            {0xa2, 0xff, 0xfe}, {0xa2, 0xc0, 0x80}, {0xa3, 0xed, 0xa0, 0x80},
            {0xa4, 0xf4, 0x90, 0x80, 0x80}, {0xa1, 0x80}, {0xa2, 0xc3, 0x28},
            {0xa3, 0xe0, 0x80, 0xaf}, {0xa1, 0xc3}};
        static const size_t bad_len[] = {3, 3, 4, 5, 2, 3, 4, 2};
        for (size_t i = 0; i < 8; i++) refused(bad_utf8[i], bad_len[i], "invalid UTF-8");
        static const uint8_t good_utf8[] = {0xa9, 0xc3, 0xa9, 0xe2, 0x82, 0xac, 0xf0, 0x9f, 0x98,
                                            0x80};
        expect(wxsky_mp_object_size(good_utf8, sizeof good_utf8) == (long)sizeof good_utf8,
               "valid UTF-8", 0);
        nested(64, 1);
        nested(65, 0);
        nested(100, 0);
    }
    /* the reader stays inside its buffer whatever a header claims */
    {
        static const uint8_t lies[][5] = {{0xdb, 0xff, 0xff, 0xff, 0xff}, {0xdd, 0xff, 0xff, 0xff, 0xff},
                                          {0xdf, 0xff, 0xff, 0xff, 0xff}, {0xcf, 0x00, 0x00, 0, 0}};
        for (size_t i = 0; i < 4; i++) {
            wxsky_mp_reader r;
            wxsky_mp_reader_init(&r, lies[i], 5);
            expect(wxsky_mp_peek(&r) == WXSKY_MP_NONE && wxsky_mp_skip(&r) != 0, "lying header",
                   (long)i);
        }
    }
    /* writer: sticky overflow */
    {
        uint8_t buf[4];
        wxsky_mp_writer w;
        wxsky_mp_writer_init(&w, buf, sizeof buf);
        wxsky_mp_write_cstr(&w, "abcd");
        wxsky_mp_write_nil(&w);
        expect(w.overflow && w.len == 0, "sticky overflow", (long)w.len);
    }
    printf("{\"selftest\":\"%s\",\"failures\":%d}\n", failures ? "failed" : "ok", failures);
    return failures ? 3 : 0;
}

/* ---------------------------------------------------------------------------------------
 * mp-fuzz
 * ------------------------------------------------------------------------------------- */

static void fuzz_walk(FILE *sink, const uint8_t *data, size_t n) {
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, data, n);
    while (wxsky_mp_peek(&r) != WXSKY_MP_NONE)
        if (put_json(sink, &r) != 0) break;
    wxsky_mp_reader_init(&r, data, n);
    while (wxsky_mp_skip(&r) == 0) {
    }
    wxsky_mp_reader_init(&r, data, n);
    uint32_t count;
    if (wxsky_mp_peek(&r) == WXSKY_MP_MAP && wxsky_mp_read_map(&r, &count) == 0)
        (void)wxsky_mp_find_key(&r, count, "topics");
    wxsky_mp_reader_init(&r, data, n);
    const char *s;
    const uint8_t *b;
    uint32_t len;
    int64_t i;
    uint64_t u;
    double d;
    int bl;
    /* every typed read on every kind of byte */
    (void)(wxsky_mp_read_str(&r, &s, &len) + wxsky_mp_read_bin(&r, &b, &len) +
           wxsky_mp_read_int(&r, &i) + wxsky_mp_read_uint(&r, &u) +
           wxsky_mp_read_double(&r, &d) + wxsky_mp_read_bool(&r, &bl) + wxsky_mp_read_nil(&r));
    /* the radar answer's decoder: a picture it accepts has every pixel in the body */
    wxsky_radar radar;
    if (wxsky_radar_decode(data, n, &radar) == WXSKY_OK && !radar.pending) {
        unsigned sum = 0;
        for (uint64_t k = 0; k < (uint64_t)radar.size_px * radar.size_px; k++)
            sum += radar.pixels[k];
        fprintf(sink, "%u\n", sum);
    }
}

static void fuzz_prefixes(const uint8_t *data, size_t n) {
    long whole = wxsky_mp_object_size(data, n);
    size_t step = n <= 160 ? 1 : n / 97 + 1;
    for (size_t p = 0; p <= n; p += step) {
        long part = wxsky_mp_object_size(data, p);
        if (whole > 0 && (size_t)whole <= p) check(part == whole, "a prefix holding the object");
        else if (whole > 0) check(part == 0, "a proper prefix of an object needs more");
        if (part < 0) check(whole < 0, "refused prefix of accepted bytes");
        if (part > 0) check(whole == part, "object size depends on later bytes");
    }
}

typedef struct fuzz_counts {
    long messages, statuses[16];
} fuzz_counts;

static void fuzz_client(wxsky_client *c, int listener, const char *address, FILE *sink,
                        const uint8_t *data, size_t n, fuzz_counts *counts) {
    int st = wxsky_client_connect(c, address);
    check(st == WXSKY_OK, "fuzz: connect");
    int srv = accept(listener, NULL, NULL);
    check(srv >= 0, "fuzz: accept");
    size_t sent = 0;
    int64_t deadline = now_ms() + 10000;
    for (;;) {
        if (srv >= 0 && sent < n) {
            ssize_t w = send(srv, data + sent, n - sent, MSG_DONTWAIT | MSG_NOSIGNAL);
            if (w > 0) sent += (size_t)w;
            else if (w < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR) sent = n;
        }
        if (srv >= 0 && sent >= n) {
            close(srv);
            srv = -1;
        }
        wxsky_message m;
        st = wxsky_client_poll(c, &m);
        if (st == WXSKY_OK) {
            counts->messages++;
            wxsky_mp_reader r;
            wxsky_mp_reader_init(&r, m.body, m.body_len);
            check(put_json(sink, &r) == 0 && r.p == r.end, "fuzz: a message body reads whole");
            continue;
        }
        if (st == WXSKY_AGAIN) {
            check(now_ms() < deadline, "fuzz: the client ends every stream");
            struct pollfd p = {wxsky_client_fd(c), POLLIN, 0};
            (void)poll(&p, 1, srv >= 0 ? 1 : 100);
            continue;
        }
        counts->statuses[-st < 16 ? -st : 0]++;
        check(st == WXSKY_ECLOSED || st == WXSKY_EFORMAT || st == WXSKY_ENOSPC,
              "fuzz: a stream ends in ECLOSED, EFORMAT or ENOSPC");
        check(wxsky_client_fd(c) == -1, "fuzz: the client closed");
        break;
    }
    if (srv >= 0) close(srv);
}

static int run_fuzz(const char *path, const char *sock_path) {
    size_t len;
    uint8_t *file = read_file(path, &len);
    FILE *sink = fopen("/dev/null", "w");
    check(sink != NULL, "/dev/null");
    long inputs = 0, complete = 0, need_more = 0, refused_n = 0;
    fuzz_counts counts;
    memset(&counts, 0, sizeof counts);
    int listener = -1;
    char address[WXSKY_ADDRESS_MAX];
    wxsky_client *small = NULL, *large = NULL;
    if (sock_path != NULL) {
        struct sockaddr_un sun;
        memset(&sun, 0, sizeof sun);
        sun.sun_family = AF_UNIX;
        check(strlen(sock_path) < sizeof sun.sun_path, "socket path length");
        strcpy(sun.sun_path, sock_path);
        unlink(sock_path);
        listener = socket(AF_UNIX, SOCK_STREAM, 0);
        check(listener >= 0 && bind(listener, (struct sockaddr *)&sun, sizeof sun) == 0 &&
              listen(listener, 4) == 0, "fuzz: listen");
        snprintf(address, sizeof address, "unix:%s", sock_path);
        small = wxsky_client_new(1024, 2);
        large = wxsky_client_new(0, 0);
        check(small && large, "wxsky_client_new");
    }
    size_t off = 0;
    while (off + 4 <= len) {
        size_t n = (size_t)file[off] | (size_t)file[off + 1] << 8 | (size_t)file[off + 2] << 16 |
                   (size_t)file[off + 3] << 24;
        off += 4;
        check(n <= len - off, "fuzz file records");
        /* a private copy, exactly n bytes, so ASan sees any read past the end */
        uint8_t *data = malloc(n ? n : 1);
        check(data != NULL, "malloc");
        memcpy(data, file + off, n);
        off += n;
        inputs++;
        long size = wxsky_mp_object_size(data, n);
        if (size > 0) complete++;
        else if (size == 0) need_more++;
        else refused_n++;
        fuzz_prefixes(data, n);
        fuzz_walk(sink, data, n);
        if (listener >= 0)
            fuzz_client(inputs % 2 ? large : small, listener, address, sink, data, n, &counts);
        free(data);
    }
    printf("{\"inputs\":%ld,\"complete\":%ld,\"need_more\":%ld,\"refused\":%ld,"
           "\"messages\":%ld,\"eclosed\":%ld,\"eformat\":%ld,\"enospc\":%ld}\n",
           inputs, complete, need_more, refused_n, counts.messages,
           counts.statuses[-WXSKY_ECLOSED], counts.statuses[-WXSKY_EFORMAT],
           counts.statuses[-WXSKY_ENOSPC]);
    wxsky_client_free(small);
    wxsky_client_free(large);
    if (listener >= 0) {
        close(listener);
        unlink(sock_path);
    }
    fclose(sink);
    free(file);
    return 0;
}

int main(int argc, char **argv) {
    setvbuf(stdout, NULL, _IOLBF, 0);
    if (argc < 2) die_usage("wxsky_client_check COMMAND ...");
    const char *cmd = argv[1];
    if (strcmp(cmd, "session") == 0) return run_session(argc - 2, argv + 2);
    if (strcmp(cmd, "mp-encode") == 0) return run_encode(argc - 2, argv + 2);
    if (strcmp(cmd, "mp-decode") == 0) return run_decode(argc - 2, argv + 2);
    if (strcmp(cmd, "mp-selftest") == 0) return run_selftest();
    if (strcmp(cmd, "mp-fuzz") == 0 && argc >= 3) return run_fuzz(argv[2], argc > 3 ? argv[3] : NULL);
    die_usage("wxsky_client_check session|mp-encode|mp-decode|mp-selftest|mp-fuzz ...");
    return 2;
}
