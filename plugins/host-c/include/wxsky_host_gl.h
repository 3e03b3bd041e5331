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
 *     (the host draws its opaque terrain and scenery, writing depth: optional, see below;
 *      wxsky_gl_shadow_bind(gl, terrain_program, unit) darkens it under the clouds)
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
/* 2: the cloud-shadow map (wxsky_gl_shadow*); 3: HDR layers (RGBA16F textures,
 * wxsky_gl_layer_format, wxsky_gl_tone_map, WXSKY_GL_DISPLAY_GLSL); 4: the tone curve's toe
 * of slope 1 (the daemon's since issue 41's last change); 5: wxsky_gl_draw_near_at and the
 * `near_depth` layer */
#define WXSKY_HOST_GL_VERSION_MINOR 5

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
 * The segment must have `sky`, `near` and `ring_0` .. `ring_7`; `near_front`,
 * `ring_in_0` .. `ring_in_7` and `shadow` are used when present; every ring layer must have ring_0's
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
 * differs from the last upload's, or after wxsky_gl_invalidate; `shadow` likewise by
 * rec->shadow_version (see wxsky_gl_shadow). Layers are matched by the
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
/* `near` full-screen at its clouds' depth, with the depth test (LEQUAL, no depth write), so
 * the host's geometry (drawn first, writing depth) stays in front of the clouds behind it and
 * the clouds in front of it cover it. Where the segment has the `near_depth` layer (the
 * daemon's [output] near_depth, protocol §1.5), each pixel goes at the distance of the nearest
 * cloud that layer holds about it, along the pixel's ray under the last
 * wxsky_gl_draw_background's projection; elsewhere (no such layer, or a pixel it holds none
 * for: a tower, rain, fog) at the plane `distance_m` in front of the eye. Give the `frame`
 * notification's `near_distance_m` (protocol §4: nothing the layer holds is nearer; 0 in
 * cloud, fog or rain at the eye). Nearer than the near plane: in front of everything. WXSKY_OK;
 * WXSKY_EINVAL (as wxsky_gl_draw_near, or a distance not >= 0); WXSKY_ESYS (a GL error). */
int wxsky_gl_draw_near_at(wxsky_gl_compositor *comp, double distance_m);
/* `near_front` full-screen, when the last upload had it (else nothing is drawn, WXSKY_OK). */
int wxsky_gl_draw_near_front(wxsky_gl_compositor *comp);

/* Zero-copy textures (protocol §6). Where the daemon exports its layer textures
 * (wxsky_request_textures gave supported 1) and this EGL display and GL context import
 * dma-bufs, the frame's pixels never pass through the CPU:
 *
 *     wxsky_request_textures(client, 2000, &tex);        // once, on a unix-socket client
 *     if (st == WXSKY_OK && tex.supported &&
 *         wxsky_gl_import_textures(gl, seg, &tex, eglGetCurrentDisplay(),
 *                                  (wxsky_gl_get_proc)eglGetProcAddress) == WXSKY_OK)
 *         zero_copy = 1;                                 // else: the segment, as before
 *     wxsky_textures_close(&tex);                        // EGL keeps its own references
 *     per frame: wxsky_frame_begin(seg, &view);  wxsky_record_decode(view.meta, ...);
 *                wxsky_gl_import_view(gl, &view, &rec);  // GPU copies, then a fence wait
 *                if (wxsky_frame_end(seg, &view) == WXSKY_ETORN) { wxsky_gl_invalidate(gl);
 *                    try again }                         // then draw as usual
 *
 * The daemon keeps one texture per layer per segment slot and fills the slot's textures
 * before it publishes the slot (glFinish first); wxsky_gl_import_view copies the view's
 * slot textures into the compositor's own (glCopyTexSubImage*, the ring layers only when
 * ring_version changed, as an upload) and waits for those copies (glFenceSync +
 * glClientWaitSync), so the seqlock check after it covers every byte the host took, and
 * the composite then reads the host's own textures while the daemon draws on. */
typedef void (*wxsky_gl_proc)(void);
typedef wxsky_gl_proc (*wxsky_gl_get_proc)(const char *name);

/* Imports every texture of `tex` that holds a layer this compositor draws, for both slots,
 * as EGLImages (EGL_LINUX_DMA_BUF_EXT) bound to GL textures (glEGLImageTargetTexture2DOES),
 * after checking at run time that the display has EGL_EXT_image_dma_buf_import (and
 * _modifiers for a texture with a modifier) and the context GL_OES_EGL_image. `egl_display`
 * is the EGLDisplay of the current context, `get_proc` eglGetProcAddress (so this library
 * links no EGL). The fds stay the caller's. WXSKY_OK; WXSKY_EINVAL (not initialised, NULL,
 * tex not supported); WXSKY_EFORMAT (an extension or entry point missing, a texture not at
 * its layer's capacity, a layer without a texture: the message names it); WXSKY_ESYS (an
 * EGL or GL call failed: the EGL error code). On failure nothing stays imported and the
 * compositor uploads from the segment as before. Changes the GL_TEXTURE_2D binding of
 * unit 0; the read framebuffer binding is restored. */
