/* Zero-copy textures (protocol §6): export_textures, its answer and the descriptors that come
 * with it (client.c receives them with the bytes; wxsky_client_call_fds hands them over). */
#include "internal.h"

#include <stdio.h>
#include <string.h>
#include <unistd.h>

void wxsky_textures_init(wxsky_textures *t) {
    if (t == NULL) return;
    memset(t, 0, sizeof *t);
    for (size_t i = 0; i < WXSKY_TEXTURE_FDS_MAX; i++) t->fds[i] = -1;
}

void wxsky_textures_close(wxsky_textures *t) {
    if (t == NULL) return;
    for (uint32_t i = 0; i < t->fd_count && i < WXSKY_TEXTURE_FDS_MAX; i++)
        if (t->fds[i] >= 0) close(t->fds[i]);
    wxsky_textures_init(t);
}

static int key_is(const char *k, uint32_t n, const char *want) {
    return strlen(want) == n && memcmp(k, want, n) == 0;
}

static int read_u32(wxsky_mp_reader *r, uint32_t *out) {
    uint64_t v;
    if (wxsky_mp_read_uint(r, &v) != WXSKY_OK || v > 0xffffffffu) return WXSKY_EFORMAT;
    *out = (uint32_t)v;
    return WXSKY_OK;
}

/* One plane {fd, stride, offset}; fd is an index into the message's descriptors. */
static int parse_plane(wxsky_mp_reader *r, wxsky_texture_plane *p, const wxsky_textures *t,
                       const char **why) {
    uint32_t n, index = 0xffffffffu;
    int have = 0;
    if (wxsky_mp_read_map(r, &n) != WXSKY_OK) return *why = "a plane is not a map", WXSKY_EFORMAT;
    for (uint32_t i = 0; i < n; i++) {
        const char *k;
        uint32_t kn;
        if (wxsky_mp_read_str(r, &k, &kn) != WXSKY_OK) return WXSKY_EFORMAT;
        int st = WXSKY_OK;
        if (key_is(k, kn, "fd")) st = read_u32(r, &index), have |= 1;
        else if (key_is(k, kn, "stride")) st = read_u32(r, &p->stride), have |= 2;
        else if (key_is(k, kn, "offset")) st = read_u32(r, &p->offset), have |= 4;
        else st = wxsky_mp_skip(r);
        if (st != WXSKY_OK) return *why = "a plane field is not an unsigned 32-bit integer", st;
    }
    if (have != 7) return *why = "a plane lacks fd, stride or offset", WXSKY_EFORMAT;
    if (index >= t->fd_count) return *why = "a plane's fd index is beyond fd_count", WXSKY_EFORMAT;
    p->fd = t->fds[index];
    return WXSKY_OK;
}

static int parse_texture(wxsky_mp_reader *r, wxsky_texture *tex, const wxsky_textures *t,
                         const char **why) {
    uint32_t n;
    int have = 0;
    if (wxsky_mp_read_map(r, &n) != WXSKY_OK) return *why = "a texture is not a map", WXSKY_EFORMAT;
    for (uint32_t i = 0; i < n; i++) {
        const char *k, *s;
        uint32_t kn, sn, planes;
        int st = WXSKY_OK;
        if (wxsky_mp_read_str(r, &k, &kn) != WXSKY_OK) return WXSKY_EFORMAT;
        if (key_is(k, kn, "layer")) {
            if (wxsky_mp_read_str(r, &s, &sn) != WXSKY_OK || sn == 0 || sn > WXSKY_LAYER_NAME_MAX)
                return *why = "a texture's layer is not a name of 1..16 bytes", WXSKY_EFORMAT;
            memcpy(tex->layer, s, sn);
            tex->layer[sn] = '\0';
            have |= 1;
        } else if (key_is(k, kn, "slot")) {
            st = read_u32(r, &tex->slot), have |= 2;
        } else if (key_is(k, kn, "width")) {
            st = read_u32(r, &tex->width), have |= 4;
        } else if (key_is(k, kn, "height")) {
            st = read_u32(r, &tex->height), have |= 8;
        } else if (key_is(k, kn, "fourcc")) {
            st = read_u32(r, &tex->fourcc), have |= 16;
        } else if (key_is(k, kn, "modifier")) {
            st = wxsky_mp_read_uint(r, &tex->modifier), have |= 32;
        } else if (key_is(k, kn, "planes")) {
            if (wxsky_mp_read_array(r, &planes) != WXSKY_OK || planes == 0 ||
                planes > WXSKY_TEXTURE_PLANES)
                return *why = "a texture's planes are not an array of 1..4", WXSKY_EFORMAT;
            tex->plane_count = planes;
            for (uint32_t p = 0; p < planes; p++)
                if ((st = parse_plane(r, &tex->planes[p], t, why)) != WXSKY_OK) return st;
            have |= 64;
        } else {
            st = wxsky_mp_skip(r);
        }
        if (st != WXSKY_OK) return *why = "a texture field has the wrong type", st;
    }
    if (have != 127)
        return *why = "a texture lacks layer, slot, width, height, fourcc, modifier or planes",
               WXSKY_EFORMAT;
    if (tex->slot > 1 || tex->width == 0 || tex->height == 0)
        return *why = "a texture's slot is not 0 or 1, or its size is 0", WXSKY_EFORMAT;
    return WXSKY_OK;
}

