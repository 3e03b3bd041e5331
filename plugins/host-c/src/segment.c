/* Opening and validating the shared-memory frame segment (protocol §1.1, §1.2, §1.6).
 *
 * Everything a frame read relies on is checked here once, against the mapped size, and copied
 * into the handle: layer count, slot size, capacities and the slot regions. A frame read then
 * trusts only those copies and the per-frame values it loads once and checks (frame.c), so a
 * segment that lies, or a writer that rewrites its header later, cannot make the library read
 * outside the mapping. (A writer that *shrinks* the object after it was mapped would make a
 * read fault with SIGBUS; the protocol forbids it and no reader can guard against it.) */
#include "segment.h"

#include <errno.h>
#include <fcntl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

static const uint8_t MAGIC[8] = {'W', 'X', 'S', 'K', 'Y', 'S', 'H', 'M'};

wxsky_segment *wxsky_segment_new(void) {
    wxsky_segment *seg = calloc(1, sizeof *seg);
    return seg;
}

void wxsky_segment_free(wxsky_segment *seg) {
    if (seg == NULL) {
        return;
    }
    wxsky_segment_close(seg);
    free(seg);
}

const char *wxsky_segment_error(const wxsky_segment *seg) {
    return seg == NULL ? "no segment handle (NULL)" : seg->error;
}

void wxsky_segment_close(wxsky_segment *seg) {
    if (seg == NULL || seg->base == NULL) {
        return;
    }
    munmap((void *)(uintptr_t)seg->base, seg->size);
    seg->base = NULL;
    seg->size = 0;
    seg->layer_count = 0;
    seg->meta_capacity = 0;
}

#define FAIL(status, ...) wxsky_fail(seg->error, sizeof seg->error, (status), __VA_ARGS__)

static int check_name(wxsky_segment *seg, const char *name) {
    size_t len = strlen(name);
    if (len == 0 || len > WXSKY_SHM_NAME_MAX) {
        return FAIL(WXSKY_EINVAL,
                    "invalid segment name: %zu characters, expected 1-%d from A-Z a-z 0-9 . _ -",
                    len, WXSKY_SHM_NAME_MAX);
    }
    for (size_t i = 0; i < len; i++) {
        unsigned char c = (unsigned char)name[i];
        int ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                 c == '.' || c == '_' || c == '-';
        if (!ok) {
            return FAIL(WXSKY_EINVAL,
                        "invalid segment name: byte 0x%02x at position %zu is not one of "
                        "A-Z a-z 0-9 . _ -",
                        c, i);
        }
    }
    return WXSKY_OK;
}

int wxsky_segment_check_region(const wxsky_segment *seg, uint32_t slot, uint64_t offset,
                               uint64_t length, const char *what, char *msg, size_t msg_size) {
    uint64_t slot_start = (uint64_t)seg->header_size + (uint64_t)slot * seg->slot_size;
    uint64_t slot_end = slot_start + seg->slot_size;
    uint64_t first = slot_start + SLOT_LAYERS + (uint64_t)LAYER_ENTRY_SIZE * seg->layer_count;
    /* the open checks made header_size + 2 * slot_size <= size, so these sums do not wrap */
    if (offset > seg->size || length > seg->size - offset) {
        return wxsky_fail(msg, msg_size, WXSKY_EFORMAT,
                          "segment '%s': slot %u %s at offset %llu (%llu bytes) run past the "
                          "segment end (size %llu)",
                          seg->name, (unsigned)slot, what, (unsigned long long)offset,
                          (unsigned long long)length, (unsigned long long)seg->size);
    }
    if (offset < first || offset > slot_end || length > slot_end - offset) {
        return wxsky_fail(msg, msg_size, WXSKY_EFORMAT,
                          "segment '%s': slot %u %s at offset %llu (%llu bytes) lie outside the "
                          "slot's data (bytes %llu to %llu)",
                          seg->name, (unsigned)slot, what, (unsigned long long)offset,
                          (unsigned long long)length, (unsigned long long)first,
                          (unsigned long long)slot_end);
    }
    return WXSKY_OK;
}

/* Bytes of a layer descriptor in the segment's layout version (checked to be 1 or 2). */
static size_t desc_size(const wxsky_segment *seg) {
    return seg->version == 1 ? LAYER_DESC_SIZE : LAYER_DESC_SIZE_V2;
}

