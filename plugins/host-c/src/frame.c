/* Reading frames under the per-slot seqlock (protocol §1.3, §1.4): zero-copy views and
 * copies into the caller's buffers. Nothing here allocates or writes to the segment.
 *
 * One attempt ("take"): load state, publish_count and active_slot (acquire); load the slot's
 * seq (acquire) and retry while it is 0 or odd; load active_slot again and retry if the slot
 * is no longer the active one (a frame completed but not yet made active would otherwise be
 * returned, and the next read would go back one frame); then load the slot's frame number,
 * metadata length and layer table once each and check them against the bounds validated at
 * open. After the caller used or copied the bytes, an acquire fence and a second load of seq
 * say whether the writer came back to the slot meanwhile (torn). Checking active_slot right
 * after seq rather than after the copy keeps reads monotonic just the same and lets a view be
 * held across one publish: the writer does not touch the slot again until the next one. */
#include "segment.h"

#include <stdio.h>
#include <string.h>
#include <time.h>

#define FAIL(status, ...) wxsky_fail(seg->error, sizeof seg->error, (status), __VA_ARGS__)

/* take()'s results besides WXSKY_OK and the errors: internal, never returned to callers. */
enum {
    TAKE_INVALID = 100, /* seq was even, but the table or lengths were out of range (message
                           in seg->error): corrupt unless the writer tore it */
    TAKE_NO_FRAME = 101,
    TAKE_BUSY = 102 /* the slot is being written or stopped being the active one */
};

#define IMMEDIATE_RETRIES 3
#define BACKOFF_NS 500000L

static int take(wxsky_segment *seg, wxsky_frame_view *v) {
    const uint8_t *p = seg->base;
    if (wxsky_load32_acquire(p + HDR_STATE) == STATE_CLOSED) {
        return FAIL(WXSKY_ECLOSED, "segment '%s': its writer (pid %u) has closed it (state 2)",
                    seg->name, (unsigned)seg->writer_pid);
    }
    if (wxsky_load64_acquire(p + HDR_PUBLISH_COUNT) == 0) {
        return TAKE_NO_FRAME;
    }
    uint32_t a = wxsky_load32_acquire(p + HDR_ACTIVE_SLOT);
    if (a > 1) {
        return FAIL(WXSKY_EFORMAT, "segment '%s': active_slot %u (offset 40), expected 0 or 1",
                    seg->name, (unsigned)a);
    }
    uint64_t slot_start = (uint64_t)seg->header_size + (uint64_t)a * seg->slot_size;
    const uint8_t *slot = p + slot_start;
    uint64_t s1 = wxsky_load64_acquire(slot + SLOT_SEQ);
    if (s1 == 0 || (s1 & 1) != 0) {
        return TAKE_BUSY;
    }
    if (wxsky_load32_acquire(p + HDR_ACTIVE_SLOT) != a) {
        return TAKE_BUSY;
    }
    v->slot_ = a;
    v->seq_ = s1;
    v->frame_number = wxsky_load64_relaxed(slot + SLOT_FRAME);
    v->layer_count = seg->layer_count;
    uint32_t meta_length = wxsky_load32_relaxed(slot + SLOT_META_LENGTH);
    uint32_t meta_offset = wxsky_load32_relaxed(slot + SLOT_META_OFFSET);
    int valid = 1;
    if (meta_length > seg->meta_capacity) {
        FAIL(WXSKY_EFORMAT, "segment '%s': slot %u meta_length %u exceeds meta_capacity %u",
             seg->name, (unsigned)a, (unsigned)meta_length, (unsigned)seg->meta_capacity);
        valid = 0;
    } else if (!wxsky_region_ok(seg, a, slot_start + meta_offset, seg->meta_capacity)) {
        wxsky_segment_check_region(seg, a, slot_start + meta_offset, seg->meta_capacity,
                                   "metadata region", seg->error, sizeof seg->error);
        valid = 0;
    }
    v->meta_length = valid ? meta_length : 0;
    v->meta = valid ? slot + meta_offset : NULL;
    for (uint32_t k = 0; k < seg->layer_count; k++) {
        const uint8_t *e = slot + SLOT_LAYERS + (size_t)LAYER_ENTRY_SIZE * k;
        const wxsky_layer_info *info = &seg->layers[k];
        wxsky_layer_view *lv = &v->layers[k];
        uint32_t w = wxsky_load32_relaxed(e);
        uint32_t h = wxsky_load32_relaxed(e + 4);
        uint64_t offset = wxsky_load64_relaxed(e + 8);
        lv->width = w;
        lv->height = h;
        lv->pixels = NULL;
        if (!valid) {
            continue;
        }
        if (w > info->max_width || h > info->max_height) {
            FAIL(WXSKY_EFORMAT,
                 "segment '%s': slot %u layer %u '%s' is %ux%u, more than its capacity %ux%u",
                 seg->name, (unsigned)a, (unsigned)k, info->name, (unsigned)w, (unsigned)h,
                 (unsigned)info->max_width, (unsigned)info->max_height);
            valid = 0;
            continue;
        }
        /* <= capacity, which was checked not to wrap; bytes_per_pixel is 4 or 8 */
        uint64_t length = (uint64_t)w * h * info->bytes_per_pixel;
        if (length == 0) {
            continue; /* absent: its offset is not used */
        }
        if (!wxsky_region_ok(seg, a, offset, length)) {
            char what[64];
            snprintf(what, sizeof what, "layer %u '%s' pixels", (unsigned)k, info->name);
            wxsky_segment_check_region(seg, a, offset, length, what, seg->error,
                                       sizeof seg->error);
            valid = 0;
            continue;
        }
        lv->pixels = p + offset;
    }
    if (!valid) {
        return TAKE_INVALID;
    }
    memset(&v->layers[seg->layer_count], 0,
           sizeof v->layers[0] * (WXSKY_MAX_LAYERS - seg->layer_count));
    return WXSKY_OK;
}

