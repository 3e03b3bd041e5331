/*
 * wxsky_host.h - the wxsky host kit: read wxsky's frames and talk to its daemon from C or C++.
 *
 * Written from docs/protocol.md (protocol version 1, frame segment versions 1 and 2, frame
 * record version 3, and version 2 read too). C99, no global state: every object carries its own last error message. Objects
 * are allocated once (`*_new`); nothing in the per-frame path allocates. Every function that
 * can fail returns a `wxsky_status` (0 or a positive "not now" code on success, negative on
 * error) and leaves a one-line message in its object (`wxsky_segment_error`,
 * `wxsky_client_error`).
 *
 * Thread safety: an object may be used by one thread at a time; distinct objects are
 * independent.
 */
#ifndef WXSKY_HOST_H
#define WXSKY_HOST_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The kit's own API version: MAJOR changes break source compatibility. */
#define WXSKY_HOST_VERSION_MAJOR 0
/* 2: frame record v3 (the cloud-shadow fields); 3: segment v2, RGBA16F layers (the layer
 * info's format and bytes_per_pixel, wxsky_half_to_float, wxsky_display); 4: wxsky_display's
 * curve with a toe of slope 1; 5: the weather radar (wxsky_request_radar, wxsky_radar_decode) */
#define WXSKY_HOST_VERSION_MINOR 5
/* The protocol versions this kit speaks (docs/protocol.md). */
#define WXSKY_PROTOCOL_VERSION 1
#define WXSKY_SEGMENT_VERSION 2     /* the newest segment layout this kit reads */
#define WXSKY_SEGMENT_VERSION_MIN 1 /* version 1: RGBA8 layers only, no format field */
#define WXSKY_RECORD_VERSION 3 /* the newest; wxsky_record_decode reads 2 as well */

#define WXSKY_MAX_LAYERS 64      /* protocol §1.2: layer_count is 1..64 */
#define WXSKY_LAYER_NAME_MAX 16  /* protocol §1.2: name is char[16] */
#define WXSKY_ERROR_MAX 256      /* bytes of an object's last error message, NUL included */

/* Runtime version of the library, (MAJOR << 16) | MINOR, to compare with the header's. */
uint32_t wxsky_host_version(void);

typedef enum wxsky_status {
    WXSKY_OK = 0,
    WXSKY_AGAIN = 1,      /* nothing yet (no frame, no message): not an error, try later */
    WXSKY_STARTING = 2,   /* the segment exists but its writer is still creating it */
    WXSKY_EINVAL = -1,    /* a bad argument (NULL, a name outside the protocol's syntax) */
    WXSKY_ENOENT = -2,    /* no such segment, or no daemon listening at the address */
    WXSKY_EFORMAT = -3,   /* a segment, record or message not in the protocol's format */
    WXSKY_EVERSION = -4,  /* a segment or record version this kit does not know */
    WXSKY_ETORN = -5,     /* the writer overwrote the frame while it was read: discard it */
    WXSKY_ECLOSED = -6,   /* the writer closed or replaced the segment / the daemon hung up */
    WXSKY_ESYS = -7,      /* a system call failed (the message names it and errno) */
    WXSKY_ENOSPC = -8,    /* a caller's buffer, or the kit's, is too small */
    WXSKY_ETIMEDOUT = -9, /* a blocking convenience call gave up */
    WXSKY_EREMOTE = -10   /* the daemon answered a request with an error (in the message) */
} wxsky_status;

/* "WXSKY_OK", "WXSKY_ETORN", ...; "unknown" for other values. */
const char *wxsky_status_name(int status);

/* ---------------------------------------------------------------------------------------
 * Frames: the shared-memory segment (protocol §1) and the frame record (§3).
 * ------------------------------------------------------------------------------------- */

typedef struct wxsky_segment wxsky_segment;

/* A layer's pixel format (protocol §1.2; a version 1 segment's layers are all RGBA8). */
typedef enum wxsky_layer_format {
    /* 4 bytes a pixel: display values (exposed, tone-mapped, sRGB-encoded by the daemon) */
    WXSKY_FORMAT_RGBA8 = 0,
    /* 8 bytes a pixel: 4 IEEE 754 half floats, little-endian, scene-linear colour before
     * exposure and tone map (the daemon's [output] layer_format = "rgba16f"): composite in
     * linear, then expose and tone-map once (wxsky_display) */
    WXSKY_FORMAT_RGBA16F = 1
} wxsky_layer_format;

