/*
 * The control channel's client (protocol §2, §4, §5): addresses, a non-blocking connection,
 * framing of the msgpack stream, requests, and the queue of messages read while waiting.
 *
 * Buffers, all allocated by wxsky_client_new:
 *  - `in`: what read() brought, [in_start, in_end). A message is handed out as pointers into
 *    it and in_start moves past it; the bytes are moved to the front only when room is needed
 *    for a read, at the start of the next poll/wait, when no message is lent any more.
 *    `scan` is the resumable validator of the message at in_start, so a message that arrives
 *    in many reads is checked once.
 *  - `out`: encoded requests not yet taken by the socket, [out_start, out_end).
 *  - `q` + `qe`: copies of the messages read while waiting for a response, a FIFO ring of
 *    contiguous entries (an entry never wraps, so it can be handed out as one span). The
 *    entry handed out last stays in place, marked taken, until the next poll/wait.
 *  - `fds`: file descriptors that came with the bytes (SCM_RIGHTS, protocol §6: only the
 *    export_textures response carries any), each with the stream range [start, end) of the
 *    recvmsg that brought it. The message they belong to begins inside that range (the
 *    daemon attaches them to the response's first byte; Linux may glue earlier bytes in
 *    front of it in one read, never a second message with descriptors), so a response that
 *    begins at stream position p claims the ones with start <= p < end. Any not claimed once
 *    every byte of their read is consumed are closed at the next poll/wait.
 */
#include "internal.h"
#include "msgpack_scan.h"

#include <arpa/inet.h>
#include <errno.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <pwd.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

#define READ_ROOM 65536u        /* compact the receive buffer when less than this is free */
#define CONNECT_TIMEOUT_MS 2000
#define SUN_PATH_MAX 107        /* §2.1: sockaddr_un.sun_path is 108 bytes with the NUL */
#define FDS_MAX 256             /* descriptors held for messages not yet handed out */
#define RECV_FDS 253            /* Linux SCM_MAX_FD: the most one message carries */
#ifndef MSG_CMSG_CLOEXEC
#define MSG_CMSG_CLOEXEC 0 /* then FD_CLOEXEC is set on each one received */
#endif

typedef struct qentry {
    size_t off;
    size_t len;
    int taken; /* handed out (or matched by a wait): freed once it reaches the head */
} qentry;

struct wxsky_client {
    int fd;
    char error[WXSKY_ERROR_MAX];
    char address[WXSKY_ADDRESS_MAX]; /* the address connected to, as given (or the default) */
    int have_address;
    uint32_t next_msgid;
    uint64_t received; /* complete messages on this connection, for "message N" */
    uint64_t dropped;
    /* the renewed subscribe a reconnect sent, whose response the client swallows */
    int resubscribe_pending;
    uint32_t resubscribe_msgid;
    /* a send failed: the daemon stopped reading (its last words may still be readable) */
    int write_closed;

    uint8_t *in;
    size_t in_cap, in_start, in_end;
    wxsky_mp_scan scan;

    uint8_t *out;
    size_t out_cap, out_start, out_end;

    uint8_t *q;
    size_t q_cap;
    qentry *qe;
    size_t qe_max, qe_head, qe_count;

    char topics[WXSKY_SUBSCRIPTION_MAX]; /* NUL-terminated names back to back */
    size_t topics_len;

    /* stream positions: of in[0], and of the message wait_until returned last (from the
     * stream, not the queue: from_stream) */
    uint64_t in_pos;
    uint64_t last_pos;
    int last_from_stream;
    /* received descriptors, oldest first, each with its read's stream range */
    int fds[FDS_MAX];
    uint64_t fd_start[FDS_MAX], fd_end[FDS_MAX];
    size_t fd_count;
    uint64_t fds_lost; /* closed at once: the table was full, or the kernel cut them */
};

/* ---------------------------------------------------------------------------------------
 * Small helpers
 * ------------------------------------------------------------------------------------- */

static int64_t now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

/* Milliseconds left until deadline (-1: none) for poll(2). */
static int remaining_ms(int64_t deadline) {
    if (deadline < 0) return -1;
    int64_t left = deadline - now_ms();
    if (left <= 0) return 0;
    return left > 1000000000 ? 1000000000 : (int)left;
}

#define FAIL(c, status, ...) wxsky_fail((c)->error, sizeof (c)->error, (status), __VA_ARGS__)

static int ok(wxsky_client *c, int status) {
    c->error[0] = '\0';
    return status;
}

static int sys_status(int err) {
    return err == ENOENT || err == ECONNREFUSED ? WXSKY_ENOENT : WXSKY_ESYS;
}

/* ---------------------------------------------------------------------------------------
 * Lifetime
 * ------------------------------------------------------------------------------------- */

wxsky_client *wxsky_client_new(size_t buffer_bytes, size_t queued) {
    if (buffer_bytes == 0) buffer_bytes = (size_t)WXSKY_MAX_MESSAGE + 65536u;
    if (buffer_bytes < 1024) buffer_bytes = 1024;
    if (queued == 0) queued = 64;
    if (queued > buffer_bytes) queued = buffer_bytes; /* every entry holds at least a byte */
    if (queued > SIZE_MAX / sizeof(qentry)) return NULL;
    wxsky_client *c = malloc(sizeof *c);
    if (c == NULL) return NULL;
    memset(c, 0, sizeof *c);
    c->fd = -1;
    c->next_msgid = 1;
    c->in = malloc(buffer_bytes);
    c->out = malloc(buffer_bytes);
    c->q = malloc(buffer_bytes);
    c->qe = malloc(queued * sizeof *c->qe);
    if (c->in == NULL || c->out == NULL || c->q == NULL || c->qe == NULL) {
        wxsky_client_free(c);
        return NULL;
    }
    c->in_cap = c->out_cap = c->q_cap = buffer_bytes;
    c->qe_max = queued;
    wxsky_mp_scan_init(&c->scan, WXSKY_MAX_MESSAGE);
    return c;
}

void wxsky_client_free(wxsky_client *c) {
    if (c == NULL) return;
    wxsky_client_close(c);
    free(c->in);
    free(c->out);
    free(c->q);
    free(c->qe);
    free(c);
}

const char *wxsky_client_error(const wxsky_client *c) {
    return c == NULL ? "no client (NULL)" : c->error;
}

int wxsky_client_fd(const wxsky_client *c) { return c == NULL ? -1 : c->fd; }

uint64_t wxsky_client_dropped(const wxsky_client *c) { return c == NULL ? 0 : c->dropped; }

static void close_fds(wxsky_client *c) {
    for (size_t i = 0; i < c->fd_count; i++) close(c->fds[i]);
    c->fd_count = 0;
}