/* Whether the writer came back to the slot since seq was loaded (after the reads it guards). */
static int torn(const wxsky_segment *seg, uint32_t slot, uint64_t seq) {
    WXSKY_FENCE_ACQUIRE();
    const uint8_t *s = seg->base + seg->header_size + (uint64_t)slot * seg->slot_size;
    return wxsky_load64_relaxed(s + SLOT_SEQ) != seq;
}

int wxsky_frame_begin(wxsky_segment *seg, wxsky_frame_view *view) {
    if (seg == NULL) {
        return WXSKY_EINVAL;
    }
    if (view == NULL || seg->base == NULL) {
        return FAIL(WXSKY_EINVAL, view == NULL ? "frame view is NULL" : "no segment is open");
    }
    int rc = take(seg, view);
    switch (rc) {
    case WXSKY_OK:
        seg->error[0] = '\0';
        return WXSKY_OK;
    case TAKE_NO_FRAME:
        return FAIL(WXSKY_AGAIN, "segment '%s': no frame published yet", seg->name);
    case TAKE_BUSY:
        return FAIL(WXSKY_AGAIN, "segment '%s': the writer is writing or switching slots; retry", seg->name);
    case TAKE_INVALID:
        if (torn(seg, view->slot_, view->seq_)) {
            return FAIL(WXSKY_AGAIN, "segment '%s': slot %u changed while it was read; retry",
                        seg->name, (unsigned)view->slot_);
        }
        view->seq_ = 0; /* not a view: end refuses it */
        return WXSKY_EFORMAT;
    default:
        return rc;
    }
}

int wxsky_frame_end(wxsky_segment *seg, const wxsky_frame_view *view) {
    if (seg == NULL) {
        return WXSKY_EINVAL;
    }
    if (view == NULL || seg->base == NULL || view->slot_ > 1 || view->seq_ == 0) {
        return FAIL(WXSKY_EINVAL, "wxsky_frame_end: not a view from wxsky_frame_begin on this "
                                  "open segment");
    }
    if (torn(seg, view->slot_, view->seq_)) {
        return FAIL(WXSKY_ETORN,
                    "segment '%s': the writer overwrote slot %u (frame %llu) while it was "
                    "read; discard it",
                    seg->name, (unsigned)view->slot_, (unsigned long long)view->frame_number);
    }
    seg->error[0] = '\0';
    return WXSKY_OK;
}