typedef struct wxsky_layer_info {
    char name[WXSKY_LAYER_NAME_MAX + 1]; /* NUL-terminated */
    uint32_t max_width;
    uint32_t max_height;
    uint64_t capacity;        /* bytes: max_width * max_height * bytes_per_pixel */
    uint32_t format;          /* a wxsky_layer_format */
    uint32_t bytes_per_pixel; /* 4 (RGBA8) or 8 (RGBA16F) */
} wxsky_layer_info;

/* The segment's header (§1.2): the fixed fields as validated at open, and the live ones as
 * they stand now (for diagnostics: frame reads do not use this). */
typedef struct wxsky_segment_header {
    uint64_t size; /* bytes mapped: the object's size at open */
    uint32_t version;
    uint32_t header_size;
    uint32_t slot_count;
    uint32_t layer_count;
    uint64_t slot_size;
    uint32_t meta_capacity;
    uint32_t writer_pid;
    uint32_t active_slot;   /* live */
    uint32_t state;         /* live: 0 initialising, 1 live, 2 closed */
    uint64_t latest_frame;  /* live */
    uint64_t publish_count; /* live */
} wxsky_segment_header;

/* A segment handle, not yet open. NULL only when out of memory. */
wxsky_segment *wxsky_segment_new(void);
/* Unmaps and frees; NULL is fine. */
void wxsky_segment_free(wxsky_segment *seg);
/* The last error message ("" after success). Never NULL. WXSKY_AGAIN and WXSKY_STARTING also
 * leave a message saying why. */
const char *wxsky_segment_error(const wxsky_segment *seg);

/* Opens and validates the segment `name` (the daemon's `shm_name`; one leading '/' is
 * accepted and ignored), every check of §1.1 and the layer table. Reopening an open handle
 * first closes it. Returns WXSKY_OK; WXSKY_STARTING while its writer is still creating it
 * (size 0, magic not yet written, or state 0: retry in a few milliseconds); WXSKY_ENOENT when
 * no object has that name; WXSKY_ECLOSED when its writer has already closed it (state 2);
 * WXSKY_EVERSION for a segment version other than 1 and 2 (WXSKY_SEGMENT_VERSION_MIN to
 * WXSKY_SEGMENT_VERSION); WXSKY_EFORMAT for anything else not in the protocol's format, a
 * layer format other than RGBA8 and RGBA16F among them (the message names the field, the
 * layer or slot, and the offsets);
 * WXSKY_EINVAL for a name outside §1.1's syntax; WXSKY_ESYS when shm_open, fstat or mmap
 * failed. On any result but WXSKY_OK the handle is left closed. */
int wxsky_segment_open(wxsky_segment *seg, const char *name);
/* Unmaps; idempotent. */
void wxsky_segment_close(wxsky_segment *seg);
/* WXSKY_OK while the mapped segment is still the live one; WXSKY_ECLOSED when its writer
 * closed it (state 2), the name is gone, or the name now refers to another object (a
 * restarted daemon, §1.6): reopen then. WXSKY_EINVAL when not open, WXSKY_ESYS when the fresh
 * shm_open/fstat failed otherwise. Costs a system call or two: call it when frames stop
 * arriving, or once a second, not every frame. A writer that died without closing leaves
 * state 1 and the name in place: that shows only as frames that stop arriving. */
int wxsky_segment_check(wxsky_segment *seg);

/* The header as validated at open, with the live fields loaded now; WXSKY_EINVAL when not
 * open. */
int wxsky_segment_get_header(const wxsky_segment *seg, wxsky_segment_header *out);
/* 0 when not open. */
uint32_t wxsky_segment_layer_count(const wxsky_segment *seg);
/* WXSKY_EINVAL for an index >= layer_count (or no segment open). */
int wxsky_segment_layer(const wxsky_segment *seg, uint32_t index, wxsky_layer_info *out);
/* The index of the layer named `name`, or -1. */
int wxsky_segment_find_layer(const wxsky_segment *seg, const char *name);
/* The latest published frame number, 0 before the first (the cheap "anything new?" test:
 * compare with `>`, §1.4; a writer may number its first frame 0, so read once before relying
 * on it). 0 when not open. */
uint64_t wxsky_segment_latest_frame(const wxsky_segment *seg);
/* 0 when not open. */
uint32_t wxsky_segment_meta_capacity(const wxsky_segment *seg);

