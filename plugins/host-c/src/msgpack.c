/*
 * The MessagePack subset of the control channel (protocol §2.2): a validator that finds where
 * one complete object ends, a bounds-checked reader and a writer into a caller's buffer.
 *
 * Why our own and not msgpack-c: the control channel needs a few dozen lines of msgpack, and
 * what it needs differs from a general library's defaults. Here nothing allocates (msgpack-c's
 * unpacker allocates zones per object; this reader gives pointers into the receive buffer, so
 * the per-frame path of a simulator allocates nothing); the accepted bytes are exactly the
 * protocol's subset (extension types and the never-used 0xc1 refused, map keys str only, str
 * valid UTF-8, containers nested at most 64 deep, one message at most 8 MiB), checked before a
 * single value is read, so a hostile or broken peer can neither crash the host nor make it
 * read out of bounds; and a simulator that links the kit carries no further dependency or
 * version constraint (msgpack-c changed its C API and package names between releases).
 */
#include "internal.h"
#include "msgpack_scan.h"

#include <string.h>

/* ---------------------------------------------------------------------------------------
 * Byte helpers
 * ------------------------------------------------------------------------------------- */

static uint64_t be_load(const uint8_t *p, size_t n) {
    uint64_t v = 0;
    for (size_t i = 0; i < n; i++) v = (v << 8) | p[i];
    return v;
}

static void be_store(uint8_t *p, uint64_t v, size_t n) {
    for (size_t i = 0; i < n; i++) p[n - 1 - i] = (uint8_t)(v >> (8 * i));
}

/* One msgpack header: what the byte at the start of an item says. */
typedef enum hkind {
    H_BAD = 0, /* 0xc1 */
    H_EXT,     /* an extension type: not the protocol's */
    H_NIL,
    H_BOOL,
    H_UINT,
    H_INT, /* a signed encoding (the value may still be >= 0) */
    H_F32,
    H_F64,
    H_STR,
    H_BIN,
    H_ARRAY,
    H_MAP
} hkind;

typedef struct header {
    hkind kind;
    size_t hlen;   /* bytes of the header, the type byte included */
    uint64_t arg;  /* STR/BIN: payload bytes; ARRAY/MAP: count; UINT: value; BOOL: 0/1 */
    int64_t sarg;  /* INT: value */
} header;

/* The header's shape from its first byte: kind, total header length, and for the fixed
 * forms the argument. Returns the bytes of the header still to be loaded (the length field). */
static size_t header_shape(uint8_t b, header *h) {
    h->arg = 0;
    h->sarg = 0;
    h->hlen = 1;
    if (b <= 0x7f) { h->kind = H_UINT; h->arg = b; return 0; }
    if (b >= 0xe0) { h->kind = H_INT; h->sarg = (int8_t)b; return 0; }
    if (b <= 0x8f) { h->kind = H_MAP; h->arg = b & 0x0f; return 0; }
    if (b <= 0x9f) { h->kind = H_ARRAY; h->arg = b & 0x0f; return 0; }
    if (b <= 0xbf) { h->kind = H_STR; h->arg = b & 0x1f; return 0; }
    switch (b) {
    case 0xc0: h->kind = H_NIL; return 0;
    case 0xc1: h->kind = H_BAD; return 0;
    case 0xc2: case 0xc3: h->kind = H_BOOL; h->arg = b & 1; return 0;
    case 0xc4: h->kind = H_BIN; return 1;
    case 0xc5: h->kind = H_BIN; return 2;
    case 0xc6: h->kind = H_BIN; return 4;
    case 0xca: h->kind = H_F32; return 4;
    case 0xcb: h->kind = H_F64; return 8;
    case 0xcc: h->kind = H_UINT; return 1;
    case 0xcd: h->kind = H_UINT; return 2;
    case 0xce: h->kind = H_UINT; return 4;
    case 0xcf: h->kind = H_UINT; return 8;
    case 0xd0: h->kind = H_INT; return 1;
    case 0xd1: h->kind = H_INT; return 2;
    case 0xd2: h->kind = H_INT; return 4;
    case 0xd3: h->kind = H_INT; return 8;
    case 0xd9: h->kind = H_STR; return 1;
    case 0xda: h->kind = H_STR; return 2;
    case 0xdb: h->kind = H_STR; return 4;
    case 0xdc: h->kind = H_ARRAY; return 2;
    case 0xdd: h->kind = H_ARRAY; return 4;
    case 0xde: h->kind = H_MAP; return 2;
    case 0xdf: h->kind = H_MAP; return 4;
    default: h->kind = H_EXT; return 0; /* 0xc7-0xc9, 0xd4-0xd8 */
    }
}