static double now_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec / 1e6;
}

int wxsky_frame_read(wxsky_segment *seg, wxsky_frame_copy *out, int timeout_ms) {
    if (seg == NULL) {
        return WXSKY_EINVAL;
    }
    if (out == NULL || seg->base == NULL || timeout_ms < 0) {
        if (out == NULL) {
            return FAIL(WXSKY_EINVAL, "frame copy is NULL");
        }
        if (seg->base == NULL) {
            return FAIL(WXSKY_EINVAL, "no segment is open");
        }
        return FAIL(WXSKY_EINVAL, "negative timeout_ms %d", timeout_ms);
    }
    for (uint32_t k = 0; k < seg->layer_count; k++) {
        if (out->pixels[k] != NULL && out->pixels_size[k] < seg->layers[k].capacity) {
            return FAIL(WXSKY_ENOSPC,
                        "segment '%s': the buffer for layer %u '%s' is %zu bytes, less than its "
                        "capacity %llu",
                        seg->name, (unsigned)k, seg->layers[k].name, out->pixels_size[k],
                        (unsigned long long)seg->layers[k].capacity);
        }
    }
    if (out->meta != NULL && out->meta_size < seg->meta_capacity) {
        return FAIL(WXSKY_ENOSPC,
                    "segment '%s': the metadata buffer is %zu bytes, less than meta_capacity %u",
                    seg->name, out->meta_size, (unsigned)seg->meta_capacity);
    }
    double deadline = now_ms() + (double)timeout_ms;
    wxsky_frame_view v;
    unsigned attempts = 0;
    unsigned overwritten = 0;
    int last = WXSKY_OK;
    for (;;) {
        int rc = take(seg, &v);
        last = rc;
        if (rc == WXSKY_OK) {
            if (out->meta != NULL) {
                memcpy(out->meta, v.meta, v.meta_length);
            }
            for (uint32_t k = 0; k < v.layer_count; k++) {
                if (out->pixels[k] != NULL && v.layers[k].pixels != NULL) {
                    memcpy(out->pixels[k], v.layers[k].pixels,
                           (size_t)v.layers[k].width * v.layers[k].height *
                               seg->layers[k].bytes_per_pixel);
                }
            }
            if (!torn(seg, v.slot_, v.seq_)) {
                out->frame_number = v.frame_number;
                out->meta_length = v.meta_length;
                for (uint32_t k = 0; k < WXSKY_MAX_LAYERS; k++) {
                    out->width[k] = k < v.layer_count ? v.layers[k].width : 0;
                    out->height[k] = k < v.layer_count ? v.layers[k].height : 0;
                }
                seg->error[0] = '\0';
                return WXSKY_OK;
            }
            overwritten++;
        } else if (rc == TAKE_INVALID) {
            if (!torn(seg, v.slot_, v.seq_)) {
                return WXSKY_EFORMAT; /* the message is in seg->error */
            }
            overwritten++;
        } else if (rc == TAKE_BUSY) {
            overwritten++;
        } else if (rc != TAKE_NO_FRAME) {
            return rc;
        }
        attempts++;
        if (attempts > IMMEDIATE_RETRIES) {
            if (now_ms() >= deadline) {
                break;
            }
            struct timespec pause = {0, BACKOFF_NS};
            nanosleep(&pause, NULL);
        }
    }
    if (last == TAKE_NO_FRAME) {
        return FAIL(WXSKY_AGAIN, "segment '%s': no frame published yet (waited %d ms)", seg->name,
                    timeout_ms);
    }
    return FAIL(WXSKY_ETIMEDOUT,
                "segment '%s': no consistent frame within %d ms: %u attempts found the slot "
                "being written or overwritten",
                seg->name, timeout_ms, overwritten);
}