/* Zero-copy read: `wxsky_frame_begin` gives pointers into the segment's active slot (layer
 * table and metadata validated); use them, then `wxsky_frame_end` says whether the writer
 * touched the slot meanwhile (WXSKY_ETORN: discard whatever was done with the pointers,
 * including a wxsky_record_decode of `meta` and its error, which may come from torn bytes).
 * The writer never writes the active slot, and the slot of a view stays untouched until the
 * writer comes back to it two publishes later, so a view held across one publish still ends
 * WXSKY_OK. The bytes behind the pointers may change at any moment: read them as untrusted
 * data (never index with them). The pointers stay valid (mapped) until the segment is closed
 * or reopened, whatever the writer does. */
typedef struct wxsky_layer_view {
    const uint8_t *pixels; /* premultiplied, in the layer's format (wxsky_layer_info), top
                              row first, stride width * bytes_per_pixel; NULL when width *
                              height is 0 */
    uint32_t width;        /* 0: the layer is absent from this frame */
    uint32_t height;
} wxsky_layer_view;

typedef struct wxsky_frame_view {
    uint64_t frame_number;
    const uint8_t *meta; /* the frame record's bytes */
    uint32_t meta_length;
    uint32_t layer_count;
    wxsky_layer_view layers[WXSKY_MAX_LAYERS]; /* entries >= layer_count are zero */
    /* private: which slot and sequence the view was taken under */
    uint32_t slot_;
    uint64_t seq_;
} wxsky_frame_view;

/* WXSKY_OK with a view, WXSKY_AGAIN when no frame was published yet or the slot is being
 * written (retry), WXSKY_ECLOSED when the writer closed, WXSKY_EFORMAT for a corrupt slot,
 * WXSKY_EINVAL when not open. Never blocks, never allocates. */
int wxsky_frame_begin(wxsky_segment *seg, wxsky_frame_view *view);
/* WXSKY_OK if the view stayed consistent, WXSKY_ETORN otherwise (WXSKY_EINVAL for a view
 * this open segment did not give). */
int wxsky_frame_end(wxsky_segment *seg, const wxsky_frame_view *view);

/* Copy-out read: a complete, consistent copy of the latest frame into caller buffers (the
 * seqlock reader of §1.4 with retries, 0.5 ms back-off after 3 immediate retries, giving up
 * after `timeout_ms`, >= 0; 0 tries a few times without sleeping). */
typedef struct wxsky_frame_copy {
    /* set by the caller: one buffer per layer index, each at least its capacity in bytes
     * (NULL: do not copy that layer), and a metadata buffer of at least meta_capacity bytes
     * (NULL: do not copy the metadata) */
    uint8_t *pixels[WXSKY_MAX_LAYERS];
    size_t pixels_size[WXSKY_MAX_LAYERS];
    uint8_t *meta;
    size_t meta_size;
    /* set by a read that returns WXSKY_OK, for every layer (copied or not; 0 from
     * layer_count on) */
    uint64_t frame_number;
    uint32_t meta_length;
    uint32_t width[WXSKY_MAX_LAYERS];
    uint32_t height[WXSKY_MAX_LAYERS];
} wxsky_frame_copy;

/* WXSKY_OK with the copy; WXSKY_AGAIN when no frame has been published by the deadline;
 * WXSKY_ETIMEDOUT when frames exist but none could be copied consistently in time (the
 * writer kept overwriting the slot); WXSKY_ENOSPC (before reading anything) for a buffer
 * smaller than its layer's capacity or the meta capacity; WXSKY_ECLOSED, WXSKY_EFORMAT,
 * WXSKY_EINVAL as wxsky_frame_begin. On any result but WXSKY_OK the buffers' contents are
 * unspecified (a torn attempt may have been copied into them): to keep the last good frame,
 * read into a second set of buffers. Never allocates. */
int wxsky_frame_read(wxsky_segment *seg, wxsky_frame_copy *out, int timeout_ms);

/* The frame record, version 3 (§3), or version 2 (whose fields are version 3's but the
 * shadow fields, which then read as zeros). */
typedef struct wxsky_record {
    uint32_t record_version;
    uint64_t frame_number;
    uint64_t ring_version;
    double time_utc_unix_s;
    double position_m[3];
    double heading_deg, pitch_deg, roll_deg, fov_deg;
    uint32_t width_px, height_px;
    double sun_direction_enu[3];
    double ring_centre_m[3];
    double ring_radius_m;
    double ring_quads_m[8][4][3];
    uint32_t ring_set;
    uint32_t fading;
    double ring_fade;
    double ring_in_centre_m[3];
    double ring_in_radius_m;
    double ring_in_quads_m[8][4][3];
    /* The cloud-shadow map, the slot's `shadow` layer (§1.5, §3.3); version 3 only. */
    uint64_t shadow_version;     /* 0: no map in this slot (the fields below are zeros) */
    double shadow_centre_m[3];   /* map centre east, north; up: the plane it lies on (MSL) */
    double shadow_size_m;        /* the square map's edge */
    double shadow_sun_enu[3];    /* the unit sun the map was made for: project along it */
} wxsky_record;