void wxsky_client_close(wxsky_client *c) {
    if (c == NULL) return;
    if (c->fd >= 0) close(c->fd);
    c->fd = -1;
    close_fds(c);
    c->in_pos = 0;
    c->last_from_stream = 0;
    /* The bytes stay where they are (a message handed out may still point at them) until
     * the next poll or wait; only the bookkeeping starts again. */
    c->in_start = c->in_end = 0;
    c->out_start = c->out_end = 0;
    c->received = 0;
    c->resubscribe_pending = 0;
    c->write_closed = 0;
    wxsky_mp_scan_init(&c->scan, WXSKY_MAX_MESSAGE);
}

/* ---------------------------------------------------------------------------------------
 * Addresses (§2.1)
 * ------------------------------------------------------------------------------------- */

typedef struct target {
    struct sockaddr_storage sa;
    socklen_t len;
} target;

/* "~", "~/rest", "~user", "~user/rest" -> the home directory; other paths as they are. */
static int expand_home(wxsky_client *c, const char *path, char *out, size_t size) {
    if (path[0] != '~') {
        if (strlen(path) >= size) return FAIL(c, WXSKY_EINVAL, "unix socket path too long");
        strcpy(out, path);
        return WXSKY_OK;
    }
    const char *rest = strchr(path, '/');
    if (rest == NULL) rest = path + strlen(path);
    size_t ulen = (size_t)(rest - path - 1);
    char user[256];
    if (ulen >= sizeof user) return FAIL(c, WXSKY_EINVAL, "user name in %.64s too long", path);
    memcpy(user, path + 1, ulen);
    user[ulen] = '\0';
    const char *home = NULL;
    struct passwd pw, *found = NULL;
    char pwbuf[2048];
    if (ulen == 0) home = getenv("HOME");
    if (home == NULL || home[0] == '\0') {
        int err = ulen == 0 ? getpwuid_r(getuid(), &pw, pwbuf, sizeof pwbuf, &found)
                            : getpwnam_r(user, &pw, pwbuf, sizeof pwbuf, &found);
        if (err != 0 || found == NULL)
            return FAIL(c, WXSKY_EINVAL, "cannot expand ~%s in the socket path", user);
        home = pw.pw_dir;
    }
    int n = snprintf(out, size, "%s%s", home, rest);
    if (n < 0 || (size_t)n >= size) return FAIL(c, WXSKY_EINVAL, "unix socket path too long");
    return WXSKY_OK;
}

static int unix_target(wxsky_client *c, const char *address, const char *path, target *t) {
    char full[512];
    if (path[0] == '\0')
        return FAIL(c, WXSKY_EINVAL, "invalid address \"%.100s\": unix: needs a socket path",
                    address);
    int st = expand_home(c, path, full, sizeof full);
    if (st != WXSKY_OK) return st;
    size_t n = strlen(full);
    struct sockaddr_un *sun = (struct sockaddr_un *)&t->sa;
    if (n > SUN_PATH_MAX || n >= sizeof sun->sun_path)
        return FAIL(c, WXSKY_EINVAL,
                    "invalid address \"%.100s\": unix socket paths are limited to %d bytes",
                    address, SUN_PATH_MAX);
    memset(&t->sa, 0, sizeof t->sa);
    sun->sun_family = AF_UNIX;
    memcpy(sun->sun_path, full, n + 1);
    t->len = (socklen_t)(offsetof(struct sockaddr_un, sun_path) + n + 1);
    return WXSKY_OK;
}

static int ascii_ieq(const char *a, const char *b) {
    for (; *a && *b; a++, b++) {
        char x = *a >= 'A' && *a <= 'Z' ? (char)(*a + 32) : *a;
        char y = *b >= 'A' && *b <= 'Z' ? (char)(*b + 32) : *b;
        if (x != y) return 0;
    }
    return *a == *b;
}

/* The loopback targets for "tcp:HOST:PORT" (localhost: 127.0.0.1, then ::1). Nothing here
 * resolves a name or touches the network: any host but a loopback literal or "localhost" is
 * refused outright. */
static int tcp_targets(wxsky_client *c, const char *address, const char *rest, target t[2],
                       int *count) {
    const char *colon = strrchr(rest, ':');
    if (colon == NULL || colon == rest || colon[1] == '\0')
        return FAIL(c, WXSKY_EINVAL, "invalid address \"%.100s\": expected tcp:HOST:PORT",
                    address);
    unsigned long port = 0;
    for (const char *p = colon + 1; *p; p++) {
        if (*p < '0' || *p > '9' || port > 65535)
            return FAIL(c, WXSKY_EINVAL, "invalid address \"%.100s\": expected tcp:HOST:PORT",
                        address);
        port = port * 10 + (unsigned long)(*p - '0');
    }
    if (port > 65535)
        return FAIL(c, WXSKY_EINVAL, "invalid address \"%.100s\": tcp port %lu is outside "
                    "0..65535", address, port);
    if (port == 0)
        return FAIL(c, WXSKY_EINVAL, "invalid address \"%.100s\": a client needs the daemon's "
                    "port, not 0", address);
    char host[128];
    size_t hlen = (size_t)(colon - rest);
    if (hlen >= 2 && rest[0] == '[' && rest[hlen - 1] == ']') {
        rest++;
        hlen -= 2;
    }
    if (hlen >= sizeof host)
        return FAIL(c, WXSKY_EINVAL, "invalid address \"%.100s\": host too long", address);
    memcpy(host, rest, hlen);
    host[hlen] = '\0';

    struct in_addr v4;
    struct in6_addr v6;
    memset(t, 0, 2 * sizeof *t);
    struct sockaddr_in *a4 = (struct sockaddr_in *)&t[0].sa;
    *count = 0;
    if (ascii_ieq(host, "localhost")) {
        a4->sin_family = AF_INET;
        a4->sin_port = htons((uint16_t)port);
        a4->sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        t[0].len = sizeof *a4;
        struct sockaddr_in6 *b6 = (struct sockaddr_in6 *)&t[1].sa;
        b6->sin6_family = AF_INET6;
        b6->sin6_port = htons((uint16_t)port);
        b6->sin6_addr = in6addr_loopback;
        t[1].len = sizeof *b6;
        *count = 2;
        return WXSKY_OK;
    }
    if (inet_pton(AF_INET, host, &v4) == 1) {
        if ((ntohl(v4.s_addr) >> 24) == 127) {
            a4->sin_family = AF_INET;
            a4->sin_port = htons((uint16_t)port);
            a4->sin_addr = v4;
            t[0].len = sizeof *a4;
            *count = 1;
            return WXSKY_OK;
        }
    } else if (inet_pton(AF_INET6, host, &v6) == 1) {
        if (memcmp(&v6, &in6addr_loopback, sizeof v6) == 0) {
            struct sockaddr_in6 *a6 = (struct sockaddr_in6 *)&t[0].sa;
            a6->sin6_family = AF_INET6;
            a6->sin6_port = htons((uint16_t)port);
            a6->sin6_addr = v6;
            t[0].len = sizeof *a6;
            *count = 1;
            return WXSKY_OK;
        }
    }
    return FAIL(c, WXSKY_EINVAL,
                "tcp host \"%.100s\" is not a loopback address: the control channel has no "
                "authentication, so tcp is only allowed on 127.0.0.0/8, localhost or ::1 "
                "(use unix:PATH otherwise)", host);
}

