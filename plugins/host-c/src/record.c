/* The frame record, version 3 or 2 (protocol §3): decoded field by field from little-endian
 * bytes at the offsets of the table, never by casting the buffer to a struct (no alignment or
 * padding assumptions, and the same result on any CPU). Version 3 only appends the shadow
 * fields, so both share one decoder. */
#include "internal.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

static uint32_t get32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static uint64_t get64(const uint8_t *p) {
    return (uint64_t)get32(p) | (uint64_t)get32(p + 4) << 32;
}

typedef struct decoder {
    const uint8_t *meta;
    char *error;
    size_t error_size;
    int status; /* the first failure, WXSKY_OK until then */
} decoder;

/* Reads the f64 at `offset` into *out; a non-finite value fails the decode, naming the field. */
static void f64(decoder *d, size_t offset, double *out, const char *field, int i, int j, int k) {
    uint64_t bits = get64(d->meta + offset);
    double v;
    memcpy(&v, &bits, sizeof v);
    *out = v;
    if (d->status == WXSKY_OK && !isfinite(v)) {
        char name[64];
        if (i < 0) {
            snprintf(name, sizeof name, "%s", field);
        } else if (j < 0) {
            snprintf(name, sizeof name, "%s[%d]", field, i);
        } else {
            snprintf(name, sizeof name, "%s[%d][%d][%d]", field, i, j, k);
        }
        d->status = wxsky_fail(d->error, d->error_size, WXSKY_EFORMAT,
                               "frame record: %s at offset %zu is not finite (%s)", name, offset,
                               isnan(v) ? "nan" : "inf");
    }
}

static void vec3(decoder *d, size_t offset, double out[3], const char *field) {
    for (int i = 0; i < 3; i++) {
        f64(d, offset + 8 * (size_t)i, &out[i], field, i, -1, -1);
    }
}

static void quads(decoder *d, size_t offset, double out[8][4][3], const char *field) {
    for (int i = 0; i < 8; i++) {
        for (int j = 0; j < 4; j++) {
            for (int k = 0; k < 3; k++) {
                f64(d, offset + 8 * (size_t)(12 * i + 3 * j + k), &out[i][j][k], field, i, j, k);
            }
        }
    }
}

static void flag(decoder *d, size_t offset, uint32_t *out, const char *field) {
    *out = get32(d->meta + offset);
    if (d->status == WXSKY_OK && *out > 1) {
        d->status = wxsky_fail(d->error, d->error_size, WXSKY_EFORMAT,
                               "frame record: %s is %u at offset %zu, expected 0 or 1", field,
                               (unsigned)*out, offset);
    }
}

int wxsky_record_decode(const uint8_t *meta, size_t length, wxsky_record *out, char *error,
                        size_t error_size) {
    if (error != NULL && error_size > 0) {
        error[0] = '\0';
    }
    if (out == NULL || (meta == NULL && length > 0)) {
        return wxsky_fail(error, error_size, WXSKY_EINVAL, "frame record: %s is NULL",
                          out == NULL ? "the output" : "the buffer");
    }
    if (length < 4) {
        return wxsky_fail(error, error_size, WXSKY_EFORMAT,
                          "frame record is %zu bytes, expected %d", length, WXSKY_RECORD_SIZE);
    }
    /* The version first: a record of another version may well have another length. */
    uint32_t version = get32(meta);
    if (version != 2 && version != WXSKY_RECORD_VERSION) {
        return wxsky_fail(error, error_size, WXSKY_EVERSION,
                          "frame record version %u; this kit reads versions 2 and %d",
                          (unsigned)version, WXSKY_RECORD_VERSION);
    }
    size_t size = version == 2 ? WXSKY_RECORD_V2_SIZE : WXSKY_RECORD_SIZE;
    if (length < size) {
        return wxsky_fail(error, error_size, WXSKY_EFORMAT,
                          "frame record is %zu bytes, expected %zu (version %u)", length, size,
                          (unsigned)version);
    }
    decoder d = {meta, error, error_size, WXSKY_OK};
    out->record_version = version;
    out->frame_number = get64(meta + 8);
    out->ring_version = get64(meta + 16);
    f64(&d, 24, &out->time_utc_unix_s, "time_utc_unix_s", -1, -1, -1);
    vec3(&d, 32, out->position_m, "position_m");
    f64(&d, 56, &out->heading_deg, "heading_deg", -1, -1, -1);
    f64(&d, 64, &out->pitch_deg, "pitch_deg", -1, -1, -1);
    f64(&d, 72, &out->roll_deg, "roll_deg", -1, -1, -1);
    f64(&d, 80, &out->fov_deg, "fov_deg", -1, -1, -1);
    out->width_px = get32(meta + 88);
    out->height_px = get32(meta + 92);
    vec3(&d, 96, out->sun_direction_enu, "sun_direction_enu");
    vec3(&d, 120, out->ring_centre_m, "ring_centre_m");
    f64(&d, 144, &out->ring_radius_m, "ring_radius_m", -1, -1, -1);
    quads(&d, 152, out->ring_quads_m, "ring_quads_m");
    flag(&d, 920, &out->ring_set, "ring_set");
    flag(&d, 924, &out->fading, "fading");
    f64(&d, 928, &out->ring_fade, "ring_fade", -1, -1, -1);
    vec3(&d, 936, out->ring_in_centre_m, "ring_in_centre_m");
    f64(&d, 960, &out->ring_in_radius_m, "ring_in_radius_m", -1, -1, -1);
    quads(&d, 968, out->ring_in_quads_m, "ring_in_quads_m");
    out->shadow_version = 0;
    memset(out->shadow_centre_m, 0, sizeof out->shadow_centre_m);
    out->shadow_size_m = 0.0;
    memset(out->shadow_sun_enu, 0, sizeof out->shadow_sun_enu);
    if (version >= 3) {
        out->shadow_version = get64(meta + 1736);
        vec3(&d, 1744, out->shadow_centre_m, "shadow_centre_m");
        f64(&d, 1768, &out->shadow_size_m, "shadow_size_m", -1, -1, -1);
        vec3(&d, 1776, out->shadow_sun_enu, "shadow_sun_enu");
        if (d.status == WXSKY_OK && out->shadow_version != 0 && !(out->shadow_size_m > 0.0)) {
            d.status = wxsky_fail(d.error, d.error_size, WXSKY_EFORMAT,
                                  "frame record: shadow_size_m is %g at offset 1768 with "
                                  "shadow_version %llu, expected above 0",
                                  out->shadow_size_m,
                                  (unsigned long long)out->shadow_version);
        }
    }
    return d.status;
}
