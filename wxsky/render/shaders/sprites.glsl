// Cloud sprites (Wang), instanced, drawn back to front, premultiplied alpha. Most face the
// camera; a sprite with a normal keeps that orientation (a flat cirrus sheet, or a sprite
// whose facing locked while the camera is inside it) and fades as the eye sees it edge-on.
// Sprite centres arrive relative to the eye so float32 keeps centimetre precision.
//
// ROUND_MIX 1 blends a flat-bottomed sprite into the round one with a second texture read per
// fragment; llvmpipe pays for that read in every fragment of a draw whatever the branch says,
// so the renderer draws only the few sprites half-way through that turn with it, and all
// others with ROUND_MIX 0: one read, of the round texture where the turn is complete.

#if defined VERTEX_SHADER
in vec2 in_corner;        // per vertex: 8 unused (the polygon's), then a quad's corners
in vec3 in_centre;        // per instance: centre minus eye, metres (ENU)
in float in_size;
in float in_rotation;
in float in_texture;
in vec4 in_rgba;
in vec3 in_normal;        // ENU unit normal, or zero: face the camera
in vec3 in_rim;           // display colour of the thin outer texels (SpriteDraw.rgba's
                          // rim), or negative: none (the texel's own colour to the edge)
uniform mat3 u_view_rot;
uniform mat4 u_proj;
// Per sheet slot, and last for a flat-bottomed sprite part-way to the round one, the convex
// polygon (8 corners as a triangle strip, 1 = half a cell, two to a vec4) outside which its
// texture is transparent, and its bounding box: a sprite covers only that, so no fragment is
// spent on empty texels (sprite_sheet.support_polygons). The polygons come in two sets: for
// sprites at least FINE_MIN_PX across, which read the finer levels, and for smaller ones,
// holding the halo of every level. Vertices 0-7 of a draw are the polygon's, 8-11 (in_corner)
// its box's.
#define TURNING_POLYGON (SHEET_CELLS * SHEET_CELLS)
#define POLYGONS (TURNING_POLYGON + 1)
uniform vec4 u_polygon[POLYGONS * 8];  // fine set, then coarse
uniform vec4 u_box[POLYGONS * 2];  // each set's bounding boxes: fine, then coarse
uniform float u_viewport_px;  // the target's width
// Per sheet slot, its mean shade (sprite_sheet.cell_shades): texels are divided by it, so a
// sprite's mean colour is the one its cloud was shaded and hazed to.
uniform float u_cell_shade[SHEET_CELLS * SHEET_CELLS];
out vec2 v_uv;
flat out float v_inv_shade;
#if ROUND_MIX
out vec2 v_round_uv;
out float v_round_mix;
#endif
out vec4 v_rgba;
flat out vec4 v_rim;  // rgb, and 1 where the sprite has a rim, else 0

vec2 cell_uv(float cell, vec2 local) {
    vec2 origin = vec2(mod(cell, float(SHEET_CELLS)), floor(cell / float(SHEET_CELLS)));
    return (origin + local * vec2(0.5, -0.5) + 0.5) / float(SHEET_CELLS);
}

// A quad's axes across its normal n: u level (the world's up across n), v up the quad; a
// lying quad (n straight up or down) takes east for u.
void quad_axes(vec3 n, out vec3 u, out vec3 v) {
    u = cross(vec3(0.0, 0.0, 1.0), n);
    float across = length(u);
    u = across > 1e-6 ? u / across : vec3(1.0, 0.0, 0.0);
    v = cross(n, u);
}