/* §2.1's default: unix:$XDG_RUNTIME_DIR/wxsky/wxsky.sock when that is an absolute path to a
 * directory, else unix:/tmp/wxsky-<uid>/wxsky.sock. The daemon makes the directory (0700); a
 * client only uses one that is a directory owned by this user (in /tmp another user could
 * have made it first, to sit on the socket). */
static int default_address(wxsky_client *c, char *out, size_t size) {
    char dir[WXSKY_ADDRESS_MAX];
    const char *rt = getenv("XDG_RUNTIME_DIR");
    struct stat st;
    int n;
    if (rt != NULL && rt[0] == '/' && stat(rt, &st) == 0 && S_ISDIR(st.st_mode))
        n = snprintf(dir, sizeof dir, "%s/wxsky", rt);
    else
        n = snprintf(dir, sizeof dir, "/tmp/wxsky-%lu", (unsigned long)getuid());
    if (n < 0 || (size_t)n >= sizeof dir)
        return FAIL(c, WXSKY_EINVAL, "XDG_RUNTIME_DIR is too long for a socket path");
    if (lstat(dir, &st) != 0) {
        int err = errno;
        return FAIL(c, sys_status(err), "no wxsky daemon at the default address: %s: %s", dir,
                    strerror(err));
    }
    if (!S_ISDIR(st.st_mode) || st.st_uid != getuid())
        return FAIL(c, WXSKY_EINVAL,
                    "socket directory %s is not a directory owned by this user; not using it",
                    dir);
    n = snprintf(out, size, "unix:%s/wxsky.sock", dir);
    if (n < 0 || (size_t)n >= size)
        return FAIL(c, WXSKY_EINVAL, "XDG_RUNTIME_DIR is too long for a socket path");
    return WXSKY_OK;
}

/* One connection attempt: the socket, or a negative status. */
static int connect_one(wxsky_client *c, const target *t, const char *address, int *fd_out) {
    int family = ((const struct sockaddr *)&t->sa)->sa_family;
    int fd = socket(family, SOCK_STREAM, 0);
    if (fd < 0) {
        int err = errno;
        return FAIL(c, WXSKY_ESYS, "socket() for %s: %s", address, strerror(err));
    }
    int flags = fcntl(fd, F_GETFL);
    if (flags < 0 || fcntl(fd, F_SETFL, flags | O_NONBLOCK) < 0 ||
        fcntl(fd, F_SETFD, FD_CLOEXEC) < 0) {
        int err = errno;
        close(fd);
        return FAIL(c, WXSKY_ESYS, "fcntl() for %s: %s", address, strerror(err));
    }
    int rc;
    do {
        rc = connect(fd, (const struct sockaddr *)&t->sa, t->len);
    } while (rc < 0 && errno == EINTR);
    if (rc < 0 && errno == EINPROGRESS) {
        struct pollfd p = {fd, POLLOUT, 0};
        int64_t deadline = now_ms() + CONNECT_TIMEOUT_MS;
        int n;
        do {
            n = poll(&p, 1, remaining_ms(deadline));
        } while (n < 0 && errno == EINTR);
        if (n == 0) {
            close(fd);
            return FAIL(c, WXSKY_ETIMEDOUT, "cannot connect to the wxsky daemon at %s: no "
                        "answer within %d ms", address, CONNECT_TIMEOUT_MS);
        }
        int err = 0;
        socklen_t elen = sizeof err;
        if (n < 0) err = errno;
        else if (getsockopt(fd, SOL_SOCKET, SO_ERROR, &err, &elen) < 0) err = errno;
        if (err != 0) {
            close(fd);
            return FAIL(c, sys_status(err), "cannot connect to the wxsky daemon at %s: %s",
                        address, strerror(err));
        }
        rc = 0;
    }
    if (rc < 0) {
        int err = errno;
        close(fd);
        if (err == EAGAIN)
            return FAIL(c, WXSKY_ESYS, "cannot connect to the wxsky daemon at %s: its listen "
                        "queue is full", address);
        return FAIL(c, sys_status(err), "cannot connect to the wxsky daemon at %s: %s",
                    address, strerror(err));
    }
    if (family != AF_UNIX) {
        int one = 1;
        (void)setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof one);
    }
    *fd_out = fd;
    return WXSKY_OK;
}

int wxsky_client_connect(wxsky_client *c, const char *address) {
    if (c == NULL) return WXSKY_EINVAL;
    wxsky_client_close(c);
    char text[WXSKY_ADDRESS_MAX];
    if (address == NULL) {
        int st = default_address(c, text, sizeof text);
        if (st != WXSKY_OK) return st;
    } else {
        if (strlen(address) >= sizeof text)
            return FAIL(c, WXSKY_EINVAL, "address longer than %d bytes", WXSKY_ADDRESS_MAX - 1);
        strcpy(text, address);
    }
    target t[2];
    int count = 1, st;
    if (strncmp(text, "unix:", 5) == 0) st = unix_target(c, text, text + 5, &t[0]);
    else if (strncmp(text, "tcp:", 4) == 0) st = tcp_targets(c, text, text + 4, t, &count);
    else st = FAIL(c, WXSKY_EINVAL, "invalid address \"%.100s\": expected unix:PATH or "
                   "tcp:HOST:PORT", text);
    if (st != WXSKY_OK) return st;
    int fd = -1;
    for (int i = 0; i < count; i++) {
        st = connect_one(c, &t[i], text, &fd);
        if (st == WXSKY_OK) break;
    }
    if (st != WXSKY_OK) {
        /* A daemon that is down now may be up later: keep the address for reconnect. */
        strcpy(c->address, text);
        c->have_address = 1;
        return st;
    }
    c->fd = fd;
    strcpy(c->address, text);
    c->have_address = 1;
    return ok(c, WXSKY_OK);
}

/* ---------------------------------------------------------------------------------------
 * Sending
 * ------------------------------------------------------------------------------------- */