#define WXSKY_RECORD_SIZE 1800    /* version 3 */
#define WXSKY_RECORD_V2_SIZE 1736 /* version 2 */

/* Decodes a record (little-endian, by byte offset; `meta` needs no alignment). WXSKY_EVERSION
 * for a record_version other than 2 and 3; WXSKY_EFORMAT when shorter than its version's size
 * (WXSKY_RECORD_SIZE, WXSKY_RECORD_V2_SIZE; bytes beyond are ignored) or a value is impossible
 * (a non-finite float, fading or ring_set not 0/1, a shadow_version not 0 with a
 * shadow_size_m not above 0). A version 2 record decodes with shadow_version 0.
 * `error` (may be NULL) gets a one-line message ("" on success). `*out` is unspecified after
 * an error. */
int wxsky_record_decode(const uint8_t *meta, size_t length, wxsky_record *out, char *error,
                        size_t error_size);

/* ---------------------------------------------------------------------------------------
 * HDR layers (RGBA16F, docs/linear-output.md): a host composites them in linear and shows the
 * result through one exposure and one tone map, the daemon's own (wxsky/scene/exposure.py
 * `display`), so its picture is the 8-bit layers' look without their per-fragment tone map.
 * ------------------------------------------------------------------------------------- */

/* An IEEE 754 binary16 value (as an RGBA16F layer holds it) as a float: exact, subnormals,
 * infinities and NaN included. */
float wxsky_half_to_float(uint16_t half);

/* The daemon's display transform of straight (not premultiplied) scene-linear colour:
 * srgb_encode(tone_map(rgb * exposure)), where tone_map is Narkowicz's form of the ACES fit
 * with a toe of slope 1, x (2.51 x + 0.14) / (x (2.43 x + 0.70) + 0.14), clamped to 0..1 (kit
 * versions before 0.4: the fit's own 0.03 and 0.59, whose toe crushed dark values), applied
 * to the largest channel with the colour scaled by the same factor and, past the curve's
 * white (7.24), burnt toward white (0.9 of the way at 4 times it: exposure.py `burn`), and
 * srgb_encode the sRGB transfer function. `exposure`: the scale on scene-linear colour (2^EV; 1 is the daemon's EV 0).
 * Negative and NaN channels count as 0. out_rgb: display values 0..1. */
void wxsky_display(const float linear_rgb[3], float exposure, float out_rgb[3]);

/* ---------------------------------------------------------------------------------------
 * MessagePack, the subset the control channel uses (§2.2): a validator, a bounded reader over
 * one complete object and a writer into a caller buffer. None of them allocates.
 * ------------------------------------------------------------------------------------- */

#define WXSKY_MAX_MESSAGE (8u * 1024u * 1024u) /* §2.2: the largest encoded message */
#define WXSKY_MP_MAX_DEPTH 64                  /* §2.2: containers nest at most this deep */

/* A reader over bytes the caller trusts to be one object (e.g. checked by
 * wxsky_mp_object_size, as the client's messages are); even on other bytes it never reads
 * outside [p, end). */
typedef struct wxsky_mp_reader {
    const uint8_t *p;
    const uint8_t *end;
    int error; /* sticky: once set (WXSKY_EFORMAT), every read fails */
} wxsky_mp_reader;

typedef enum wxsky_mp_type {
    WXSKY_MP_NONE = 0, /* error, end, or a byte that is not the protocol's */
    WXSKY_MP_NIL,
    WXSKY_MP_BOOL,
    WXSKY_MP_INT,  /* an integer in int64 range (any encoding, so also 0..INT64_MAX) */
    WXSKY_MP_UINT, /* an integer above INT64_MAX: only wxsky_mp_read_uint reads it */
    WXSKY_MP_FLOAT,
    WXSKY_MP_STR,
    WXSKY_MP_BIN,
    WXSKY_MP_ARRAY,
    WXSKY_MP_MAP
} wxsky_mp_type;

/* The size of the one complete object at the start of buf: > 0 bytes, 0 when more bytes are
 * needed, < 0 (WXSKY_EFORMAT) for bytes that are not the protocol's msgpack: an extension type
 * or 0xc1, a map key that is not a str, a str that is not valid UTF-8, containers nested deeper
 * than WXSKY_MP_MAX_DEPTH (the outermost counts as 1), or an object that is or would be larger
 * than WXSKY_MAX_MESSAGE (refused as soon as a header says so, without waiting for the bytes).
 * Bytes after the object are not looked at. */