/* Decodes the header at p (avail bytes there). 1: complete, 0: needs more bytes. The payload of
 * a STR/BIN is not checked here. */
static int header_read(const uint8_t *p, size_t avail, header *h) {
    if (avail < 1) return 0;
    size_t extra = header_shape(p[0], h);
    if (avail < 1 + extra) return 0;
    h->hlen = 1 + extra;
    if (extra == 0) return 1;
    uint64_t v = be_load(p + 1, extra);
    switch (h->kind) {
    case H_INT:
        switch (extra) {
        case 1: h->sarg = (int8_t)(uint8_t)v; break;
        case 2: h->sarg = (int16_t)(uint16_t)v; break;
        case 4: h->sarg = (int32_t)(uint32_t)v; break;
        default: memcpy(&h->sarg, &v, sizeof v); break; /* two's complement, as C99 int64_t */
        }
        break;
    case H_F32: case H_F64: h->arg = v; break; /* the bits */
    default: h->arg = v; break;
    }
    return 1;
}

/* RFC 3629 UTF-8 (what Python's strict "utf-8" codec accepts: no overlongs, no surrogates,
 * nothing above U+10FFFF). */
static int utf8_valid(const uint8_t *s, size_t n) {
    size_t i = 0;
    while (i < n) {
        uint8_t c = s[i];
        if (c < 0x80) { i++; continue; }
        size_t more;
        uint8_t lo = 0x80, hi = 0xbf;
        if (c >= 0xc2 && c <= 0xdf) more = 1;
        else if (c == 0xe0) { more = 2; lo = 0xa0; }
        else if (c >= 0xe1 && c <= 0xec) more = 2;
        else if (c == 0xed) { more = 2; hi = 0x9f; }
        else if (c >= 0xee && c <= 0xef) more = 2;
        else if (c == 0xf0) { more = 3; lo = 0x90; }
        else if (c >= 0xf1 && c <= 0xf3) more = 3;
        else if (c == 0xf4) { more = 3; hi = 0x8f; }
        else return 0;
        if (n - i - 1 < more) return 0;
        if (s[i + 1] < lo || s[i + 1] > hi) return 0;
        for (size_t k = 2; k <= more; k++)
            if (s[i + k] < 0x80 || s[i + k] > 0xbf) return 0;
        i += 1 + more;
    }
    return 1;
}

/* ---------------------------------------------------------------------------------------
 * Validation: where one complete object ends (resumable)
 * ------------------------------------------------------------------------------------- */

void wxsky_mp_scan_init(wxsky_mp_scan *s, size_t limit) {
    s->pos = 0;
    s->depth = 0;
    s->owed = 1; /* the object itself */
    s->limit = limit;
    s->why = NULL;
}

static long scan_fail(wxsky_mp_scan *s, const char *why) {
    s->why = why;
    return WXSKY_EFORMAT;
}

long wxsky_mp_scan_run(wxsky_mp_scan *s, const uint8_t *buf, size_t len) {
    if (s->why != NULL) return WXSKY_EFORMAT;
    if (s->owed == 0) return (long)s->pos;
    for (;;) {
        /* Every item not yet started needs at least one byte. */
        if ((uint64_t)s->pos + s->owed > s->limit)
            return scan_fail(s, "message larger than the protocol's limit");
        if (s->pos >= len) return 0;
        header h;
        if (!header_read(buf + s->pos, len - s->pos, &h)) return 0;
        int is_key = s->depth > 0 && s->map[s->depth - 1] && s->left[s->depth - 1] % 2 == 0;
        switch (h.kind) {
        case H_BAD: return scan_fail(s, "byte 0xc1 is not a msgpack type");
        case H_EXT: return scan_fail(s, "msgpack extension types are not part of the protocol");
        default: break;
        }
        if (is_key && h.kind != H_STR) return scan_fail(s, "a map key that is not a string");
        uint64_t size = h.hlen;
        if (h.kind == H_STR || h.kind == H_BIN) size += h.arg;
        uint64_t owed_after = s->owed - 1;
        uint64_t children = 0;
        if (h.kind == H_ARRAY || h.kind == H_MAP) {
            if (s->depth >= WXSKY_MP_MAX_DEPTH)
                return scan_fail(s, "containers nested deeper than 64");
            children = h.kind == H_MAP ? 2 * h.arg : h.arg;
            owed_after += children;
        }
        if ((uint64_t)s->pos + size + owed_after > s->limit)
            return scan_fail(s, "message larger than the protocol's limit");
        if (size > len - s->pos) return 0; /* the payload is still on its way */
        if (h.kind == H_STR && !utf8_valid(buf + s->pos + h.hlen, (size_t)h.arg))
            return scan_fail(s, "a string that is not valid UTF-8");
        /* The item is complete (or, for a container, its header): commit. */
        if (s->depth > 0) s->left[s->depth - 1]--;
        s->pos += (size_t)size;
        s->owed = owed_after;
        if (children > 0) {
            s->left[s->depth] = children;
            s->map[s->depth] = h.kind == H_MAP;
            s->depth++;
            continue;
        }
        while (s->depth > 0 && s->left[s->depth - 1] == 0) s->depth--;
        if (s->depth == 0) return (long)s->pos;
    }
}