/* Writes what `out` holds: OK when empty, AGAIN when the socket is full. */
static int flush_out(wxsky_client *c) {
    while (c->out_start < c->out_end) {
        ssize_t n = send(c->fd, c->out + c->out_start, c->out_end - c->out_start, MSG_NOSIGNAL);
        if (n > 0) {
            c->out_start += (size_t)n;
            continue;
        }
        if (n < 0 && errno == EINTR) continue;
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return WXSKY_AGAIN;
        int err = n < 0 ? errno : EPIPE;
        /* The unsent bytes are lost; what the daemon sent before it went is still read, and
         * the read side then reports the end. */
        c->out_start = c->out_end = 0;
        c->write_closed = 1;
        if (err == EPIPE || err == ECONNRESET)
            return FAIL(c, WXSKY_ECLOSED, "the wxsky daemon at %s closed the connection",
                        c->address);
        return FAIL(c, WXSKY_ESYS, "send() to the wxsky daemon at %s: %s", c->address,
                    strerror(err));
    }
    c->out_start = c->out_end = 0;
    return WXSKY_OK;
}

int wxsky_client_flush(wxsky_client *c) {
    if (c == NULL) return WXSKY_EINVAL;
    if (c->fd < 0) return FAIL(c, WXSKY_ECLOSED, "not connected to the wxsky daemon");
    if (c->write_closed)
        return FAIL(c, WXSKY_ECLOSED, "the wxsky daemon at %s closed the connection",
                    c->address);
    int st = flush_out(c);
    return st < 0 ? st : ok(c, st);
}

/* Starts a request in the free part of `out`: [0, msgid, method, ...params follow. */
static int begin_request(wxsky_client *c, const char *method, wxsky_mp_writer *w) {
    if (method == NULL) return FAIL(c, WXSKY_EINVAL, "no method (NULL)");
    if (c->fd < 0) return FAIL(c, WXSKY_ECLOSED, "not connected to the wxsky daemon");
    if (c->write_closed)
        return FAIL(c, WXSKY_ECLOSED, "the wxsky daemon at %s closed the connection",
                    c->address);
    if (c->out_start == c->out_end) {
        c->out_start = c->out_end = 0;
    } else if (c->out_start > 0) {
        memmove(c->out, c->out + c->out_start, c->out_end - c->out_start);
        c->out_end -= c->out_start;
        c->out_start = 0;
    }
    wxsky_mp_writer_init(w, c->out + c->out_end, c->out_cap - c->out_end);
    wxsky_mp_write_array(w, 4);
    wxsky_mp_write_uint(w, 0);
    wxsky_mp_write_uint(w, c->next_msgid);
    wxsky_mp_write_cstr(w, method);
    return WXSKY_OK;
}

static int finish_request(wxsky_client *c, const wxsky_mp_writer *w, const char *method,
                          uint32_t *msgid) {
    if (w->overflow) {
        if (c->out_end > c->out_start)
            return FAIL(c, WXSKY_AGAIN, "%.64s: earlier requests still wait for the socket",
                        method);
        return FAIL(c, WXSKY_ENOSPC, "%.64s: the request is larger than the send buffer "
                    "(%zu bytes)", method, c->out_cap);
    }
    c->out_end += w->len;
    uint32_t id = c->next_msgid++; /* wraps from 2^32-1 to 0 */
    if (msgid != NULL) *msgid = id;
    int st = flush_out(c);
    return st < 0 ? st : ok(c, WXSKY_OK);  /* AGAIN: the rest goes out later */
}

int wxsky_client_request(wxsky_client *c, const char *method, const uint8_t *params_msgpack,
                         size_t params_len, uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    static const uint8_t empty_map = 0x80;
    if (params_msgpack == NULL) {
        if (params_len != 0) return FAIL(c, WXSKY_EINVAL, "params NULL with a length");
        params_msgpack = &empty_map;
        params_len = 1;
    }
    long size = wxsky_mp_object_size(params_msgpack, params_len);
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, params_msgpack, params_len);
    if (size != (long)params_len || wxsky_mp_peek(&r) != WXSKY_MP_MAP)
        return FAIL(c, WXSKY_EINVAL, "%.64s: params must be exactly one msgpack map (§2.2)",
                    method == NULL ? "request" : method);
    wxsky_mp_writer w;
    int st = begin_request(c, method, &w);
    if (st != WXSKY_OK) return st;
    wxsky_mp_write_raw(&w, params_msgpack, params_len);
    return finish_request(c, &w, method, msgid);
}

/* ---------------------------------------------------------------------------------------
 * Typed requests (§2.4, §5)
 * ------------------------------------------------------------------------------------- */

static int topic_index(const wxsky_client *c, const char *topic, size_t *where) {
    size_t i = 0;
    while (i < c->topics_len) {
        size_t n = strlen(c->topics + i);
        if (strcmp(c->topics + i, topic) == 0) {
            *where = i;
            return 1;
        }
        i += n + 1;
    }
    return 0;
}

static int check_topics(wxsky_client *c, const char *const *topics, size_t count) {
    if (topics == NULL && count > 0) return FAIL(c, WXSKY_EINVAL, "topics NULL");
    if (count > 0xffffffffu) return FAIL(c, WXSKY_EINVAL, "too many topics");
    for (size_t i = 0; i < count; i++)
        if (topics[i] == NULL) return FAIL(c, WXSKY_EINVAL, "topic %zu is NULL", i);
    return WXSKY_OK;
}

static int send_topics(wxsky_client *c, const char *method, const char *const *topics,
                       size_t count, uint32_t *msgid) {
    wxsky_mp_writer w;
    int st = begin_request(c, method, &w);
    if (st != WXSKY_OK) return st;
    wxsky_mp_write_map(&w, 1);
    wxsky_mp_write_cstr(&w, "topics");
    wxsky_mp_write_array(&w, (uint32_t)count);
    for (size_t i = 0; i < count; i++) wxsky_mp_write_cstr(&w, topics[i]);
    return finish_request(c, &w, method, msgid);
}

int wxsky_subscribe(wxsky_client *c, const char *const *topics, size_t count, uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    int st = check_topics(c, topics, count);
    if (st != WXSKY_OK) return st;
    /* Room in the kept set first, so the set and the daemon's never disagree. */
    size_t need = 0, where;
    for (size_t i = 0; i < count; i++) {
        int dup = 0;
        for (size_t k = 0; k < i; k++) dup |= strcmp(topics[k], topics[i]) == 0;
        if (!dup && !topic_index(c, topics[i], &where)) need += strlen(topics[i]) + 1;
    }
    if (c->topics_len + need > sizeof c->topics)
        return FAIL(c, WXSKY_ENOSPC, "subscribe: more than %d bytes of topic names",
                    WXSKY_SUBSCRIPTION_MAX);
    st = send_topics(c, "subscribe", topics, count, msgid);
    if (st != WXSKY_OK) return st;
    for (size_t i = 0; i < count; i++) {
        if (topic_index(c, topics[i], &where)) continue;
        size_t n = strlen(topics[i]) + 1;
        memcpy(c->topics + c->topics_len, topics[i], n);
        c->topics_len += n;
    }
    return WXSKY_OK;
}

