// Cloud sprites (Wang), instanced, drawn back to front, premultiplied alpha. Most face the
// camera; a sprite with a normal keeps that orientation (a flat cirrus sheet, or a sprite
// whose facing locked while the camera is inside it) and fades as the eye sees it edge-on.
// Sprite centres arrive relative to the eye so float32 keeps centimetre precision.
//
// ROUND_MIX 1 blends a flat-bottomed sprite into the round one with a second texture read per
// fragment; llvmpipe pays for that read in every fragment of a draw whatever the branch says,
// so the renderer draws only the few sprites half-way through that turn with it, and all
// others with ROUND_MIX 0: one read, of the round texture where the turn is complete.
// DECK 1 draws a stratiform deck's sprites seen from under its base, with the base's relief;
// FLAT_BASE 1 heaped clouds' sprites, cut at and shaded toward their layer's flat base.
// NEAR_DEPTH 1 draws, instead of the colour, each fragment's distance from the eye (metres,
// in red) where the sprite shows at 8 bits (its alpha at least NEAR_DEPTH_ALPHA), for a MIN
// blend: the `near_depth` layer, the depth of the nearest cloud at each pixel of `near`.

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
#if FLAT_BASE
in float in_base;         // the flat base the sprite is cut at, metres over the eye
#endif
#if DECK
in vec3 in_deck;          // its deck's base, metres over the eye (the eye is under it), and
                          // the eye's east and north less the deck's drift (mod 64 km)
#endif
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
uniform float u_inv_haze_m;  // 1 / the haze distance the sprites' colours were faded with
uniform float u_inv_clear_haze_m;  // 1 / the clear air's, over the hazy layer's top
uniform float u_haze_top_up_m;  // the hazy layer's top over the eye (sky.haze_share)
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
#if FLAT_BASE
out float v_above_base_m;  // how far the quad's point is above its cloud's flat base
flat out float v_base_soft_m;  // over how many metres above the base the cut fades in
flat out float v_pixel_m;  // a pixel's size at the sprite, metres
flat out float v_base_depth_m;  // how far above the base the base's shadow reaches
flat out float v_base_dim;  // the shade at the base, its haze taken into account
#endif
flat out float v_haze;  // the share of the sprite's colour that is air (layout.hazed)
#if DECK
out vec3 v_ray;  // the quad's point, eye-relative (ENU): the ray the fragment is seen along
flat out vec3 v_deck;  // in_deck
#endif
#if NEAR_DEPTH
out float v_dist_m;  // the quad's point's distance from the eye
#endif

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
    float alpha = in_rgba.a;
    vec3 u, v;
    if (!facing) {
        // Spanned across the normal as a facing sprite is (quad_axes), so a sprite whose
        // facing locks with the eye straight along its normal does not move.
        vec3 n = normalize(in_normal);
        quad_axes(n, u, v);
        // Seen edge-on a quad is a line: fade it by the angle to the eye (Wang's in-cloud rule).
        alpha *= abs(dot(n, normalize(-in_centre)));
    } else {
        // Face the eye point, upright (the world's up across the picture): the same quad in
        // the world whichever way a view from this eye looks, so display channels turned from
        // one camera meet without seams, and a rolled view does not roll the clouds' bases.
        quad_axes(-in_centre / max(length(in_centre), 1e-6), u, v);
        // Sprites the eye is about to pass through fade out instead of filling the screen.
        float dist = length(u_view_rot * in_centre);
        alpha *= smoothstep(0.1 * in_size, 0.6 * in_size, dist);
    }
    vec3 world = in_centre + (corner.x * u + corner.y * v) * 0.5 * in_size;
#if FLAT_BASE
    v_above_base_m = world.z - in_base;
#endif
#if DECK
    v_ray = world;
#endif
#if NEAR_DEPTH
    v_dist_m = length(world);
#endif
    vec3 c = u_view_rot * world;
    gl_Position = u_proj * vec4(c, 1.0);
    // A sprite's colour is cloud x (1 - haze) + air x haze (layout.hazed): its texels' shade
    // and its base's darken the cloud's light, not the air's before it, so both fade by the
    // haze (aerial perspective takes a far cloud's detail, not only its colour).
    float lo = min(in_centre.z, 0.0);
    float hi = max(in_centre.z, 0.0);
    float below = clamp((u_haze_top_up_m - lo) / max(hi - lo, 1e-3), 0.0, 1.0);
    v_haze = 1.0 - exp(-length(in_centre)
                       * (below * u_inv_haze_m + (1.0 - below) * u_inv_clear_haze_m));
#if FLAT_BASE
    // Seen edge-on, every sprite's cut lies on one line: the cloud's flat base. Seen more
    // steeply, each cut is its own straight edge across the base's outline, so it softens
    // into the sprite's round lower half instead, as the angle goes from BASE_SOFT_FROM to
    // BASE_SOFT_TO (the way a flat-bottomed texture turns round).
    float steep = abs(in_centre.z) / max(length(in_centre), 1e-3);
    // A pixel's size at the sprite, in metres (a facing quad's both ways): the cut's
    // antialiasing, without a derivative per fragment.
    v_pixel_m = max(length(in_centre) / (0.5 * u_viewport_px * u_proj[0][0]), 1e-3);
    // Far, the base's ragged lowest metres average into a ramp (renderer.BASE_FEATHER_M).
    float feather_m = BASE_FEATHER_M * smoothstep(BASE_FEATHER_FROM_M, BASE_FEATHER_TO_M,
                                                  length(in_centre));
    v_base_soft_m = max(max(v_pixel_m, feather_m),
                        0.5 * in_size * smoothstep(BASE_SOFT_FROM, BASE_SOFT_TO, steep));
    v_base_depth_m = BASE_SHADE_DEPTH * in_size;
    // From below, the base is the cloud's underside, in the whole cloud's shadow; seen near
    // edge-on, what shows of it is the cloud's lower side, which the sun reaches sideways.
    float underside = smoothstep(BASE_DIM_FROM, BASE_DIM_TO, steep);
    v_base_dim = mix(mix(1.0, BASE_DIM, underside), 1.0, v_haze);