static int check_layers(wxsky_segment *seg, const uint8_t *p) {
    const size_t dsize = desc_size(seg);
    for (uint32_t k = 0; k < seg->layer_count; k++) {
        const uint8_t *d = p + HDR_LAYERS + dsize * k;
        wxsky_layer_info *info = &seg->layers[k];
        size_t len = 0;
        while (len < WXSKY_LAYER_NAME_MAX && d[len] != 0) {
            len++;
        }
        for (size_t i = 0; i < WXSKY_LAYER_NAME_MAX; i++) {
            uint8_t c = d[i];
            int ok = i < len ? (c >= 0x21 && c <= 0x7e) : c == 0;
            if (!ok) {
                return FAIL(WXSKY_EFORMAT,
                            "segment '%s': layer %u name has byte 0x%02x at position %zu "
                            "(descriptor at offset %zu): names are ASCII 0x21-0x7E, NUL-padded",
                            seg->name, (unsigned)k, c, i, (size_t)HDR_LAYERS + dsize * k);
            }
        }
        if (len == 0) {
            return FAIL(WXSKY_EFORMAT,
                        "segment '%s': layer %u has an empty name (descriptor at offset %zu)",
                        seg->name, (unsigned)k, (size_t)HDR_LAYERS + dsize * k);
        }
        memcpy(info->name, d, len);
        info->name[len] = '\0';
        for (uint32_t j = 0; j < k; j++) {
            if (strcmp(seg->layers[j].name, info->name) == 0) {
                return FAIL(WXSKY_EFORMAT, "segment '%s': layers %u and %u are both named '%s'",
                            seg->name, (unsigned)j, (unsigned)k, info->name);
            }
        }
        info->max_width = wxsky_get32(d + 16);
        info->max_height = wxsky_get32(d + 20);
        info->capacity = wxsky_get64(d + 24);
        /* Version 1 has no format field: every layer is RGBA8. */
        info->format = seg->version == 1 ? WXSKY_FORMAT_RGBA8 : wxsky_get32(d + LD_FORMAT);
        if (info->format == WXSKY_FORMAT_RGBA8) {
            info->bytes_per_pixel = 4;
        } else if (info->format == WXSKY_FORMAT_RGBA16F) {
            info->bytes_per_pixel = 8;
        } else {
            return FAIL(WXSKY_EFORMAT,
                        "segment '%s': layer %u '%s' has format %u (descriptor offset %zu); "
                        "this kit reads 0 RGBA8 and 1 RGBA16F",
                        seg->name, (unsigned)k, info->name, (unsigned)info->format,
                        (size_t)HDR_LAYERS + dsize * k + LD_FORMAT);
        }
        uint64_t pixels = (uint64_t)info->max_width * info->max_height; /* < 2^64 */
        if (pixels > UINT64_MAX / info->bytes_per_pixel ||
            info->capacity != pixels * info->bytes_per_pixel) {
            return FAIL(WXSKY_EFORMAT,
                        "segment '%s': layer %u '%s' capacity %llu is not max_width %u * "
                        "max_height %u * %u",
                        seg->name, (unsigned)k, info->name, (unsigned long long)info->capacity,
                        (unsigned)info->max_width, (unsigned)info->max_height,
                        (unsigned)info->bytes_per_pixel);
        }
    }
    return WXSKY_OK;
}

static int check_slots(wxsky_segment *seg, const uint8_t *p) {
    char what[64];
    for (uint32_t s = 0; s < 2; s++) {
        uint64_t slot_start = (uint64_t)seg->header_size + (uint64_t)s * seg->slot_size;
        const uint8_t *slot = p + slot_start;
        uint32_t meta_offset = wxsky_get32(slot + SLOT_META_OFFSET);
        int rc = wxsky_segment_check_region(seg, s, slot_start + meta_offset, seg->meta_capacity,
                                            "metadata region", seg->error, sizeof seg->error);
        if (rc != WXSKY_OK) {
            return rc;
        }
        for (uint32_t k = 0; k < seg->layer_count; k++) {
            const uint8_t *e = slot + SLOT_LAYERS + (size_t)LAYER_ENTRY_SIZE * k;
            uint64_t offset = wxsky_get64(e + 8);
            snprintf(what, sizeof what, "layer %u '%s' pixels", (unsigned)k, seg->layers[k].name);
            rc = wxsky_segment_check_region(seg, s, offset, seg->layers[k].capacity, what,
                                            seg->error, sizeof seg->error);
            if (rc != WXSKY_OK) {
                return rc;
            }
        }
    }
    return WXSKY_OK;
}