int wxsky_unsubscribe(wxsky_client *c, const char *const *topics, size_t count,
                      uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    int st = check_topics(c, topics, count);
    if (st != WXSKY_OK) return st;
    st = send_topics(c, "unsubscribe", topics, count, msgid);
    if (st != WXSKY_OK) return st;
    for (size_t i = 0; i < count; i++) {
        size_t where;
        if (!topic_index(c, topics[i], &where)) continue;
        size_t n = strlen(c->topics + where) + 1;
        memmove(c->topics + where, c->topics + where + n, c->topics_len - where - n);
        c->topics_len -= n;
    }
    return WXSKY_OK;
}

static void write_vec3(wxsky_mp_writer *w, const double v[3]) {
    wxsky_mp_write_array(w, 3);
    for (int i = 0; i < 3; i++) wxsky_mp_write_double(w, v[i]);
}

int wxsky_set_camera(wxsky_client *c, const wxsky_camera *camera, uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    if (camera == NULL) return FAIL(c, WXSKY_EINVAL, "set_camera: camera NULL");
    wxsky_mp_writer w;
    int st = begin_request(c, "set_camera", &w);
    if (st != WXSKY_OK) return st;
    wxsky_mp_write_map(&w, 5u + (camera->width != 0) + (camera->height != 0));
    wxsky_mp_write_cstr(&w, "position_m");
    write_vec3(&w, camera->position_m);
    wxsky_mp_write_cstr(&w, "heading_deg");
    wxsky_mp_write_double(&w, camera->heading_deg);
    wxsky_mp_write_cstr(&w, "pitch_deg");
    wxsky_mp_write_double(&w, camera->pitch_deg);
    wxsky_mp_write_cstr(&w, "roll_deg");
    wxsky_mp_write_double(&w, camera->roll_deg);
    wxsky_mp_write_cstr(&w, "fov_deg");
    wxsky_mp_write_double(&w, camera->fov_deg);
    if (camera->width != 0) {
        wxsky_mp_write_cstr(&w, "width");
        wxsky_mp_write_uint(&w, camera->width);
    }
    if (camera->height != 0) {
        wxsky_mp_write_cstr(&w, "height");
        wxsky_mp_write_uint(&w, camera->height);
    }
    return finish_request(c, &w, "set_camera", msgid);
}

int wxsky_set_aircraft(wxsky_client *c, const double *position_m, uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    wxsky_mp_writer w;
    int st = begin_request(c, "set_aircraft", &w);
    if (st != WXSKY_OK) return st;
    wxsky_mp_write_map(&w, 1);
    wxsky_mp_write_cstr(&w, "position_m");
    if (position_m == NULL) wxsky_mp_write_nil(&w);
    else write_vec3(&w, position_m);
    return finish_request(c, &w, "set_aircraft", msgid);
}

int wxsky_set_time(wxsky_client *c, const char *time_utc, const double *rate, uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    if (time_utc == NULL && rate == NULL)
        return FAIL(c, WXSKY_EINVAL, "set_time: give time_utc and/or rate");
    wxsky_mp_writer w;
    int st = begin_request(c, "set_time", &w);
    if (st != WXSKY_OK) return st;
    wxsky_mp_write_map(&w, (uint32_t)(time_utc != NULL) + (rate != NULL));
    if (time_utc != NULL) {
        wxsky_mp_write_cstr(&w, "time_utc");
        wxsky_mp_write_cstr(&w, time_utc);
    }
    if (rate != NULL) {
        wxsky_mp_write_cstr(&w, "rate");
        wxsky_mp_write_double(&w, *rate);
    }
    return finish_request(c, &w, "set_time", msgid);
}

static int one_string(wxsky_client *c, const char *method, const char *key, const char *value,
                      uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    if (value == NULL) return FAIL(c, WXSKY_EINVAL, "%s: %s NULL", method, key);
    wxsky_mp_writer w;
    int st = begin_request(c, method, &w);
    if (st != WXSKY_OK) return st;
    wxsky_mp_write_map(&w, 1);
    wxsky_mp_write_cstr(&w, key);
    wxsky_mp_write_cstr(&w, value);
    return finish_request(c, &w, method, msgid);
}

int wxsky_apply_preset(wxsky_client *c, const char *name, uint32_t *msgid) {
    return one_string(c, "apply_preset", "name", name, msgid);
}

int wxsky_apply_metar(wxsky_client *c, const char *report, uint32_t *msgid) {
    return one_string(c, "apply_metar", "report", report, msgid);
}

int wxsky_release(wxsky_client *c, const char *source, uint32_t *msgid) {
    return one_string(c, "release", "source", source == NULL ? "control" : source, msgid);
}

int wxsky_request_status(wxsky_client *c, uint32_t *msgid) {
    return wxsky_client_request(c, "status", NULL, 0, msgid);
}

int wxsky_request_radar(wxsky_client *c, double range_nm, double tilt_deg, uint32_t size_px,
                        uint32_t *msgid) {
    if (c == NULL) return WXSKY_EINVAL;
    wxsky_mp_writer w;
    int st = begin_request(c, "radar", &w);
    if (st != WXSKY_OK) return st;
    wxsky_mp_write_map(&w, 3);
    wxsky_mp_write_cstr(&w, "range_nm");
    wxsky_mp_write_double(&w, range_nm);
    wxsky_mp_write_cstr(&w, "tilt_deg");
    wxsky_mp_write_double(&w, tilt_deg);
    wxsky_mp_write_cstr(&w, "size_px");
    wxsky_mp_write_uint(&w, size_px);
    return finish_request(c, &w, "radar", msgid);
}

static int key_is(const char *key, uint32_t len, const char *want) {
    return len == strlen(want) && memcmp(key, want, len) == 0;
}