long wxsky_mp_object_size(const uint8_t *buf, size_t len);

void wxsky_mp_reader_init(wxsky_mp_reader *r, const uint8_t *buf, size_t len);
wxsky_mp_type wxsky_mp_peek(const wxsky_mp_reader *r);
/* Each read checks the type and that the item lies inside the buffer; on a mismatch it returns
 * WXSKY_EFORMAT, sets r->error and does not move (wxsky_mp_skip may stop part-way). `out` may be NULL (read and discard). */
int wxsky_mp_read_nil(wxsky_mp_reader *r);
int wxsky_mp_read_bool(wxsky_mp_reader *r, int *out);
int wxsky_mp_read_int(wxsky_mp_reader *r, int64_t *out);   /* WXSKY_MP_INT */
int wxsky_mp_read_uint(wxsky_mp_reader *r, uint64_t *out); /* any integer >= 0 */
int wxsky_mp_read_double(wxsky_mp_reader *r, double *out); /* float32/64; ints convert */
/* The string's bytes in the buffer, not NUL-terminated. */
int wxsky_mp_read_str(wxsky_mp_reader *r, const char **out, uint32_t *len);
int wxsky_mp_read_bin(wxsky_mp_reader *r, const uint8_t **out, uint32_t *len);
/* Container headers: the elements (arrays) or key/value pairs (maps) follow. A count larger
 * than the bytes left is refused. */
int wxsky_mp_read_array(wxsky_mp_reader *r, uint32_t *count);
int wxsky_mp_read_map(wxsky_mp_reader *r, uint32_t *count);
/* Skips one whole item, containers included (iteratively: no recursion, any depth). */
int wxsky_mp_skip(wxsky_mp_reader *r);
/* In a map whose header was just read (count pairs follow), position the reader at the value
 * of `key`; WXSKY_AGAIN when absent (the reader is then past the map), WXSKY_EFORMAT for a key
 * that is not a str. */
int wxsky_mp_find_key(wxsky_mp_reader *r, uint32_t count, const char *key);

/* A writer: every write is all or nothing; one that does not fit sets `overflow`, and every
 * later write is then refused too, so a message is checked once, at its end. Integers take
 * their smallest encoding, doubles are always float64, strings the str family (str8 included),
 * byte strings the bin family: msgpack-python's packb(use_bin_type=True) gives the same bytes. */
typedef struct wxsky_mp_writer {
    uint8_t *buf;
    size_t cap;
    size_t len;
    int overflow; /* sticky: set when a write did not fit */
} wxsky_mp_writer;

void wxsky_mp_writer_init(wxsky_mp_writer *w, uint8_t *buf, size_t cap);
void wxsky_mp_write_nil(wxsky_mp_writer *w);
void wxsky_mp_write_bool(wxsky_mp_writer *w, int v);
void wxsky_mp_write_int(wxsky_mp_writer *w, int64_t v);
void wxsky_mp_write_uint(wxsky_mp_writer *w, uint64_t v);
void wxsky_mp_write_double(wxsky_mp_writer *w, double v);
void wxsky_mp_write_str(wxsky_mp_writer *w, const char *s, size_t len); /* UTF-8 */
void wxsky_mp_write_cstr(wxsky_mp_writer *w, const char *s);
void wxsky_mp_write_bin(wxsky_mp_writer *w, const uint8_t *data, size_t len);
void wxsky_mp_write_array(wxsky_mp_writer *w, uint32_t count);
void wxsky_mp_write_map(wxsky_mp_writer *w, uint32_t count);
/* Appends bytes that are already msgpack (e.g. a value kept from a received message). */
void wxsky_mp_write_raw(wxsky_mp_writer *w, const uint8_t *data, size_t len);

/* ---------------------------------------------------------------------------------------
 * Control and stream (protocol §2, §4, §5).
 *
 * One client is one connection to the daemon, driven from the host's own loop: requests are
 * sent without waiting (each returns its msgid), and wxsky_client_poll hands out what arrived,
 * one complete message at a time, never blocking. wxsky_client_wait / wxsky_client_call block
 * (with a timeout) for one response, keeping whatever else arrives meanwhile in a queue that
 * poll returns first, so nothing is reordered. Memory: three areas of `buffer_bytes` (receive,
 * send, queue), allocated by wxsky_client_new; only the pages used are ever touched. Nothing
 * allocates afterwards.
 * ------------------------------------------------------------------------------------- */