int wxsky_gl_import_textures(wxsky_gl_compositor *comp, const wxsky_segment *seg,
                             const wxsky_textures *tex, void *egl_display,
                             wxsky_gl_get_proc get_proc);
/* The zero-copy upload of a view (wxsky_frame_begin): copies its slot's imported textures
 * into the compositor's and waits for the copies; then wxsky_frame_end decides (WXSKY_ETORN:
 * wxsky_gl_invalidate and take the frame again). WXSKY_OK; WXSKY_EINVAL (nothing imported,
 * NULL, a layer beyond its capacity); WXSKY_ESYS (a GL error, or the copies not done in
 * 1 s). Changes the unit 0 texture bindings; the read framebuffer binding is restored. */
int wxsky_gl_import_view(wxsky_gl_compositor *comp, const wxsky_frame_view *view,
                         const wxsky_record *rec);
/* 1 after a successful wxsky_gl_import_textures, until released (or re-initialised). */
int wxsky_gl_zero_copy(const wxsky_gl_compositor *comp);
/* Drops the imported textures (back to uploads from the segment). */
void wxsky_gl_release_textures(wxsky_gl_compositor *comp);

/* The cloud-shadow map (protocol §1.5 `shadow`, §3.3) for the host's terrain shader. The
 * compositor keeps it in a texture of its own (GL_TEXTURE_2D, RGBA8, LINEAR, CLAMP_TO_EDGE,
 * at the layer's capacity; made by wxsky_gl_init when the segment has a `shadow` layer),
 * uploaded by wxsky_gl_upload_* only when the record's shadow_version changes (or after
 * wxsky_gl_invalidate); the placement comes from the last uploaded record, whose centre
 * moves every frame with the clouds.
 *
 * The host pastes WXSKY_GL_SHADOW_GLSL into its terrain's fragment (or vertex) shader, after
 * its #version and precision lines (GLSL 3.30 core or ES 3.00), and calls
 * wxsky_shadow(world_m): world_m in the record's coordinates (east, north, up metres MSL
 * around the observer, protocol §0). It returns T, 0 (full shadow) .. 1 (none): 1 where the
 * frame has no map, outside the map, or with the sun at or below the horizon. Light with it,
 * e.g. colour = albedo * (ambient + (1 - ambient) * T * max(0, dot(n, sun))), sun the
 * record's sun_direction_enu (not the map's). Each frame, with the program bound or not,
 * wxsky_gl_shadow_bind sets the uniforms; a host that sets uniforms its own way reads them
 * from wxsky_gl_shadow. The function is exactly the reference host's
 * (wxsky/host/compositor.py, ShadowMap.transmittance), down to GL's bilinear weights. */
#define WXSKY_GL_SHADOW_GLSL                                                                   \
    "uniform sampler2D wxsky_shadow_map;\n"                                                    \
    "uniform vec4 wxsky_shadow_rect;   /* west edge east_m, north edge north_m, 1/size_m, "     \
    "present */\n"                                                                             \
    "uniform vec4 wxsky_shadow_sun;    /* the map's sun (unit, ENU), its plane's up_m */\n"     \
    "uniform vec4 wxsky_shadow_texels; /* used width, height; texture width, height */\n"      \
    "float wxsky_shadow(vec3 p) {\n"                                                           \
    "    vec3 s = wxsky_shadow_sun.xyz;\n"                                                     \
    "    if (wxsky_shadow_rect.w == 0.0 || !(s.z > 0.0)) return 1.0;\n"                        \
    "    vec2 q = p.xy + s.xy * ((wxsky_shadow_sun.w - p.z) / s.z);\n"                         \
    "    vec2 f = vec2(q.x - wxsky_shadow_rect.x, wxsky_shadow_rect.y - q.y) * "               \
    "wxsky_shadow_rect.z;\n"                                                                   \
    "    if (f.x < 0.0 || f.x > 1.0 || f.y < 0.0 || f.y > 1.0) return 1.0;\n"                  \
    "    vec2 px = clamp(f * wxsky_shadow_texels.xy, vec2(0.5), wxsky_shadow_texels.xy - 0.5);\n" \
    "    return texture(wxsky_shadow_map, px / wxsky_shadow_texels.zw).r;\n"                    \
    "}\n"

/* The uniforms of WXSKY_GL_SHADOW_GLSL for the last uploaded frame. */
typedef struct wxsky_gl_shadow_params {
    unsigned int texture; /* the GL texture name (GL_TEXTURE_2D); 0: the segment has no map */
    int present;          /* 1: the last frame had a map; 0: wxsky_shadow gives 1 */
    float rect[4];        /* wxsky_shadow_rect */
    float sun[4];         /* wxsky_shadow_sun */
    float texels[4];      /* wxsky_shadow_texels */
} wxsky_gl_shadow_params;