int wxsky_radar_decode(const uint8_t *body, size_t len, wxsky_radar *out) {
    if (body == NULL || out == NULL) return WXSKY_EINVAL;
    memset(out, 0, sizeof *out);
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, body, len);
    uint32_t count = 0;
    if (wxsky_mp_read_map(&r, &count) != WXSKY_OK) return WXSKY_EFORMAT;
    int seen_pending = 0, seen_size = 0;
    uint32_t pixels_len = 0;
    for (uint32_t i = 0; i < count; i++) {
        const char *key;
        uint32_t key_len;
        if (wxsky_mp_read_str(&r, &key, &key_len) != WXSKY_OK) return WXSKY_EFORMAT;
        int st;
        if (key_is(key, key_len, "pending")) {
            st = wxsky_mp_read_bool(&r, &out->pending);
            seen_pending = 1;
        } else if (key_is(key, key_len, "size_px")) {
            uint64_t v = 0;
            st = wxsky_mp_read_uint(&r, &v);
            if (st == WXSKY_OK && (v == 0 || v > 4096)) return WXSKY_EFORMAT;
            out->size_px = (uint32_t)v;
            seen_size = 1;
        } else if (key_is(key, key_len, "range_nm")) {
            st = wxsky_mp_read_double(&r, &out->range_nm);
        } else if (key_is(key, key_len, "tilt_deg")) {
            st = wxsky_mp_read_double(&r, &out->tilt_deg);
        } else if (key_is(key, key_len, "age_s")) {
            st = wxsky_mp_read_double(&r, &out->age_s);
        } else if (key_is(key, key_len, "dbz_offset")) {
            st = wxsky_mp_read_double(&r, &out->dbz_offset);
        } else if (key_is(key, key_len, "dbz_step")) {
            st = wxsky_mp_read_double(&r, &out->dbz_step);
        } else if (key_is(key, key_len, "centre_m")) {
            uint32_t n = 0;
            st = wxsky_mp_read_array(&r, &n);
            if (st == WXSKY_OK && n != 3) return WXSKY_EFORMAT;
            for (uint32_t k = 0; st == WXSKY_OK && k < 3; k++)
                st = wxsky_mp_read_double(&r, &out->centre_m[k]);
        } else if (key_is(key, key_len, "pixels")) {
            st = wxsky_mp_read_bin(&r, &out->pixels, &pixels_len);
        } else {
            st = wxsky_mp_skip(&r);
        }
        if (st != WXSKY_OK) return WXSKY_EFORMAT;
    }
    if (!seen_pending || !seen_size) return WXSKY_EFORMAT;
    if (out->pending) {
        out->pixels = NULL;
        return WXSKY_OK;
    }
    if (out->pixels == NULL || out->dbz_step <= 0.0 ||
        (uint64_t)pixels_len != (uint64_t)out->size_px * out->size_px)
        return WXSKY_EFORMAT;
    return WXSKY_OK;
}

int wxsky_client_reconnect(wxsky_client *c) {
    if (c == NULL) return WXSKY_EINVAL;
    if (!c->have_address) return FAIL(c, WXSKY_EINVAL, "reconnect: never connected");
    char address[WXSKY_ADDRESS_MAX];
    strcpy(address, c->address);
    int st = wxsky_client_connect(c, address);
    if (st != WXSKY_OK || c->topics_len == 0) return st;
    const char *list[WXSKY_SUBSCRIPTION_MAX]; /* each name takes at least its NUL */
    size_t count = 0;
    for (size_t i = 0; i < c->topics_len; i += strlen(c->topics + i) + 1)
        list[count++] = c->topics + i;
    uint32_t id = 0;
    st = send_topics(c, "subscribe", list, count, &id);
    if (st != WXSKY_OK) return st;
    c->resubscribe_pending = 1;
    c->resubscribe_msgid = id;
    return WXSKY_OK;
}

/* ---------------------------------------------------------------------------------------
 * Receiving
 * ------------------------------------------------------------------------------------- */

enum { DECODED_SKIP = 3 }; /* a request from the daemon: not for the host (§2.4) */

/* Checks one complete, validated object against §2.2's shapes and fills *msg. */
static int decode_message(const uint8_t *buf, size_t len, wxsky_message *msg, const char **why) {
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, buf, len);
    memset(msg, 0, sizeof *msg);
    uint32_t n;
    int64_t kind;
    if (wxsky_mp_peek(&r) != WXSKY_MP_ARRAY) {
        *why = "expected an array [type, ...]";
        return WXSKY_EFORMAT;
    }
    wxsky_mp_read_array(&r, &n);
    if (n == 0 || wxsky_mp_peek(&r) != WXSKY_MP_INT || wxsky_mp_read_int(&r, &kind) != 0 ||
        kind < 0 || kind > 2) {
        *why = "unknown message type (0 request, 1 response, 2 notification)";
        return WXSKY_EFORMAT;
    }
    if (kind == 0) return DECODED_SKIP;
    if (kind == 1) {
        *why = "expected [1, msgid, error, result]";
        if (n != 4) return WXSKY_EFORMAT;
        wxsky_mp_type t = wxsky_mp_peek(&r);
        if (t == WXSKY_MP_NIL) {
            wxsky_mp_read_nil(&r);
        } else {
            uint64_t id;
            if (wxsky_mp_read_uint(&r, &id) != 0 || id > 0xffffffffu) return WXSKY_EFORMAT;
            msg->has_msgid = 1;
            msg->msgid = (uint32_t)id;
        }
        t = wxsky_mp_peek(&r);
        if (t == WXSKY_MP_NIL) {
            wxsky_mp_read_nil(&r);
        } else if (t == WXSKY_MP_STR) {
            wxsky_mp_read_str(&r, &msg->error, &msg->error_len);
        } else {
            return WXSKY_EFORMAT;
        }
        msg->kind = WXSKY_RESPONSE;
    } else {
        *why = "expected [2, method, params]";
        if (n != 3 || wxsky_mp_peek(&r) != WXSKY_MP_STR) return WXSKY_EFORMAT;
        wxsky_mp_read_str(&r, &msg->method, &msg->method_len);
        if (wxsky_mp_peek(&r) != WXSKY_MP_MAP) {
            *why = "expected [2, method, params] with params a map";
            return WXSKY_EFORMAT;
        }
        msg->kind = WXSKY_NOTIFICATION;
    }
    msg->body = r.p;
    if (wxsky_mp_skip(&r) != 0 || r.p != r.end) return WXSKY_EFORMAT;
    msg->body_len = (size_t)(r.p - msg->body);
    return WXSKY_OK;
}

/* The next complete message in `in`: OK (*msg, and *size its bytes, not yet consumed), AGAIN
 * when incomplete, negative (the connection closed) for bytes that are not the protocol. */
static int parse_next(wxsky_client *c, wxsky_message *msg, size_t *size) {
    for (;;) {
        const uint8_t *start = c->in + c->in_start;
        size_t avail = c->in_end - c->in_start;
        long n = wxsky_mp_scan_run(&c->scan, start, avail);
        if (n == 0) return WXSKY_AGAIN;
        uint64_t number = c->received + 1;
        const char *why = c->scan.why;
        int st = WXSKY_EFORMAT;
        if (n > 0) st = decode_message(start, (size_t)n, msg, &why);
        if (st < 0) {
            size_t at = c->scan.pos;
            wxsky_client_close(c);
            if (n < 0)
                return FAIL(c, WXSKY_EFORMAT, "bad data from the wxsky daemon at %s: message "
                            "%llu: %s (at byte %zu); connection closed", c->address,
                            (unsigned long long)number, why, at);
            return FAIL(c, WXSKY_EFORMAT, "bad data from the wxsky daemon at %s: message %llu: "
                        "%s; connection closed", c->address, (unsigned long long)number, why);
        }
        c->received++;
        wxsky_mp_scan_init(&c->scan, WXSKY_MAX_MESSAGE);
        if (st == DECODED_SKIP || (msg->kind == WXSKY_RESPONSE && c->resubscribe_pending &&
                                   msg->has_msgid && msg->msgid == c->resubscribe_msgid)) {
            if (st != DECODED_SKIP) c->resubscribe_pending = 0;
            c->in_start += (size_t)n;
            continue;
        }
        *size = (size_t)n;
        return WXSKY_OK;
    }
}

