/* The resumable msgpack validator behind wxsky_mp_object_size, for the client's receive buffer
 * (a message arriving in many reads is scanned once, not once per read). Not installed. */
#ifndef WXSKY_MSGPACK_SCAN_H
#define WXSKY_MSGPACK_SCAN_H

#include "wxsky_host.h"

typedef struct wxsky_mp_scan {
    size_t pos;    /* bytes of the object validated so far (always at an item boundary) */
    uint32_t depth;
    uint64_t owed; /* items not yet started, at every level (each needs at least one byte) */
    size_t limit;  /* the largest object accepted */
    const char *why; /* the reason, once the bytes were refused */
    uint64_t left[WXSKY_MP_MAX_DEPTH]; /* items not yet started in each open container */
    uint8_t map[WXSKY_MP_MAX_DEPTH];
} wxsky_mp_scan;

void wxsky_mp_scan_init(wxsky_mp_scan *s, size_t limit);
/* Continues over buf[0..len) (the same object's bytes as before, possibly more of them): the
 * object's size when complete, 0 when more bytes are needed, WXSKY_EFORMAT (s->why says why,
 * s->pos where) for bytes that are not the protocol's msgpack. */
long wxsky_mp_scan_run(wxsky_mp_scan *s, const uint8_t *buf, size_t len);

#endif
