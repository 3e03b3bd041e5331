/* The frame segment's private state and byte-level accessors (protocol §1.2), shared by
 * segment.c and frame.c; not installed. */
#ifndef WXSKY_HOST_SEGMENT_H
#define WXSKY_HOST_SEGMENT_H

#include "internal.h"

#include <sys/types.h>

#define WXSKY_SHM_NAME_MAX 200

/* Header, offsets from the segment start. */
#define HDR_MAGIC 0
#define HDR_VERSION 8
#define HDR_HEADER_SIZE 12
#define HDR_SLOT_COUNT 16
#define HDR_LAYER_COUNT 20
#define HDR_SLOT_SIZE 24
#define HDR_META_CAPACITY 32
#define HDR_WRITER_PID 36
#define HDR_ACTIVE_SLOT 40
#define HDR_STATE 44
#define HDR_LATEST_FRAME 48
#define HDR_PUBLISH_COUNT 56
#define HDR_LAYERS 64
#define HDR_FIXED_SIZE 64
#define LAYER_DESC_SIZE 32    /* segment version 1 */
#define LAYER_DESC_SIZE_V2 40 /* version 2: + u32 format, u32 reserved */
#define LD_FORMAT 32
/* Slot header, offsets from the slot start. */
#define SLOT_SEQ 0
#define SLOT_FRAME 8
#define SLOT_META_LENGTH 16
#define SLOT_META_OFFSET 20
#define SLOT_LAYERS 24
#define LAYER_ENTRY_SIZE 16

#define STATE_INITIALISING 0
#define STATE_LIVE 1
#define STATE_CLOSED 2

struct wxsky_segment {
    const uint8_t *base; /* the read-only mapping; NULL when closed */
    size_t size;
    dev_t dev;
    ino_t ino;
    /* fixed fields, copied and validated at open: the live mapping is never trusted again for
     * them, so a writer that rewrites them later cannot move a read out of bounds */
    uint32_t version;
    uint32_t header_size;
    uint32_t layer_count;
    uint32_t meta_capacity;
    uint32_t writer_pid;
    uint64_t slot_size;
    wxsky_layer_info layers[WXSKY_MAX_LAYERS];
    char name[WXSKY_SHM_NAME_MAX + 1];
    char error[WXSKY_ERROR_MAX];
};

/* The protocol is little-endian; the atomic loads read native words. */
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
#define WXSKY_LE32(x) __builtin_bswap32(x)
#define WXSKY_LE64(x) __builtin_bswap64(x)
#else
#define WXSKY_LE32(x) (x)
#define WXSKY_LE64(x) (x)
#endif

/* Byte-wise little-endian reads: any alignment, for fields that do not change. */
static inline uint32_t wxsky_get32(const uint8_t *p) {
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static inline uint64_t wxsky_get64(const uint8_t *p) {
    return (uint64_t)wxsky_get32(p) | (uint64_t)wxsky_get32(p + 4) << 32;
}

/* Single aligned loads of fields the writer changes (the offsets are validated to be aligned
 * at open), so a value is read once and cannot change between its check and its use. */
static inline uint32_t wxsky_load32_acquire(const uint8_t *p) {
    return WXSKY_LE32(WXSKY_LOAD_ACQUIRE((const uint32_t *)(const void *)p));
}

static inline uint64_t wxsky_load64_acquire(const uint8_t *p) {
    return WXSKY_LE64(WXSKY_LOAD_ACQUIRE((const uint64_t *)(const void *)p));
}

static inline uint32_t wxsky_load32_relaxed(const uint8_t *p) {
    return WXSKY_LE32(WXSKY_LOAD_RELAXED((const uint32_t *)(const void *)p));
}

static inline uint64_t wxsky_load64_relaxed(const uint8_t *p) {
    return WXSKY_LE64(WXSKY_LOAD_RELAXED((const uint64_t *)(const void *)p));
}

/* Whether `length` bytes at segment offset `offset` lie inside slot `slot` after its header
 * and layer table (and so inside the segment: open checked header_size + 2 * slot_size <=
 * size, so none of these sums wraps). */
static inline int wxsky_region_ok(const struct wxsky_segment *seg, uint32_t slot, uint64_t offset,
                                  uint64_t length) {
    uint64_t slot_start = (uint64_t)seg->header_size + (uint64_t)slot * seg->slot_size;
    uint64_t slot_end = slot_start + seg->slot_size;
    uint64_t first = slot_start + 24 + 16 * (uint64_t)seg->layer_count;
    return offset >= first && offset <= slot_end && length <= slot_end - offset;
}

/* wxsky_region_ok with the message: on failure writes "segment 'NAME': slot S <what> at offset
 * N (L bytes) run past the segment end (size M)" (or "... lie outside the slot's data (bytes A
 * to B)") into msg[msg_size] and returns WXSKY_EFORMAT; WXSKY_OK otherwise. */
int wxsky_segment_check_region(const wxsky_segment *seg, uint32_t slot, uint64_t offset,
                               uint64_t length, const char *what, char *msg, size_t msg_size);

#endif