/* One read() into `in`: OK (bytes came), AGAIN (none now), or negative (closed). */
/* Keeps the descriptors a recvmsg brought, with its stream range. */
static void keep_fds(wxsky_client *c, struct msghdr *mh, uint64_t start, uint64_t end) {
    for (struct cmsghdr *cm = CMSG_FIRSTHDR(mh); cm != NULL; cm = CMSG_NXTHDR(mh, cm)) {
        if (cm->cmsg_level != SOL_SOCKET || cm->cmsg_type != SCM_RIGHTS) continue;
        size_t n = (cm->cmsg_len - CMSG_LEN(0)) / sizeof(int);
        const unsigned char *data = CMSG_DATA(cm);
        for (size_t i = 0; i < n; i++) {
            int fd;
            memcpy(&fd, data + i * sizeof fd, sizeof fd);
            if (MSG_CMSG_CLOEXEC == 0) (void)fcntl(fd, F_SETFD, FD_CLOEXEC);
            if (c->fd_count == FDS_MAX) {
                close(fd);
                c->fds_lost++;
                continue;
            }
            c->fds[c->fd_count] = fd;
            c->fd_start[c->fd_count] = start;
            c->fd_end[c->fd_count] = end;
            c->fd_count++;
        }
    }
    if (mh->msg_flags & MSG_CTRUNC) c->fds_lost++; /* the kernel closed those that did not fit */
}

/* Closes the descriptors whose read is consumed entirely and that nobody claimed. */
static void drop_consumed_fds(wxsky_client *c) {
    uint64_t consumed = c->in_pos + c->in_start;
    size_t k = 0;
    for (size_t i = 0; i < c->fd_count; i++) {
        if (c->fd_end[i] <= consumed) {
            close(c->fds[i]);
            continue;
        }
        c->fds[k] = c->fds[i];
        c->fd_start[k] = c->fd_start[i];
        c->fd_end[k] = c->fd_end[i];
        k++;
    }
    c->fd_count = k;
}

static int fill(wxsky_client *c) {
    if (c->in_start == c->in_end) {
        c->in_pos += c->in_end;
        c->in_start = c->in_end = 0;
    } else if (c->in_start > 0 && c->in_cap - c->in_end < READ_ROOM) {
        memmove(c->in, c->in + c->in_start, c->in_end - c->in_start);
        c->in_pos += c->in_start;
        c->in_end -= c->in_start;
        c->in_start = 0;
    }
    if (c->in_end == c->in_cap) {
        size_t cap = c->in_cap;
        wxsky_client_close(c);
        return FAIL(c, WXSKY_ENOSPC, "a message from the wxsky daemon is larger than the "
                    "receive buffer (%zu bytes); connection closed", cap);
    }
    for (;;) {
        /* recvmsg rather than read: the export_textures response brings descriptors (§6) */
        union {
            struct cmsghdr align;
            unsigned char buf[CMSG_SPACE(sizeof(int) * RECV_FDS)];
        } ctl;
        struct iovec iov = {c->in + c->in_end, c->in_cap - c->in_end};
        struct msghdr mh;
        memset(&mh, 0, sizeof mh);
        mh.msg_iov = &iov;
        mh.msg_iovlen = 1;
        mh.msg_control = ctl.buf;
        mh.msg_controllen = sizeof ctl.buf;
        ssize_t n = recvmsg(c->fd, &mh, MSG_CMSG_CLOEXEC);
        if (n > 0) {
            uint64_t start = c->in_pos + c->in_end;
            if (mh.msg_controllen > 0) keep_fds(c, &mh, start, start + (uint64_t)n);
            c->in_end += (size_t)n;
            return WXSKY_OK;
        }
        if (n < 0 && errno == EINTR) continue;
        if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) return WXSKY_AGAIN;
        int err = n < 0 ? errno : 0;
        int partial = c->in_end > c->in_start;
        wxsky_client_close(c);
        if (err == 0 || err == ECONNRESET)
            return FAIL(c, WXSKY_ECLOSED, "the wxsky daemon at %s closed the connection%s",
                        c->address, partial ? " in the middle of a message" : "");
        return FAIL(c, WXSKY_ESYS, "read() from the wxsky daemon at %s: %s", c->address,
                    strerror(err));
    }
}

/* Frees the entries handed out by the previous poll/wait (they sit at the head by then, or
 * wait there behind entries still to be read). */
static void release_taken(wxsky_client *c) {
    while (c->qe_count > 0 && c->qe[c->qe_head].taken) {
        c->qe_head = (c->qe_head + 1) % c->qe_max;
        c->qe_count--;
    }
}

static void drop_oldest(wxsky_client *c) {
    if (!c->qe[c->qe_head].taken) c->dropped++;
    c->qe_head = (c->qe_head + 1) % c->qe_max;
    c->qe_count--;
}

/* Copies a message into the queue, dropping the oldest entries until it fits. */
static void enqueue(wxsky_client *c, const uint8_t *bytes, size_t len) {
    if (len > c->q_cap) {
        c->dropped++;
        return;
    }
    size_t off = 0;
    for (;;) {
        if (c->qe_count == c->qe_max) {
            drop_oldest(c);
            continue;
        }
        if (c->qe_count == 0) {
            off = 0;
            break;
        }
        const qentry *head = &c->qe[c->qe_head];
        const qentry *tail = &c->qe[(c->qe_head + c->qe_count - 1) % c->qe_max];
        size_t tail_end = tail->off + tail->len;
        if (tail->off >= head->off) { /* live bytes are [head, tail_end) */
            if (c->q_cap - tail_end >= len) { off = tail_end; break; }
            if (head->off >= len) { off = 0; break; }
        } else if (head->off - tail_end >= len) { /* live: [head, ...) and [0, tail_end) */
            off = tail_end;
            break;
        }
        drop_oldest(c);
    }
    memcpy(c->q + off, bytes, len);
    qentry *e = &c->qe[(c->qe_head + c->qe_count) % c->qe_max];
    e->off = off;
    e->len = len;
    e->taken = 0;
    c->qe_count++;
}