long wxsky_mp_object_size(const uint8_t *buf, size_t len) {
    if (buf == NULL && len > 0) return WXSKY_EINVAL;
    wxsky_mp_scan s;
    wxsky_mp_scan_init(&s, WXSKY_MAX_MESSAGE);
    return wxsky_mp_scan_run(&s, buf, len);
}

/* ---------------------------------------------------------------------------------------
 * Reader
 * ------------------------------------------------------------------------------------- */

void wxsky_mp_reader_init(wxsky_mp_reader *r, const uint8_t *buf, size_t len) {
    r->p = buf;
    r->end = buf == NULL ? NULL : buf + len;
    r->error = 0;
}

static int r_fail(wxsky_mp_reader *r) {
    r->error = WXSKY_EFORMAT;
    return WXSKY_EFORMAT;
}

/* The header at the reader's position, its payload bounds-checked. 1 or 0 (error/end). */
static int r_header(const wxsky_mp_reader *r, header *h) {
    if (r->error || r->p == NULL || r->p >= r->end) return 0;
    size_t avail = (size_t)(r->end - r->p);
    if (!header_read(r->p, avail, h)) return 0;
    if (h->kind == H_BAD || h->kind == H_EXT) return 0;
    if ((h->kind == H_STR || h->kind == H_BIN) && h->arg > avail - h->hlen) return 0;
    /* Every element needs a byte: a count beyond the bytes left cannot be honest. */
    if (h->kind == H_ARRAY && h->arg > avail - h->hlen) return 0;
    if (h->kind == H_MAP && 2 * h->arg > avail - h->hlen) return 0;
    return 1;
}

wxsky_mp_type wxsky_mp_peek(const wxsky_mp_reader *r) {
    header h;
    if (!r_header(r, &h)) return WXSKY_MP_NONE;
    switch (h.kind) {
    case H_NIL: return WXSKY_MP_NIL;
    case H_BOOL: return WXSKY_MP_BOOL;
    case H_UINT: return h.arg > (uint64_t)INT64_MAX ? WXSKY_MP_UINT : WXSKY_MP_INT;
    case H_INT: return WXSKY_MP_INT;
    case H_F32: case H_F64: return WXSKY_MP_FLOAT;
    case H_STR: return WXSKY_MP_STR;
    case H_BIN: return WXSKY_MP_BIN;
    case H_ARRAY: return WXSKY_MP_ARRAY;
    case H_MAP: return WXSKY_MP_MAP;
    default: return WXSKY_MP_NONE;
    }
}

int wxsky_mp_read_nil(wxsky_mp_reader *r) {
    header h;
    if (!r_header(r, &h) || h.kind != H_NIL) return r_fail(r);
    r->p += h.hlen;
    return WXSKY_OK;
}

int wxsky_mp_read_bool(wxsky_mp_reader *r, int *out) {
    header h;
    if (!r_header(r, &h) || h.kind != H_BOOL) return r_fail(r);
    r->p += h.hlen;
    if (out) *out = (int)h.arg;
    return WXSKY_OK;
}

int wxsky_mp_read_int(wxsky_mp_reader *r, int64_t *out) {
    header h;
    if (!r_header(r, &h)) return r_fail(r);
    int64_t v;
    if (h.kind == H_INT) v = h.sarg;
    else if (h.kind == H_UINT && h.arg <= (uint64_t)INT64_MAX) v = (int64_t)h.arg;
    else return r_fail(r);
    r->p += h.hlen;
    if (out) *out = v;
    return WXSKY_OK;
}

int wxsky_mp_read_uint(wxsky_mp_reader *r, uint64_t *out) {
    header h;
    if (!r_header(r, &h)) return r_fail(r);
    uint64_t v;
    if (h.kind == H_UINT) v = h.arg;
    else if (h.kind == H_INT && h.sarg >= 0) v = (uint64_t)h.sarg;
    else return r_fail(r);
    r->p += h.hlen;
    if (out) *out = v;
    return WXSKY_OK;
}