void main() {
    int slot = int(in_texture + 0.5);
    bool facing = dot(in_normal, in_normal) <= 0.25;
    // A flat-bottomed sprite paints a cloud's base seen from the side. Seen steeply from
    // below its straight edge is no base at all but a grey bar across the cloud, so it
    // turns into a round soft one (ROUND_SLOT) that still closes the base.
    float round_mix = 0.0;
    int polygon = slot;
    if (facing && slot == FLAT_BOTTOM_SLOT) {
        round_mix = smoothstep(ROUND_FROM, ROUND_TO,
                               abs(in_centre.z) / max(length(in_centre), 1e-3));
        // Turned at all, it is drawn as both textures' polygon (the round one alone would
        // cut what the flat one's larger disc let the coarse levels show).
        polygon = round_mix > 0.0 ? TURNING_POLYGON : slot;
    }
    // Across the picture, the sprite is this many pixels (less, seen obliquely).
    float across = 0.5 * u_viewport_px * u_proj[0][0] * in_size / max(length(in_centre), 1.0);
    if (!facing) {
        across *= abs(dot(normalize(in_normal), normalize(in_centre)));
    }
    bool fine = across >= FINE_MIN_PX;
    vec2 local;
    if (gl_VertexID < 8) {
        int corner = (fine ? 0 : POLYGONS * 8) + polygon * 8 + gl_VertexID;
        vec4 pair = u_polygon[corner / 2];
        local = (corner % 2 == 0) ? pair.xy : pair.zw;
    } else {
        vec4 box = u_box[(fine ? 0 : POLYGONS) + polygon];
        local = mix(box.xy, box.zw, in_corner * 0.5 + 0.5);
    }
    float s = sin(in_rotation), k = cos(in_rotation);
    vec2 corner = mat2(k, s, -s, k) * local;
    vec3 c;
    float alpha = in_rgba.a;
    if (!facing) {
        // Spanned across the normal as a facing sprite is (quad_axes), so a sprite whose
        // facing locks with the eye straight along its normal does not move.
        vec3 n = normalize(in_normal);
        vec3 u, v;
        quad_axes(n, u, v);
        vec3 world = in_centre + (corner.x * u + corner.y * v) * 0.5 * in_size;
        c = u_view_rot * world;
        // Seen edge-on a quad is a line: fade it by the angle to the eye (Wang's in-cloud rule).
        alpha *= abs(dot(n, normalize(-in_centre)));
    } else {
        // Face the eye point, upright (the world's up across the picture): the same quad in
        // the world whichever way a view from this eye looks, so display channels turned from
        // one camera meet without seams, and a rolled view does not roll the clouds' bases.
        vec3 u, v;
        quad_axes(-in_centre / max(length(in_centre), 1e-6), u, v);
        c = u_view_rot * (in_centre + (corner.x * u + corner.y * v) * 0.5 * in_size);
        // Sprites the eye is about to pass through fade out instead of filling the screen.
        float dist = length(u_view_rot * in_centre);
        alpha *= smoothstep(0.1 * in_size, 0.6 * in_size, dist);
    }
    gl_Position = u_proj * vec4(c, 1.0);
#if ROUND_MIX
    v_uv = cell_uv(in_texture, local);
    v_round_uv = cell_uv(float(ROUND_SLOT), local);
    v_round_mix = round_mix;
#else
    // Only sprites whose turn is none (0) or complete (1) come here.
    v_uv = cell_uv(round_mix > 0.5 ? float(ROUND_SLOT) : in_texture, local);
#endif
    int shown = round_mix > 0.5 ? ROUND_SLOT : slot;
#if ROUND_MIX
    v_inv_shade = 1.0 / mix(u_cell_shade[slot], u_cell_shade[ROUND_SLOT], round_mix);
#else
    v_inv_shade = 1.0 / u_cell_shade[shown];
#endif
    v_rgba = vec4(in_rgba.rgb, alpha);
    v_rim = in_rim.r < 0.0 ? vec4(0.0) : vec4(in_rim, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
#include "display.glsl"
in vec2 v_uv;
#if ROUND_MIX
in vec2 v_round_uv;
in float v_round_mix;
#endif
in vec4 v_rgba;
flat in float v_inv_shade;
flat in vec4 v_rim;
uniform sampler2D u_sheet;
out vec4 f_colour;
void main() {
    vec4 t = texture(u_sheet, v_uv);
#if ROUND_MIX
    if (v_round_mix > 0.0) {
        t = mix(t, texture(u_sheet, v_round_uv), v_round_mix);
    }
#endif
    float a = t.a * v_rgba.a;
    // Most of a soft sprite is empty: skip the blend there (fill rate is what sprites cost).
    if (a < 1.0 / 512.0) {
        discard;
    }
    // A texel's opacity is how thick the cloud is there: the thinner, the more it shows the
    // light its sprite's centre is shaded without (the rim: the forward peak that the cloud
    // before the centre hides, which a silhouette's thin edge lets through).
    vec3 body = v_rgba.rgb * (t.rgb * v_inv_shade);
    f_colour = legacy_output(vec4(mix(body, v_rim.rgb, (1.0 - t.a) * v_rim.a) * a, a));
}
#endif