/* Every check of §1.1, in its order, then the layer table and the slot regions. */
static int validate(wxsky_segment *seg, const uint8_t *p) {
    /* The magic is written last at creation: an acquire load of it orders every later read of
     * the header after it. */
    uint64_t magic_word = WXSKY_LOAD_ACQUIRE((const uint64_t *)(const void *)p);
    uint8_t magic[8];
    memcpy(magic, &magic_word, sizeof magic);
    if (memcmp(magic, MAGIC, sizeof magic) != 0) {
        int partial = 1; /* zero, or being written: every byte 0 or the magic's */
        for (int i = 0; i < 8; i++) {
            partial = partial && (magic[i] == 0 || magic[i] == MAGIC[i]);
        }
        if (partial) {
            return FAIL(WXSKY_STARTING,
                        "segment '%s': its writer is still creating it (no magic yet); retry "
                        "in a few milliseconds",
                        seg->name);
        }
        return FAIL(WXSKY_EFORMAT,
                    "segment '%s' is not a wxsky frame segment (magic %02x %02x %02x %02x %02x "
                    "%02x %02x %02x at offset 0, expected \"WXSKYSHM\")",
                    seg->name, magic[0], magic[1], magic[2], magic[3], magic[4], magic[5],
                    magic[6], magic[7]);
    }
    seg->version = wxsky_get32(p + HDR_VERSION);
    if (seg->version < WXSKY_SEGMENT_VERSION_MIN || seg->version > WXSKY_SEGMENT_VERSION) {
        return FAIL(WXSKY_EVERSION,
                    "segment '%s' has layout version %u (offset 8); this kit reads versions "
                    "%d to %d",
                    seg->name, (unsigned)seg->version, WXSKY_SEGMENT_VERSION_MIN,
                    WXSKY_SEGMENT_VERSION);
    }
    uint32_t slot_count = wxsky_get32(p + HDR_SLOT_COUNT);
    if (slot_count != 2) {
        return FAIL(WXSKY_EFORMAT, "segment '%s': slot_count %u (offset 16), expected 2",
                    seg->name, (unsigned)slot_count);
    }
    seg->header_size = wxsky_get32(p + HDR_HEADER_SIZE);
    seg->slot_size = wxsky_get64(p + HDR_SLOT_SIZE);
    uint64_t size = seg->size;
    if (seg->header_size > size || seg->slot_size > (size - seg->header_size) / 2) {
        return FAIL(WXSKY_EFORMAT,
                    "segment '%s': header_size %u + 2 * slot_size %llu exceeds the segment "
                    "size %llu",
                    seg->name, (unsigned)seg->header_size, (unsigned long long)seg->slot_size,
                    (unsigned long long)size);
    }
    /* Beyond §1.1's list, what a reader needs before it reads anything else. */
    if (seg->header_size % 8 != 0 || seg->slot_size % 8 != 0) {
        return FAIL(WXSKY_EFORMAT,
                    "segment '%s': header_size %u and slot_size %llu must be multiples of 8",
                    seg->name, (unsigned)seg->header_size, (unsigned long long)seg->slot_size);
    }
    seg->layer_count = wxsky_get32(p + HDR_LAYER_COUNT);
    if (seg->layer_count < 1 || seg->layer_count > WXSKY_MAX_LAYERS) {
        uint32_t n = seg->layer_count;
        seg->layer_count = 0;
        return FAIL(WXSKY_EFORMAT, "segment '%s': layer_count %u (offset 20), expected 1-%d",
                    seg->name, (unsigned)n, WXSKY_MAX_LAYERS);
    }
    uint64_t descriptors_end = HDR_LAYERS + (uint64_t)desc_size(seg) * seg->layer_count;
    if (seg->header_size < descriptors_end) {
        return FAIL(WXSKY_EFORMAT,
                    "segment '%s': header_size %u leaves no room for %u layer descriptors "
                    "(they end at offset %llu)",
                    seg->name, (unsigned)seg->header_size, (unsigned)seg->layer_count,
                    (unsigned long long)descriptors_end);
    }
    uint64_t table_end = SLOT_LAYERS + (uint64_t)LAYER_ENTRY_SIZE * seg->layer_count;
    if (seg->slot_size < table_end) {
        return FAIL(WXSKY_EFORMAT,
                    "segment '%s': slot_size %llu is smaller than a slot header with %u layers "
                    "(%llu bytes)",
                    seg->name, (unsigned long long)seg->slot_size, (unsigned)seg->layer_count,
                    (unsigned long long)table_end);
    }
    seg->meta_capacity = wxsky_get32(p + HDR_META_CAPACITY);
    seg->writer_pid = wxsky_get32(p + HDR_WRITER_PID);
    int rc = check_layers(seg, p);
    if (rc == WXSKY_OK) {
        rc = check_slots(seg, p);
    }
    if (rc != WXSKY_OK) {
        return rc;
    }
    uint32_t state = wxsky_load32_acquire(p + HDR_STATE);
    if (state == STATE_INITIALISING) {
        return FAIL(WXSKY_STARTING, "segment '%s': state 0, its writer is still initialising it",
                    seg->name);
    }
    if (state == STATE_CLOSED) {
        return FAIL(WXSKY_ECLOSED, "segment '%s': its writer (pid %u) has closed it (state 2)",
                    seg->name, (unsigned)seg->writer_pid);
    }
    if (state != STATE_LIVE) {
        return FAIL(WXSKY_EFORMAT, "segment '%s': state %u (offset 44), expected 0, 1 or 2",
                    seg->name, (unsigned)state);
    }
    return WXSKY_OK;
}

