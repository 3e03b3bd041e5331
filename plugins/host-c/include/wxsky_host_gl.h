/*
 * wxsky_host_gl.h - the wxsky host kit's GL compositor: draws a frame's layers into the
 * host's framebuffer (docs/protocol.md §0), with the host's depth buffer and matrices.
 *
 * A separate library, libwxsky_host_gl (link it before libwxsky_host, and with -lGL, or
 * -lGLESv2 for a GLES build), so that hosts without GL need not link GL or EGL. OpenGL 3.3
 * core; the same source builds for OpenGL ES 3.0 with -DWXSKY_GL_ES (only the shaders'
 * version line and precision change). C99, no global state: every compositor carries its own
 * last error message. wxsky_gl_new allocates the object, wxsky_gl_init (and
 * wxsky_gl_set_streaming) the GL objects; the per-frame path allocates nothing (the streaming
 * uploads re-specify their buffers' storage each frame, the usual orphaning).
 *
 * Every function but wxsky_gl_new and wxsky_gl_error needs the host's GL context current, the
 * one wxsky_gl_init ran in (or one sharing its objects). A compositor is used by one thread at
 * a time.
 *
 * Per frame:
 *     wxsky_frame_read(seg, &copy, ...);  wxsky_record_decode(copy.meta, ..., &rec, ...);
 *     wxsky_gl_upload_copy(gl, &copy, &rec);      // only the layers that changed
 *     (the host draws its opaque terrain and scenery, writing depth: optional, see below)
 *     wxsky_gl_draw_background(gl, view, proj);   // sky, then the ring with its cross-fade
 *     wxsky_gl_draw_near(gl);
 *     (the host draws its own aircraft)
 *     wxsky_gl_draw_near_front(gl);
 *
 * Depth: the background writes no depth. The sky is drawn at the far plane and the ring
 * images at their quads' true depth, both with the depth test (LEQUAL) against the host's
 * depth buffer. So a host that draws its opaque geometry first (writing depth) gets the sky
 * only where it drew nothing, far ring clouds hidden by nearer terrain and nearer ring clouds
 * blended over farther terrain; a host that draws its geometry after the background simply
 * covers it. `near` and `near_front` are drawn full-screen without the depth test, as §0 says.
 * The depth written by the ring pass is the hit point's depth under the host's projection and
 * the default depth range (0..1, nearer smaller, cleared to 1): a reversed-Z host (GL_GREATER)
 * is not supported yet.
 *
 * Blending: every layer is premultiplied "over" (ONE, ONE_MINUS_SRC_ALPHA). GL state left
 * by each draw: GL_BLEND enabled with that function and GL_FUNC_ADD, the depth mask GL_FALSE,
 * GL_CULL_FACE disabled (the scissor test and stencil untouched), GL_DEPTH_TEST enabled
 * with GL_LEQUAL (background) or disabled (near, near_front); the compositor's program, vertex
 * array and textures (units 0 and 1) bound. Uploads change the GL_UNPACK_* pixel-store state
 * (row length 0, alignment 4, skips 0) and the textures bound to unit 0, and unbind
 * GL_PIXEL_UNPACK_BUFFER.
 *
 * GL errors: each call fetches the pending GL errors (glGetError) when it is done and returns
 * WXSKY_ESYS with the first code in its message; an error the host raised before the call and
 * did not fetch is reported so too (the compositor never discards it unseen).
 */
#ifndef WXSKY_HOST_GL_H
#define WXSKY_HOST_GL_H

#include <stdint.h>

#include "wxsky_host.h"