/* The answer's map (after the descriptors were taken). */
static int parse_answer(wxsky_mp_reader *r, wxsky_textures *t, int *have_fd_count,
                        uint32_t *announced, const char **why) {
    uint32_t n;
    const uint8_t *textures_at = NULL;
    wxsky_mp_reader tr;
    int have_supported = 0;
    if (wxsky_mp_read_map(r, &n) != WXSKY_OK) return *why = "the answer is not a map", WXSKY_EFORMAT;
    for (uint32_t i = 0; i < n; i++) {
        const char *k, *s;
        uint32_t kn, sn;
        int st = WXSKY_OK;
        if (wxsky_mp_read_str(r, &k, &kn) != WXSKY_OK) return WXSKY_EFORMAT;
        if (key_is(k, kn, "supported")) {
            st = wxsky_mp_read_bool(r, &t->supported), have_supported = 1;
        } else if (key_is(k, kn, "reason") && wxsky_mp_peek(r) == WXSKY_MP_STR) {
            wxsky_mp_read_str(r, &s, &sn);
            snprintf(t->reason, sizeof t->reason, "%.*s", (int)(sn < 255 ? sn : 255), s);
        } else if (key_is(k, kn, "slot_count")) {
            st = read_u32(r, &t->slot_count);
        } else if (key_is(k, kn, "fd_count")) {
            st = read_u32(r, announced), *have_fd_count = 1;
        } else if (key_is(k, kn, "textures")) {
            textures_at = r->p; /* parsed below, once the descriptors are known */
            st = wxsky_mp_skip(r);
        } else {
            st = wxsky_mp_skip(r);
        }
        if (st != WXSKY_OK) return *why = "a field of the answer has the wrong type", st;
    }
    if (!have_supported) return *why = "the answer has no 'supported'", WXSKY_EFORMAT;
    if (!t->supported) return WXSKY_OK;
    if (!*have_fd_count || textures_at == NULL)
        return *why = "a supported answer lacks fd_count or textures", WXSKY_EFORMAT;
    if (*announced != t->fd_count) return WXSKY_ESYS; /* the caller says how many came */
    wxsky_mp_reader_init(&tr, textures_at, (size_t)(r->end - textures_at));
    if (wxsky_mp_read_array(&tr, &n) != WXSKY_OK)
        return *why = "textures is not an array", WXSKY_EFORMAT;
    if (n > WXSKY_TEXTURES_MAX) return *why = "more textures than WXSKY_TEXTURES_MAX", WXSKY_ENOSPC;
    for (uint32_t i = 0; i < n; i++) {
        int st = parse_texture(&tr, &t->textures[i], t, why);
        if (st != WXSKY_OK) return st;
    }
    t->count = n;
    return WXSKY_OK;
}

int wxsky_request_textures(wxsky_client *c, int timeout_ms, wxsky_textures *out) {
    wxsky_message m;
    size_t got = 0;
    int fds[WXSKY_TEXTURE_FDS_MAX];
    if (c == NULL) return WXSKY_EINVAL;
    if (out == NULL) return wxsky_client_fail(c, WXSKY_EINVAL, "export_textures: out NULL");
    wxsky_textures_close(out);
    int st = wxsky_client_call_fds(c, "export_textures", NULL, 0, timeout_ms, &m, fds,
                                   WXSKY_TEXTURE_FDS_MAX, &got);
    if (st != WXSKY_OK) return st;
    for (size_t i = 0; i < got; i++) out->fds[i] = fds[i];
    out->fd_count = (uint32_t)got;
    wxsky_mp_reader r;
    wxsky_mp_reader_init(&r, m.body, m.body_len);
    const char *why = "";
    int have_fd_count = 0;
    uint32_t announced = 0;
    st = parse_answer(&r, out, &have_fd_count, &announced, &why);
    if (st == WXSKY_OK && !out->supported) {
        char reason[WXSKY_ERROR_MAX];
        memcpy(reason, out->reason, sizeof reason);
        wxsky_textures_close(out); /* a fallback answer brings none; close any stray ones */
        memcpy(out->reason, reason, sizeof reason);
        return st;
    }
    if (st == WXSKY_ESYS) {
        uint32_t came = out->fd_count;
        wxsky_textures_close(out);
        return wxsky_client_fail(c, WXSKY_ESYS,
                                 "export_textures: the answer announces %u file descriptors, "
                                 "%u came with it (%llu lost on arrival)",
                                 announced, came,
                                 (unsigned long long)wxsky_client_fds_lost(c));
    }
    if (st != WXSKY_OK) {
        wxsky_textures_close(out);
        return wxsky_client_fail(c, st, "export_textures: %s", why);
    }
    return st;
}