/* Fills *out (zeros, present 0, when nothing was uploaded yet: then WXSKY_EINVAL). Needs no
 * GL context. WXSKY_OK; WXSKY_EINVAL (NULL, not initialised, no frame uploaded). */
int wxsky_gl_shadow(const wxsky_gl_compositor *comp, wxsky_gl_shadow_params *out);
/* Binds the map's texture to texture unit `unit` and sets the four uniforms in `program` (the
 * host's, linked with WXSKY_GL_SHADOW_GLSL; uniforms the linker dropped are skipped). Leaves
 * `program` in use (glUseProgram), the texture bound to `unit`, and GL_TEXTURE0 active.
 * WXSKY_OK; WXSKY_EINVAL (not initialised, no frame uploaded, program 0, a unit outside
 * GL_MAX_COMBINED_TEXTURE_IMAGE_UNITS); WXSKY_ESYS (a GL error: e.g. not a program). */
int wxsky_gl_shadow_bind(wxsky_gl_compositor *comp, unsigned int program, int unit);

/* HDR layers (protocol §1.2: a segment whose picture layers are RGBA16F, the daemon's
 * [output] layer_format = "rgba16f"; docs/linear-output.md). wxsky_gl_init makes the
 * textures GL_RGBA16F and the uploads take GL_HALF_FLOAT; the draws are the same, so they
 * composite scene-linear colour with the same blending. Draw them into a float colour
 * buffer (GL_RGBA16F or GL_RGBA32F: an 8-bit one would clip at 1), then show that composite
 * once through the daemon's exposure and tone map: wxsky_gl_tone_map, or the host's own
 * post-processing with WXSKY_GL_DISPLAY_GLSL in it (it may apply its own tone map instead:
 * the layers are before any). The exact answer to the approximation the 8-bit layers make
 * (each fragment tone-mapped, then blended: docs/linear-output.md). */

/* WXSKY_FORMAT_RGBA8 or WXSKY_FORMAT_RGBA16F: the picture layers' format (the segment's
 * sky, near, near_front and ring layers share one; wxsky_gl_init refuses a segment where
 * they do not, and a shadow map other than RGBA8); -1 when not initialised. */
int wxsky_gl_layer_format(const wxsky_gl_compositor *comp);

/* Draws `linear_texture` (the host's GL_TEXTURE_2D holding the linear composite, one texel a
 * pixel of the current viewport, texel (0, 0) at the viewport's corner) into the current
 * framebuffer through wxsky_display (WXSKY_GL_DISPLAY_GLSL) at `exposure` (the scale on
 * scene-linear colour: 2^EV, 1 is the daemon's EV 0), opaque, without blending or depth.
 * Leaves GL_BLEND and GL_DEPTH_TEST disabled, the depth mask GL_FALSE, the compositor's
 * program and vertex array bound and the texture on unit 0. WXSKY_OK; WXSKY_EINVAL (not
 * initialised, texture 0, exposure not positive and finite); WXSKY_ESYS (a GL error). */
int wxsky_gl_tone_map(wxsky_gl_compositor *comp, unsigned int linear_texture, float exposure);

/* GLSL (3.30 core or ES 3.00; paste after the #version and precision lines): vec3
 * wxsky_display(vec3 linear, float exposure), the daemon's display transform
 * (wxsky/scene/exposure.py `display`, the host kit's wxsky_display): Narkowicz's ACES fit on
 * the largest channel, the colour scaled alike, burnt toward white past the curve's white
 * (exposure.py `burn`), then the sRGB encoding. */
#define WXSKY_GL_DISPLAY_GLSL                                                                  \
    "vec3 wxsky_display(vec3 linear, float exposure) {\n"                                     \
    "    vec3 c = max(linear * exposure, vec3(0.0));\n"                                       \
    "    float m = max(c.r, max(c.g, c.b));\n"                                                \
    "    if (!(m > 0.0)) return vec3(0.0);\n"                                                 \
    "    float y = clamp(m * (2.51 * m + 0.14) / (m * (2.43 * m + 0.70) + 0.14), 0.0, 1.0);\n" \
    "    float b = clamp((m / 7.241657386773973 - 1.0) / 3.0, 0.0, 1.0);\n"                   \
    "    vec3 t = clamp(mix(c * (y / m), vec3(y), 0.9 * b * b * (3.0 - 2.0 * b)), 0.0, 1.0);\n" \
    "    return mix(12.92 * t, 1.055 * pow(t, vec3(1.0 / 2.4)) - 0.055, "                     \
    "step(vec3(0.0031308), t));\n"                                                           \
    "}\n"

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