#define WXSKY_ADDRESS_MAX 256       /* bytes of an address, NUL included */
#define WXSKY_SUBSCRIPTION_MAX 1024 /* bytes of topic names a client keeps for reconnect */

typedef struct wxsky_client wxsky_client;

/* A client, not connected, with buffers of `buffer_bytes` (0: the protocol's 8 MiB message
 * limit plus 64 KiB, so any message fits; at least 1024) and room for `queued` messages read
 * while waiting for a response (0: 64). NULL only when out of memory. */
wxsky_client *wxsky_client_new(size_t buffer_bytes, size_t queued);
void wxsky_client_free(wxsky_client *c); /* closes; NULL is fine */
/* The message of the last call that did not succeed (a request's WXSKY_AGAIN says why too),
 * "" after one that did (a poll's WXSKY_AGAIN included). Never NULL. For WXSKY_EREMOTE, the
 * daemon's message verbatim (cut at WXSKY_ERROR_MAX - 1 bytes). */
const char *wxsky_client_error(const wxsky_client *c);

/* Connects to "unix:PATH" (a leading ~ or ~user expanded; at most 107 bytes) or
 * "tcp:HOST:PORT" with HOST 127.x.y.z, localhost, ::1 or [::1] (§2.1: any other host is refused
 * with WXSKY_EINVAL before a socket is made; names other than localhost are never resolved),
 * or, when `address` is NULL, the default address of §2.1, whose directory must then exist and
 * belong to this user. WXSKY_ENOENT when nothing listens there. Waits at most 2 s (then
 * WXSKY_ETIMEDOUT); the socket
 * is then non-blocking (and close-on-exec; tcp with TCP_NODELAY). Connecting a connected
 * client closes the old connection first. The subscription set is kept: after a connect to a
 * new address, call wxsky_subscribe again (or use wxsky_client_reconnect). */
int wxsky_client_connect(wxsky_client *c, const char *address);
/* Connects again to the last address and renews the subscription (every topic subscribed and
 * not unsubscribed since the client was made): for after the daemon restarted and poll
 * returned WXSKY_ECLOSED. Retry it (e.g. once a second) while it returns WXSKY_ENOENT. The
 * daemon's answer to the renewed subscribe is consumed by the client, never returned. */
int wxsky_client_reconnect(wxsky_client *c);
/* Closes the connection; idempotent. Requests not yet sent are dropped; queued messages stay,
 * and poll returns them before WXSKY_ECLOSED. */
void wxsky_client_close(wxsky_client *c);
/* The socket, for the host's own poll()/select() (POLLIN; POLLOUT while wxsky_client_flush
 * returns WXSKY_AGAIN); -1 when not connected. */
int wxsky_client_fd(const wxsky_client *c);
/* Messages dropped from the full queue so far (the oldest go first, §2.4's rule). */
uint64_t wxsky_client_dropped(const wxsky_client *c);

/* Requests. Each is encoded into the send buffer and written at once as far as the socket
 * takes it; the rest goes out with the next request, poll, wait or flush. WXSKY_OK: queued,
 * *msgid (may be NULL) says which response answers it. WXSKY_AGAIN: not queued, because
 * earlier requests still wait for the socket (poll or flush, then retry); WXSKY_ENOSPC: larger
 * than the send buffer; WXSKY_ECLOSED: not connected (or the send found the daemon gone).
 * msgids count up from 1 per client and wrap from 2^32-1 to 0; they carry on over reconnects.
 * `params_msgpack`: one complete msgpack map (NULL with params_len 0: {}), else WXSKY_EINVAL. */
int wxsky_client_request(wxsky_client *c, const char *method, const uint8_t *params_msgpack,
                         size_t params_len, uint32_t *msgid);
/* Sends what the send buffer still holds: WXSKY_OK when empty, WXSKY_AGAIN when the socket is
 * full (wait for POLLOUT on the fd). */
int wxsky_client_flush(wxsky_client *c);

/* `subscribe` / `unsubscribe` (§2.4) with `count` topic names; the client also keeps the set
 * (at most WXSKY_SUBSCRIPTION_MAX bytes of names, else WXSKY_ENOSPC and nothing sent) for
 * wxsky_client_reconnect. The result is {"topics": [the whole set, sorted]}. */
int wxsky_subscribe(wxsky_client *c, const char *const *topics, size_t count, uint32_t *msgid);
int wxsky_unsubscribe(wxsky_client *c, const char *const *topics, size_t count,
                      uint32_t *msgid);