#ifdef __cplusplus
extern "C" {
#endif

/* The GL compositor's API version: MAJOR changes break source compatibility. */
#define WXSKY_HOST_GL_VERSION_MAJOR 0
#define WXSKY_HOST_GL_VERSION_MINOR 1

/* Runtime version of the GL library, (MAJOR << 16) | MINOR, to compare with the header's. */
uint32_t wxsky_gl_version(void);

/* The camera model of the frame record (wxsky/scene/camera.py, protocol §3). */
#define WXSKY_GL_NEAR_M 2.0
#define WXSKY_GL_FAR_M 200000.0

typedef struct wxsky_gl_compositor wxsky_gl_compositor;

/* A compositor with no GL objects yet (needs no GL context). NULL only when out of memory. */
wxsky_gl_compositor *wxsky_gl_new(void);
/* Deletes its GL objects (the context it was initialised in must be current, unless it was
 * never initialised) and frees it; NULL is fine. */
void wxsky_gl_free(wxsky_gl_compositor *comp);
/* The last error message ("" after success). Never NULL. */
const char *wxsky_gl_error(const wxsky_gl_compositor *comp);

/* Compiles the shaders and makes one texture per layer, sized to the layer's capacity, for
 * the open segment `seg` (only its layer table is read: the segment may be closed afterwards).
 * The segment must have `sky`, `near` and `ring_0` .. `ring_7`; `near_front` and
 * `ring_in_0` .. `ring_in_7` are used when present; every ring layer must have ring_0's
 * capacity. Other layers are ignored. Initialising again (e.g. for a reopened segment with
 * other capacities) first deletes the old objects. WXSKY_OK; WXSKY_EINVAL (NULL, a segment
 * not open); WXSKY_EFORMAT (a layer missing, ring capacities that differ, a capacity above
 * GL_MAX_TEXTURE_SIZE / GL_MAX_ARRAY_TEXTURE_LAYERS); WXSKY_ESYS (a shader that does not
 * compile or link, a GL error: the message has the GL log). On error the compositor is left
 * uninitialised. */
int wxsky_gl_init(wxsky_gl_compositor *comp, const wxsky_segment *seg);

/* Uploads a frame and keeps its record (a struct copy) for the draws that follow. `sky`,
 * `near` and `near_front` are uploaded every time (a layer of width 0 is then not drawn);
 * the ring layers (ring_i, and ring_in_i while `rec->fading`) only when rec->ring_version
 * differs from the last upload's, or after wxsky_gl_invalidate. Layers are matched by the
 * indices of the segment given to wxsky_gl_init. WXSKY_OK; WXSKY_EINVAL (not initialised,
 * NULL, a layer larger than its capacity); WXSKY_ESYS (a GL error).
 *
 * From a copy (wxsky_frame_read): a layer whose buffer is NULL is not uploaded (its texture
 * keeps what it had; for ring layers, copy all of them or none). */
int wxsky_gl_upload_copy(wxsky_gl_compositor *comp, const wxsky_frame_copy *copy,
                         const wxsky_record *rec);
/* From a zero-copy view (wxsky_frame_begin): when wxsky_frame_end then says WXSKY_ETORN, the
 * textures may hold torn pixels: call wxsky_gl_invalidate, so the next upload sends every
 * layer again. */
int wxsky_gl_upload_view(wxsky_gl_compositor *comp, const wxsky_frame_view *view,
                         const wxsky_record *rec);
/* pbo 1: stream the full-screen layers (sky, near, near_front: uploaded every frame) through
 * one pixel-unpack buffer each (orphaned with glBufferData, filled with glMapBufferRange,
 * then glTexSubImage2D from the buffer), so a GPU driver can copy them to the texture
 * asynchronously instead of stalling the upload; the ring layers, uploaded rarely, go
 * directly. pbo 0 (the default): every layer by glTexSubImage* from client memory. May be
 * called before or after wxsky_gl_init (after: the buffers are made or deleted now, so the
 * context must be current). WXSKY_OK; WXSKY_EINVAL; WXSKY_ESYS (a GL error). */
int wxsky_gl_set_streaming(wxsky_gl_compositor *comp, int pbo);
/* Makes the next upload send the ring layers whatever their ring_version. */
void wxsky_gl_invalidate(wxsky_gl_compositor *comp);

/* Draws `sky` full-screen then the ring (the 8 ring_i images on the record's quads; while
 * fading, (1 - ring_fade) x those + ring_fade x the ring_in_i images on the incoming quads),
 * into the current framebuffer and viewport, for the host's view and projection matrices
 * (column-major, as glUniformMatrix4fv takes them without transposing; world coordinates
 * east-north-up metres, §0). The full-screen layers are stretched over the viewport; when
 * proj[5] (row 1, column 1) is negative the projection flips y (as the record's camera model
 * does, wxsky_gl_camera_matrices with flip_y 1) and the layers' top row goes to framebuffer
 * row 0, otherwise to the viewport's top. WXSKY_OK; WXSKY_EINVAL (not initialised, no frame
 * uploaded, NULL, a matrix that is not invertible or not finite); WXSKY_ESYS (a GL error). */
int wxsky_gl_draw_background(wxsky_gl_compositor *comp, const double view[16],
                             const double proj[16]);
/* `near` full-screen, oriented as the last wxsky_gl_draw_background said. */
int wxsky_gl_draw_near(wxsky_gl_compositor *comp);
/* `near_front` full-screen, when the last upload had it (else nothing is drawn, WXSKY_OK). */
int wxsky_gl_draw_near_front(wxsky_gl_compositor *comp);

/* The view and projection matrices (column-major) of a record's camera, exactly as
 * wxsky/scene/camera.py makes them: near WXSKY_GL_NEAR_M, far WXSKY_GL_FAR_M, horizontal
 * fov_deg, aspect width_px / height_px. flip_y 1: y flipped, so framebuffer row 0 is the
 * image's top row (what glReadPixels gives in the layers' row order: for offscreen use);
 * flip_y 0: the usual GL orientation (for a window). */
void wxsky_gl_camera_matrices(const wxsky_record *rec, int flip_y, double view[16],
                              double proj[16]);

#ifdef __cplusplus
}
#endif

#endif /* WXSKY_HOST_GL_H */