#endif
#if DECK
    v_deck = in_deck;
#endif
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
#if FLAT_BASE
in float v_above_base_m;
flat in float v_base_soft_m;
flat in float v_pixel_m;
flat in float v_base_depth_m;
flat in float v_base_dim;
#endif
flat in float v_haze;
#if DECK
in vec3 v_ray;
flat in vec3 v_deck;
#endif
#if NEAR_DEPTH
in float v_dist_m;
#endif
uniform sampler2D u_sheet;
out vec4 f_colour;
#if DECK
// Value noise in -1..1 on a unit lattice, smooth between its points: no tile repeats.
float lattice(vec2 q) {
    return fract(sin(dot(q, vec2(127.1, 311.7))) * 43758.5453) * 2.0 - 1.0;
}
float value_noise(vec2 p) {
    vec2 i = floor(p), f = fract(p);
    vec2 w = f * f * (3.0 - 2.0 * f);
    return mix(mix(lattice(i), lattice(i + vec2(1.0, 0.0)), w.x),
               mix(lattice(i + vec2(0.0, 1.0)), lattice(i + vec2(1.0, 1.0)), w.x), w.y);
}
// The deck's base as the eye sees it from below: where this fragment's ray meets the base's
// plane, a darker or lighter patch (thicker and thinner parts of the deck; DECK_SCALES_M,
// each weighed by DECK_RELIEF), in the deck's own frame, so every sprite of it shows the one
// relief and it drifts with the wind. Each scale fades out once a pixel spans a third of it,
// so nothing shimmers toward the horizon.
float deck_relief() {
    vec2 seen = v_ray.xy * (v_deck.x / max(v_ray.z, 1e-3));
    vec2 p = seen + v_deck.yz;
    float pixel_m = length(fwidth(seen));
    float n = 0.0;
    for (int k = 0; k < 3; k++) {
        float scale = DECK_SCALES_M[k];
        float keep = 1.0 - smoothstep(0.1 * scale, 0.33 * scale, pixel_m);
        // Each scale's lattice turned its own way, so no grid lines up across them.
        float a = 0.9 * float(k + 1);
        vec2 q = mat2(cos(a), sin(a), -sin(a), cos(a)) * p;
        n += DECK_RELIEF[k] * keep * value_noise(q / scale + 17.0 * float(k + 1));
    }
    return clamp(1.0 + n, 0.4, 1.6);  // a thick patch darkens the base, never blackens it
}
#endif
void main() {
    vec4 t = texture(u_sheet, v_uv);
#if ROUND_MIX
    if (v_round_mix > 0.0) {
        t = mix(t, texture(u_sheet, v_round_uv), v_round_mix);
    }
#endif
    // A heaped cloud's sprites end at its flat base, the condensation level, antialiased
    // over the pixel the base crosses (a round puff's lower half would hang below it), or
    // seen steeply, fading in over v_base_soft_m above it.
#if FLAT_BASE
    float a = t.a * v_rgba.a * clamp((v_above_base_m + 0.5 * v_pixel_m) / v_base_soft_m, 0.0, 1.0);
#else
    float a = t.a * v_rgba.a;
#endif
    // Most of a soft sprite is empty: skip the blend there (fill rate is what sprites cost).
    if (a < 1.0 / 512.0) {
        discard;
    }
#if NEAR_DEPTH
    if (a < NEAR_DEPTH_ALPHA) {
        discard;
    }
    f_colour = vec4(v_dist_m, 0.0, 0.0, 1.0);
    return;
#endif
    // A texel's opacity is how thick the cloud is there: the thinner, the more it shows the
    // light its sprite's centre is shaded without (the rim: the forward peak that the cloud
    // before the centre hides, which a silhouette's thin edge lets through).
    vec3 body = v_rgba.rgb * mix(t.rgb * v_inv_shade, vec3(1.0), v_haze);
#if DECK
    // A sprite of no deck drawn with this variant (renderer.MAX_VARIANT_RUNS) has none
    // (v_deck.x is 0); the branch is the same over each sprite, whose derivatives it takes.
    if (v_deck.x > 0.0) {
        body *= mix(deck_relief(), 1.0, v_haze);
    }
#endif
    // The lowest part of a flat-based cloud is in the shadow of all of it: darker toward the
    // base within each sprite, so the base is one dark band under the cloud, not the lit
    // lower halves of the puffs its cut ends (a sprite's own colour is one value).
    // (Not the rim: the silver lining is the sun's forward beam through the thin edge.)
#if FLAT_BASE
    body *= mix(v_base_dim, 1.0, clamp(v_above_base_m / v_base_depth_m, 0.0, 1.0));
#endif
    f_colour = legacy_output(vec4(mix(body, v_rim.rgb, (1.0 - t.a) * v_rim.a) * a, a));
}
#endif