typedef struct wxsky_camera {
    double position_m[3]; /* east, north, up (§0 coordinates) */
    double heading_deg, pitch_deg, roll_deg, fov_deg;
    uint32_t width, height; /* 0: keep the daemon's (both are then left out of the request) */
} wxsky_camera;

/* `set_camera` with every field of *camera (§5); the result is the new camera. */
int wxsky_set_camera(wxsky_client *c, const wxsky_camera *camera, uint32_t *msgid);
/* position_m NULL: no aircraft (stop splitting the near layer). */
int wxsky_set_aircraft(wxsky_client *c, const double *position_m, uint32_t *msgid);
/* time_utc: ISO 8601 ("2024-06-21T12:00:00Z"); rate: simulated s per wall s. Either may be
 * NULL (not both: WXSKY_EINVAL). */
int wxsky_set_time(wxsky_client *c, const char *time_utc, const double *rate, uint32_t *msgid);
int wxsky_apply_preset(wxsky_client *c, const char *name, uint32_t *msgid);
int wxsky_apply_metar(wxsky_client *c, const char *report, uint32_t *msgid);
/* source NULL: "control". */
int wxsky_release(wxsky_client *c, const char *source, uint32_t *msgid);
int wxsky_request_status(wxsky_client *c, uint32_t *msgid);

/* `radar` (§5, docs/radar.md): the weather radar's picture of the clouds wxsky draws, from the
 * camera. range_nm 10..320, tilt_deg -15..15, size_px 64..1024: the daemon checks them (a bad
 * one is WXSKY_EREMOTE naming the field). The answer comes at once: the last picture made for
 * these settings, or `pending` until the first one is (ask again). Decode it with
 * wxsky_radar_decode. */
int wxsky_request_radar(wxsky_client *c, double range_nm, double tilt_deg, uint32_t size_px,
                        uint32_t *msgid);

typedef struct wxsky_radar {
    int pending;                 /* 1: no picture yet for these settings; the rest is 0 */
    uint32_t size_px;            /* the picture is size_px x size_px */
    double range_nm, tilt_deg;   /* as asked */
    double age_s;                /* since the picture was made */
    double dbz_offset, dbz_step; /* dBZ = byte * dbz_step + dbz_offset (-32, 0.5) */
    double centre_m[3];          /* where it was taken from (east, north, up) */
    const uint8_t *pixels;       /* size_px * size_px bytes, rows north to south, columns west
                                    to east, the camera in the middle (north-up); points into
                                    the message's body: valid as long as it is; NULL pending */
} wxsky_radar;

/* A `radar` response's result (wxsky_message.body) into *out: WXSKY_OK, or WXSKY_EFORMAT when
 * it is not one (a missing or mistyped field, pixels not size_px^2 bytes). */
int wxsky_radar_decode(const uint8_t *body, size_t len, wxsky_radar *out);

typedef enum wxsky_message_kind {
    WXSKY_RESPONSE = 1,
    WXSKY_NOTIFICATION = 2
} wxsky_message_kind;

/* A received message, checked against §2.2 (shape, types, limits). Its pointers stay valid
 * until the next poll/wait/call on the client (not past wxsky_client_free). */
typedef struct wxsky_message {
    wxsky_message_kind kind;
    int has_msgid;  /* responses: 0 when the daemon could not tell (msgid nil) */
    uint32_t msgid;
    const char *method; /* notifications: the topic (not NUL-terminated) */
    uint32_t method_len;
    const char *error; /* responses: NULL on success, else the one-line message */
    uint32_t error_len;
    const uint8_t *body; /* msgpack of the result (responses) or params map (notifications) */
    size_t body_len;
} wxsky_message;

/* Non-blocking: WXSKY_OK with the next message (queued ones first, then the stream, in the
 * order the daemon sent them), WXSKY_AGAIN when none is complete yet, WXSKY_ECLOSED when the
 * daemon hung up (or the client is not connected), WXSKY_EFORMAT for bytes that are not the
 * protocol, WXSKY_ENOSPC for a message larger than the receive buffer (both close the
 * connection: a msgpack stream cannot be resynchronised). Each call reads the socket until one
 * message is complete or the socket is empty, and sends pending requests first. Every response
 * is returned, including late ones whose msgid the host no longer waits for (§2.3: discard
 * those), and the daemon's nil-msgid error before it hangs up (has_msgid 0). Requests from the
 * daemon, which §2.4 says do not occur, are skipped. */