int wxsky_mp_read_double(wxsky_mp_reader *r, double *out) {
    header h;
    if (!r_header(r, &h)) return r_fail(r);
    double v;
    switch (h.kind) {
    case H_F32: {
        uint32_t bits = (uint32_t)h.arg;
        float f;
        memcpy(&f, &bits, sizeof f);
        v = f;
        break;
    }
    case H_F64: memcpy(&v, &h.arg, sizeof v); break;
    case H_UINT: v = (double)h.arg; break;
    case H_INT: v = (double)h.sarg; break;
    default: return r_fail(r);
    }
    r->p += h.hlen;
    if (out) *out = v;
    return WXSKY_OK;
}

static int read_bytes(wxsky_mp_reader *r, hkind kind, const uint8_t **out, uint32_t *len) {
    header h;
    if (!r_header(r, &h) || h.kind != kind) return r_fail(r);
    if (out) *out = r->p + h.hlen;
    if (len) *len = (uint32_t)h.arg;
    r->p += h.hlen + (size_t)h.arg;
    return WXSKY_OK;
}

int wxsky_mp_read_str(wxsky_mp_reader *r, const char **out, uint32_t *len) {
    const uint8_t *p = NULL;
    int st = read_bytes(r, H_STR, &p, len);
    if (st == WXSKY_OK && out) *out = (const char *)p;
    return st;
}

int wxsky_mp_read_bin(wxsky_mp_reader *r, const uint8_t **out, uint32_t *len) {
    return read_bytes(r, H_BIN, out, len);
}

int wxsky_mp_read_array(wxsky_mp_reader *r, uint32_t *count) {
    header h;
    if (!r_header(r, &h) || h.kind != H_ARRAY) return r_fail(r);
    r->p += h.hlen;
    if (count) *count = (uint32_t)h.arg;
    return WXSKY_OK;
}

int wxsky_mp_read_map(wxsky_mp_reader *r, uint32_t *count) {
    header h;
    if (!r_header(r, &h) || h.kind != H_MAP) return r_fail(r);
    r->p += h.hlen;
    if (count) *count = (uint32_t)h.arg;
    return WXSKY_OK;
}

int wxsky_mp_skip(wxsky_mp_reader *r) {
    /* Iterative: the items still to skip, whatever their depth. */
    uint64_t todo = 1;
    while (todo > 0) {
        header h;
        if (!r_header(r, &h)) return r_fail(r);
        r->p += h.hlen;
        if (h.kind == H_STR || h.kind == H_BIN) r->p += (size_t)h.arg;
        todo--;
        if (h.kind == H_ARRAY) todo += h.arg;
        else if (h.kind == H_MAP) todo += 2 * h.arg;
        if (todo > (uint64_t)(r->end - r->p)) return r_fail(r);
    }
    return WXSKY_OK;
}

int wxsky_mp_find_key(wxsky_mp_reader *r, uint32_t count, const char *key) {
    if (key == NULL) return r_fail(r);
    size_t want = strlen(key);
    for (uint32_t i = 0; i < count; i++) {
        const char *k;
        uint32_t klen;
        if (wxsky_mp_read_str(r, &k, &klen) != WXSKY_OK) return WXSKY_EFORMAT;
        if (klen == want && memcmp(k, key, want) == 0) return WXSKY_OK;
        if (wxsky_mp_skip(r) != WXSKY_OK) return WXSKY_EFORMAT;
    }
    return r->error ? WXSKY_EFORMAT : WXSKY_AGAIN;
}

/* ---------------------------------------------------------------------------------------
 * Writer
 * ------------------------------------------------------------------------------------- */

void wxsky_mp_writer_init(wxsky_mp_writer *w, uint8_t *buf, size_t cap) {
    w->buf = buf;
    w->cap = buf == NULL ? 0 : cap;
    w->len = 0;
    w->overflow = 0;
}

/* Room for n more bytes, or NULL (and overflow set): a write is all or nothing. */
static uint8_t *w_reserve(wxsky_mp_writer *w, size_t n) {
    if (w->overflow || n > w->cap - w->len) {
        w->overflow = 1;
        return NULL;
    }
    uint8_t *p = w->buf + w->len;
    w->len += n;
    return p;
}

/* A type byte followed by an n-byte big-endian argument. */
static void w_head(wxsky_mp_writer *w, uint8_t type, uint64_t arg, size_t n, size_t payload) {
    if (w->overflow || payload > w->cap - w->len || 1 + n > w->cap - w->len - payload) {
        w->overflow = 1;
        return;
    }
    uint8_t *p = w->buf + w->len; /* room checked above */
    w->len += 1 + n;
    p[0] = type;
    be_store(p + 1, arg, n);
}