/* Hands out queue entry i (an index from the head). */
static void take_entry(wxsky_client *c, size_t i, wxsky_message *msg) {
    qentry *e = &c->qe[(c->qe_head + i) % c->qe_max];
    const char *why = NULL;
    e->taken = 1;
    /* Validated when it arrived: decoding the copy cannot fail. */
    (void)decode_message(c->q + e->off, e->len, msg, &why);
}

int wxsky_client_poll(wxsky_client *c, wxsky_message *msg) {
    if (c == NULL || msg == NULL) return c == NULL ? WXSKY_EINVAL : FAIL(c, WXSKY_EINVAL, "msg NULL");
    release_taken(c);
    drop_consumed_fds(c);
    c->last_from_stream = 0;
    for (size_t i = 0; i < c->qe_count; i++) {
        if (!c->qe[(c->qe_head + i) % c->qe_max].taken) {
            take_entry(c, i, msg);
            return ok(c, WXSKY_OK);
        }
    }
    if (c->fd < 0) return FAIL(c, WXSKY_ECLOSED, "not connected to the wxsky daemon");
    (void)flush_out(c); /* a failure shows on the read side, after the daemon's last words */
    for (;;) {
        size_t size;
        int st = parse_next(c, msg, &size);
        if (st == WXSKY_OK) {
            c->in_start += size;
            return ok(c, WXSKY_OK);
        }
        if (st < 0) return st;
        st = fill(c);
        if (st == WXSKY_AGAIN) return ok(c, WXSKY_AGAIN);
        if (st < 0) return st;
    }
}

static int answer(wxsky_client *c, const wxsky_message *m, wxsky_message *response) {
    if (response != NULL) *response = *m;
    if (m->error == NULL) return ok(c, WXSKY_OK);
    int n = (int)(m->error_len < WXSKY_ERROR_MAX ? m->error_len : WXSKY_ERROR_MAX - 1);
    return FAIL(c, WXSKY_EREMOTE, "%.*s", n, m->error);
}

static int wait_until(wxsky_client *c, uint32_t msgid, int64_t deadline,
                      wxsky_message *response) {
    release_taken(c);
    drop_consumed_fds(c);
    c->last_from_stream = 0;
    /* A response that came during an earlier wait is in the queue already. */
    for (size_t i = 0; i < c->qe_count; i++) {
        const qentry *e = &c->qe[(c->qe_head + i) % c->qe_max];
        if (e->taken) continue;
        wxsky_message m;
        const char *why;
        if (decode_message(c->q + e->off, e->len, &m, &why) == WXSKY_OK &&
            m.kind == WXSKY_RESPONSE && m.has_msgid && m.msgid == msgid) {
            take_entry(c, i, &m);
            return answer(c, &m, response);
        }
    }
    for (;;) {
        if (c->fd < 0) return FAIL(c, WXSKY_ECLOSED, "not connected to the wxsky daemon");
        int want_out = flush_out(c) == WXSKY_AGAIN; /* failures: as in poll */
        for (;;) {
            wxsky_message m;
            size_t size;
            int st = parse_next(c, &m, &size);
            if (st < 0) return st;
            if (st == WXSKY_AGAIN) break;
            if (m.kind == WXSKY_RESPONSE && (!m.has_msgid || m.msgid == msgid)) {
                c->last_pos = c->in_pos + c->in_start;
                c->last_from_stream = 1;
                c->in_start += size;
                if (m.has_msgid) return answer(c, &m, response);
                /* The daemon could not read what we sent and hangs up after saying so. */
                st = answer(c, &m, response);
                wxsky_client_close(c); /* keeps the message */
                return st;
            }
            enqueue(c, c->in + c->in_start, size);
            c->in_start += size;
        }
        int st = fill(c);
        if (st == WXSKY_OK) continue;
        if (st < 0) return st;
        struct pollfd p = {c->fd, (short)(POLLIN | (want_out ? POLLOUT : 0)), 0};
        int n = poll(&p, 1, remaining_ms(deadline));
        if (n < 0 && errno != EINTR) {
            int err = errno;
            return FAIL(c, WXSKY_ESYS, "poll(): %s", strerror(err));
        }
        if (n == 0)
            return FAIL(c, WXSKY_ETIMEDOUT, "no answer to request %lu from the wxsky daemon "
                        "at %s in time", (unsigned long)msgid, c->address);
    }
}

int wxsky_client_wait(wxsky_client *c, uint32_t msgid, int timeout_ms, wxsky_message *response) {
    if (c == NULL) return WXSKY_EINVAL;
    int64_t deadline = timeout_ms < 0 ? -1 : now_ms() + timeout_ms;
    return wait_until(c, msgid, deadline, response);
}

int wxsky_client_call(wxsky_client *c, const char *method, const uint8_t *params_msgpack,
                      size_t params_len, int timeout_ms, wxsky_message *response) {
    if (c == NULL) return WXSKY_EINVAL;
    int64_t deadline = timeout_ms < 0 ? -1 : now_ms() + timeout_ms;
    uint32_t id = 0;
    for (;;) {
        int st = wxsky_client_request(c, method, params_msgpack, params_len, &id);
        if (st == WXSKY_OK) break;
        if (st != WXSKY_AGAIN) return st;
        /* The send buffer is full of earlier requests: wait for the socket to take some. */
        struct pollfd p = {c->fd, POLLOUT, 0};
        int n = poll(&p, 1, remaining_ms(deadline));
        if (n == 0)
            return FAIL(c, WXSKY_ETIMEDOUT, "%.64s: the wxsky daemon at %s does not read its "
                        "requests", method, c->address);
        if (n > 0) (void)flush_out(c);
    }
    return wait_until(c, id, deadline, response);
}

int wxsky_client_call_fds(wxsky_client *c, const char *method, const uint8_t *params_msgpack,
                          size_t params_len, int timeout_ms, wxsky_message *response,
                          int *fds, size_t max_fds, size_t *fd_count) {
    *fd_count = 0;
    int st = wxsky_client_call(c, method, params_msgpack, params_len, timeout_ms, response);
    if (st != WXSKY_OK || !c->last_from_stream) return st;
    size_t k = 0, n = 0;
    for (size_t i = 0; i < c->fd_count; i++) {
        if (c->fd_start[i] <= c->last_pos && c->last_pos < c->fd_end[i] && n < max_fds) {
            fds[n++] = c->fds[i]; /* now the caller's */
            continue;
        }
        c->fds[k] = c->fds[i];
        c->fd_start[k] = c->fd_start[i];
        c->fd_end[k] = c->fd_end[i];
        k++;
    }
    c->fd_count = k;
    *fd_count = n;
    return WXSKY_OK;
}

uint64_t wxsky_client_fds_lost(const wxsky_client *c) { return c == NULL ? 0 : c->fds_lost; }

int wxsky_client_fail(wxsky_client *c, int status, const char *fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(c->error, sizeof c->error, fmt, ap);
    va_end(ap);
    return status;
}