int wxsky_client_poll(wxsky_client *c, wxsky_message *msg);
/* Blocking: waits up to timeout_ms (< 0: for ever) for the response to `msgid`, queueing
 * every other message that arrives meanwhile (the oldest dropped when the queue is full).
 * WXSKY_OK with *response (may be NULL), WXSKY_EREMOTE when the daemon answered with an error
 * (its message in wxsky_client_error and in response->error; a nil-msgid error, after which
 * the daemon hangs up, also ends the wait, and closes the client), WXSKY_ETIMEDOUT (the
 * response, when it comes, is then returned by poll), WXSKY_ECLOSED, WXSKY_EFORMAT. */
int wxsky_client_wait(wxsky_client *c, uint32_t msgid, int timeout_ms, wxsky_message *response);
/* wxsky_client_request then wxsky_client_wait; the timeout covers both (a full socket is
 * waited for too). */
int wxsky_client_call(wxsky_client *c, const char *method, const uint8_t *params_msgpack,
                      size_t params_len, int timeout_ms, wxsky_message *response);

/* ---------------------------------------------------------------------------------------
 * Zero-copy textures (protocol §6): the daemon's layer textures as dma-bufs, where its GPU
 * driver exports them, passed over the unix socket (SCM_RIGHTS) with the export_textures
 * answer. The GL compositor imports them (wxsky_gl_import_textures); everywhere else a host
 * keeps reading the segment, which needs no configuration.
 * ------------------------------------------------------------------------------------- */

#define WXSKY_TEXTURE_PLANES 4                    /* EGL_EXT_image_dma_buf_import_modifiers */
#define WXSKY_TEXTURES_MAX (2 * WXSKY_MAX_LAYERS) /* one per layer per segment slot */
#define WXSKY_TEXTURE_FDS_MAX 253                 /* Linux SCM_MAX_FD */
#define WXSKY_DRM_FORMAT_MOD_INVALID 0x00ffffffffffffffull

typedef struct wxsky_texture_plane {
    int fd; /* one of wxsky_textures.fds (several planes may share one) */
    uint32_t stride;
    uint32_t offset;
} wxsky_texture_plane;

typedef struct wxsky_texture {
    char layer[WXSKY_LAYER_NAME_MAX + 1]; /* the segment layer it holds, NUL-terminated */
    uint32_t slot;                        /* the segment slot (0 or 1) whose frame it holds */
    uint32_t width, height;               /* the texture: the layer's capacity */
    uint32_t fourcc;                      /* DRM fourcc: 'AB24' (ABGR8888) = RGBA8 in memory */
    uint64_t modifier;                    /* DRM format modifier (MOD_INVALID: implicit) */
    uint32_t plane_count;                 /* 1..WXSKY_TEXTURE_PLANES */
    wxsky_texture_plane planes[WXSKY_TEXTURE_PLANES];
} wxsky_texture;

typedef struct wxsky_textures {
    int supported;                /* 1: textures and fds below; 0: use the segment (reason) */
    char reason[WXSKY_ERROR_MAX]; /* the daemon's reason when not supported */
    uint32_t slot_count;
    uint32_t count;
    wxsky_texture textures[WXSKY_TEXTURES_MAX];
    int fds[WXSKY_TEXTURE_FDS_MAX]; /* owned: wxsky_textures_close closes them */
    uint32_t fd_count;
} wxsky_textures;

/* An empty set (no fds): call before the first request, so close is always safe. */
void wxsky_textures_init(wxsky_textures *t);
/* Closes the fds (an importer may close them once imported: EGL keeps its own reference)
 * and empties the set; NULL is fine. */
void wxsky_textures_close(wxsky_textures *t);

/* Sends export_textures on a unix-socket client and waits up to timeout_ms for the answer
 * and its descriptors. Closes what *out held first. WXSKY_OK: out->supported 1 with
 * out->count textures and out->fd_count fds (the caller's), or out->supported 0 with the
 * daemon's reason (no textures on this GPU, or a tcp connection): use the segment.
 * WXSKY_EREMOTE: the daemon answered with an error (one that predates the command says
 * "unknown command"): use the segment too. WXSKY_EFORMAT: an answer not in §6's shape;
 * WXSKY_ESYS: the descriptors the answer announces did not all arrive (the message says how
 * many did); WXSKY_ENOSPC: more than WXSKY_TEXTURES_MAX textures; otherwise as
 * wxsky_client_call. On any result but WXSKY_OK with supported 1, *out holds no fds. */
int wxsky_request_textures(wxsky_client *c, int timeout_ms, wxsky_textures *out);

#ifdef __cplusplus
}
#endif

#endif /* WXSKY_HOST_H */