int wxsky_segment_open(wxsky_segment *seg, const char *name) {
    if (seg == NULL) {
        return WXSKY_EINVAL;
    }
    wxsky_segment_close(seg);
    seg->name[0] = '\0';
    if (name == NULL) {
        return FAIL(WXSKY_EINVAL, "segment name is NULL");
    }
    if (name[0] == '/') {
        name++;
    }
    int rc = check_name(seg, name);
    if (rc != WXSKY_OK) {
        return rc;
    }
    memcpy(seg->name, name, strlen(name) + 1);
    char path[WXSKY_SHM_NAME_MAX + 2];
    path[0] = '/';
    memcpy(path + 1, name, strlen(name) + 1);

    int fd = shm_open(path, O_RDONLY, 0);
    if (fd < 0) {
        int e = errno;
        if (e == ENOENT) {
            return FAIL(WXSKY_ENOENT,
                        "segment '%s': no shared-memory object of that name (is the wxsky "
                        "daemon running?)",
                        seg->name);
        }
        return FAIL(WXSKY_ESYS, "segment '%s': shm_open: %s (errno %d)", seg->name, strerror(e),
                    e);
    }
    struct stat st;
    if (fstat(fd, &st) != 0) {
        int e = errno;
        close(fd);
        return FAIL(WXSKY_ESYS, "segment '%s': fstat: %s (errno %d)", seg->name, strerror(e), e);
    }
    if (st.st_size == 0) {
        close(fd);
        return FAIL(WXSKY_STARTING,
                    "segment '%s' is empty: its writer is still creating it; retry in a few "
                    "milliseconds",
                    seg->name);
    }
    if (st.st_size < HDR_FIXED_SIZE || (uint64_t)st.st_size > SIZE_MAX) {
        close(fd);
        return FAIL(WXSKY_EFORMAT,
                    "segment '%s' is %lld bytes, less than the 64-byte header: not a wxsky "
                    "frame segment",
                    seg->name, (long long)st.st_size);
    }
    size_t size = (size_t)st.st_size;
    void *map = mmap(NULL, size, PROT_READ, MAP_SHARED, fd, 0);
    int map_errno = errno;
    close(fd); /* the mapping keeps the object alive */
    if (map == MAP_FAILED) {
        return FAIL(WXSKY_ESYS, "segment '%s': mmap of %zu bytes: %s (errno %d)", seg->name, size,
                    strerror(map_errno), map_errno);
    }
    seg->size = size;
    rc = validate(seg, map);
    if (rc != WXSKY_OK) {
        munmap(map, size);
        seg->size = 0;
        seg->layer_count = 0;
        seg->meta_capacity = 0;
        return rc;
    }
    seg->base = map;
    seg->dev = st.st_dev;
    seg->ino = st.st_ino;
    seg->error[0] = '\0';
    return WXSKY_OK;
}