void wxsky_mp_write_nil(wxsky_mp_writer *w) { w_head(w, 0xc0, 0, 0, 0); }

void wxsky_mp_write_bool(wxsky_mp_writer *w, int v) { w_head(w, v ? 0xc3 : 0xc2, 0, 0, 0); }

void wxsky_mp_write_uint(wxsky_mp_writer *w, uint64_t v) {
    if (v <= 0x7f) w_head(w, (uint8_t)v, 0, 0, 0);
    else if (v <= 0xff) w_head(w, 0xcc, v, 1, 0);
    else if (v <= 0xffff) w_head(w, 0xcd, v, 2, 0);
    else if (v <= 0xffffffffu) w_head(w, 0xce, v, 4, 0);
    else w_head(w, 0xcf, v, 8, 0);
}

void wxsky_mp_write_int(wxsky_mp_writer *w, int64_t v) {
    if (v >= 0) {
        wxsky_mp_write_uint(w, (uint64_t)v);
        return;
    }
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    if (v >= -32) w_head(w, (uint8_t)(bits & 0xff), 0, 0, 0);
    else if (v >= INT8_MIN) w_head(w, 0xd0, bits, 1, 0);
    else if (v >= INT16_MIN) w_head(w, 0xd1, bits, 2, 0);
    else if (v >= INT32_MIN) w_head(w, 0xd2, bits, 4, 0);
    else w_head(w, 0xd3, bits, 8, 0);
}

void wxsky_mp_write_double(wxsky_mp_writer *w, double v) {
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits);
    w_head(w, 0xcb, bits, 8, 0);
}

static void write_sized(wxsky_mp_writer *w, const uint8_t types[3], uint8_t fix, size_t fixmax,
                        const void *data, size_t len) {
    if (data == NULL && len > 0) {
        w->overflow = 1;
        return;
    }
    if (len <= fixmax) w_head(w, (uint8_t)(fix | len), 0, 0, len);
    else if (len <= 0xff) w_head(w, types[0], len, 1, len);
    else if (len <= 0xffff) w_head(w, types[1], len, 2, len);
    else if ((uint64_t)len <= 0xffffffffu) w_head(w, types[2], len, 4, len);
    else w->overflow = 1;
    if (w->overflow) return;
    if (len > 0) memcpy(w_reserve(w, len), data, len); /* room checked by w_head */
}

void wxsky_mp_write_str(wxsky_mp_writer *w, const char *s, size_t len) {
    static const uint8_t types[3] = {0xd9, 0xda, 0xdb};
    write_sized(w, types, 0xa0, 31, s, len);
}

void wxsky_mp_write_cstr(wxsky_mp_writer *w, const char *s) {
    if (s == NULL) {
        w->overflow = 1;
        return;
    }
    wxsky_mp_write_str(w, s, strlen(s));
}

void wxsky_mp_write_bin(wxsky_mp_writer *w, const uint8_t *data, size_t len) {
    /* bin has no fix form: the smallest is bin8. */
    if (data == NULL && len > 0) {
        w->overflow = 1;
        return;
    }
    if (len <= 0xff) w_head(w, 0xc4, len, 1, len);
    else if (len <= 0xffff) w_head(w, 0xc5, len, 2, len);
    else if ((uint64_t)len <= 0xffffffffu) w_head(w, 0xc6, len, 4, len);
    else w->overflow = 1;
    if (w->overflow) return;
    if (len > 0) memcpy(w_reserve(w, len), data, len);
}

void wxsky_mp_write_array(wxsky_mp_writer *w, uint32_t count) {
    if (count <= 15) w_head(w, (uint8_t)(0x90 | count), 0, 0, 0);
    else if (count <= 0xffff) w_head(w, 0xdc, count, 2, 0);
    else w_head(w, 0xdd, count, 4, 0);
}

void wxsky_mp_write_map(wxsky_mp_writer *w, uint32_t count) {
    if (count <= 15) w_head(w, (uint8_t)(0x80 | count), 0, 0, 0);
    else if (count <= 0xffff) w_head(w, 0xde, count, 2, 0);
    else w_head(w, 0xdf, count, 4, 0);
}

void wxsky_mp_write_raw(wxsky_mp_writer *w, const uint8_t *data, size_t len) {
    if (data == NULL && len > 0) {
        w->overflow = 1;
        return;
    }
    uint8_t *p = w_reserve(w, len);
    if (p != NULL && len > 0) memcpy(p, data, len);
}