int wxsky_segment_check(wxsky_segment *seg) {
    if (seg == NULL) {
        return WXSKY_EINVAL;
    }
    if (seg->base == NULL) {
        return FAIL(WXSKY_EINVAL, "no segment is open");
    }
    if (wxsky_load32_acquire(seg->base + HDR_STATE) == STATE_CLOSED) {
        return FAIL(WXSKY_ECLOSED, "segment '%s': its writer (pid %u) has closed it (state 2)",
                    seg->name, (unsigned)seg->writer_pid);
    }
    char path[WXSKY_SHM_NAME_MAX + 2];
    path[0] = '/';
    memcpy(path + 1, seg->name, strlen(seg->name) + 1);
    int fd = shm_open(path, O_RDONLY, 0);
    if (fd < 0) {
        int e = errno;
        if (e == ENOENT) {
            return FAIL(WXSKY_ECLOSED, "segment '%s': the name is gone (its writer removed it)",
                        seg->name);
        }
        return FAIL(WXSKY_ESYS, "segment '%s': shm_open: %s (errno %d)", seg->name, strerror(e),
                    e);
    }
    struct stat st;
    int stat_rc = fstat(fd, &st);
    int e = errno;
    close(fd);
    if (stat_rc != 0) {
        return FAIL(WXSKY_ESYS, "segment '%s': fstat: %s (errno %d)", seg->name, strerror(e), e);
    }
    if (st.st_dev != seg->dev || st.st_ino != seg->ino) {
        return FAIL(WXSKY_ECLOSED,
                    "segment '%s': the name now refers to another object (a new writer replaced "
                    "it); reopen",
                    seg->name);
    }
    seg->error[0] = '\0';
    return WXSKY_OK;
}

int wxsky_segment_get_header(const wxsky_segment *seg, wxsky_segment_header *out) {
    if (seg == NULL || out == NULL || seg->base == NULL) {
        return WXSKY_EINVAL;
    }
    out->size = seg->size;
    out->version = seg->version;
    out->header_size = seg->header_size;
    out->slot_count = 2;
    out->layer_count = seg->layer_count;
    out->slot_size = seg->slot_size;
    out->meta_capacity = seg->meta_capacity;
    out->writer_pid = seg->writer_pid;
    out->active_slot = wxsky_load32_acquire(seg->base + HDR_ACTIVE_SLOT);
    out->state = wxsky_load32_acquire(seg->base + HDR_STATE);
    out->latest_frame = wxsky_load64_acquire(seg->base + HDR_LATEST_FRAME);
    out->publish_count = wxsky_load64_acquire(seg->base + HDR_PUBLISH_COUNT);
    return WXSKY_OK;
}

uint32_t wxsky_segment_layer_count(const wxsky_segment *seg) {
    return seg == NULL || seg->base == NULL ? 0 : seg->layer_count;
}

int wxsky_segment_layer(const wxsky_segment *seg, uint32_t index, wxsky_layer_info *out) {
    if (seg == NULL || out == NULL || seg->base == NULL || index >= seg->layer_count) {
        return WXSKY_EINVAL;
    }
    *out = seg->layers[index];
    return WXSKY_OK;
}

int wxsky_segment_find_layer(const wxsky_segment *seg, const char *name) {
    if (seg == NULL || name == NULL || seg->base == NULL) {
        return -1;
    }
    for (uint32_t k = 0; k < seg->layer_count; k++) {
        if (strcmp(seg->layers[k].name, name) == 0) {
            return (int)k;
        }
    }
    return -1;
}

uint64_t wxsky_segment_latest_frame(const wxsky_segment *seg) {
    if (seg == NULL || seg->base == NULL) {
        return 0;
    }
    if (wxsky_load64_acquire(seg->base + HDR_PUBLISH_COUNT) == 0) {
        return 0;
    }
    return wxsky_load64_acquire(seg->base + HDR_LATEST_FRAME);
}

uint32_t wxsky_segment_meta_capacity(const wxsky_segment *seg) {
    return seg == NULL || seg->base == NULL ? 0 : seg->meta_capacity;
}
