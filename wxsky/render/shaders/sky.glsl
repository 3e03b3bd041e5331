// Sky dome for one camera, after Roden & Parberry: the day gradient, blended by the darkness
// of the sky with a flickering star texture and a galaxy band; the sun and moon discs; and
// the thin cloud dome for high and distant cover. Full-screen triangle.
// Needs STAR_FACE_PX, STAR_JITTER, STAR_RATE_SCALE_HZ and the switches SKY_STARS, SKY_MOON,
// SKY_DOME, SKY_PHYSICAL, SKY_SUN, SKY_DECK (wxsky/render/sky_textures.py): llvmpipe runs
// both sides of every branch under a mask, so a feature a frame does not need is compiled
// out, not skipped. Where a feature does show, it usually covers a small part of the picture
// (the moon's disc, the distant cloud band above the horizon): the renderer draws the sky
// without it over the whole picture, then the variant with it over the rectangle where it can
// be seen (u_rect). Outside a feature the variants give the same colour, bit for bit, so only
// cost changes.
#include "common.glsl"
#include "display.glsl"

#if defined VERTEX_SHADER
#include "rect_quad.glsl"
#endif

#if defined FRAGMENT_SHADER
out vec4 f_colour;
#include "view_ray.glsl"
uniform float u_pixel_rad;
uniform vec3 u_sun_dir;
uniform vec3 u_zenith;
uniform vec3 u_horizon;
uniform vec3 u_ground;
uniform vec3 u_sun_rgb;
uniform float u_sun_cos_radius;
// Night sky
uniform float u_stars;            // 0 (day) .. 1 (clear astronomical night)
uniform mat3 u_celestial_from_enu;
uniform mat3 u_galactic_from_celestial;
uniform float u_star_clock_s;     // wraps where every star's sine repeats
uniform vec2 u_star_sigma_gain;   // Gaussian width (radians), brightness gain
uniform float u_star_floor;       // brightness lost to a not yet dark sky
uniform sampler2D u_star_tex;     // R mean, G flicker rate, B variance, A phase
uniform sampler2D u_galaxy_tex;
// Moon
uniform vec3 u_moon_dir;
uniform float u_moon_sin_radius;
uniform vec3 u_moon_rgb;
uniform vec3 u_earthshine_rgb;
// Cloud dome
uniform sampler2D u_dome_tex;     // R, G cloud shapes (R: maria too); B detail; A fibres
uniform sampler2D u_sunset_tex;   // tint at (sunset, sqrt(sin elevation)); clamped
uniform float u_dome_height_m;    // of the dome plane above the eye; 0 = none
uniform vec4 u_dome_controls;     // high cover, total cover, density, sunset
uniform vec2 u_dome_band;         // sin(elevation): distant cover full below x, none above y
uniform mat2 u_dome_m0;
uniform mat2 u_dome_m1;
uniform mat2 u_dome_m2;
uniform vec2 u_dome_off0;
uniform vec2 u_dome_off1;
uniform vec2 u_dome_off2;
uniform vec3 u_dome_rgb;          // cloud lit by sky and sun
uniform float u_dome_veil;        // cirrostratus cover: the milky film and the 22 deg halo
uniform vec3 u_moon_halo_dir;     // the moon, for its halo (toward it, unit)
uniform vec3 u_moon_halo_rgb;     // the moon's light on the veil, as u_sun_rgb is the sun's
uniform vec3 u_dome_haze_rgb;     // the air between the eye and the layer (SkyParams.haze_rgb)
uniform float u_haze_m;
uniform float u_haze_depth_m;     // of the dome's height, how much lies in the hazy layer
uniform float u_clear_haze_m;     // haze distance in the clear air above it
// Ground band (every variant): the eye's height over the ground under the observer (at least
// 0.5 m is taken), the haze distance over the ground, how much of the eye's height lies in the
// hazy layer, the clear air's haze distance.
uniform vec4 u_ground_air;
// The gradient sky's air at the horizon, where a layer reaches it (rgb: the dome's haze colour
// there; a: 1 when the dome's distant band is drawn, else 0 and the clear sky's horizon
// shows). The physical sky's is its baked table's (u_air_floor).
uniform vec4 u_horizon_air;
uniform vec3 u_ground_tint;       // the light on the ground, at the luminance of white

const float PI = 3.14159265358979;

#if SKY_PHYSICAL
// The physical atmosphere (wxsky/scene/atmosphere.py): radiance in kcd/m^2 from the sky-view
// table, the sun's disc and its aureole, then one exposure and tone map to the display.
uniform sampler2D u_sky_view;     // rows: sky_view_v (0.5 at the horizon); cols: 0..pi from the sun
uniform float u_sky_view_scale;   // the texture holds radiance / this (half floats)
uniform float u_horizon_rad;      // elevation of the horizon from the eye (<= 0)
uniform float u_sky_scale;        // kcd/m^2 -> display, set from Python (display_exposure)
uniform vec3 u_sun_radiance;      // at the disc's centre, transmitted to the eye, kcd/m^2
uniform float u_limb_darkening;
uniform vec4 u_aureole;           // rgb: strength (kcd/m^2 per unit phase), w: HG g
uniform float u_atmosphere_serial;  // changes with the table (the kept layer redraws)
uniform vec2 u_overcast;          // share of grey, dimming: cover above the eye (overcast_veil)

float hg_phase(float nu, float g) {
    float k = 1.0 + g * g - 2.0 * g * nu;
    return (1.0 - g * g) / (4.0 * PI * k * sqrt(k));
}

// The sky-view table's row for an elevation (atmosphere.sky_view_v): square-root rows about
// the horizon, so the horizon falls on a texel edge and stays sharp.
float sky_view_row(float el) {
    float h = u_horizon_rad;
    return el >= h ? 0.5 + 0.5 * sqrt(clamp((el - h) / (0.5 * PI - h), 0.0, 1.0))
                   : 0.5 - 0.5 * sqrt(clamp((h - el) / (h + 0.5 * PI), 0.0, 1.0));
}

// Scene-linear sky radiance along `ray`: the table, the aureole and the limb-darkened disc.
vec3 physical_sky(vec3 ray) {
    float el = asin(clamp(ray.z, -1.0, 1.0));
    float h = u_horizon_rad;
    float v = sky_view_row(el);
    vec2 flat_ray = normalize(ray.xy + vec2(1e-6, 0.0));
    vec2 flat_sun = normalize(u_sun_dir.xy + vec2(1e-6, 0.0));
    float u = acos(clamp(dot(flat_ray, flat_sun), -1.0, 1.0)) / PI;
    vec3 radiance = textureLod(u_sky_view, vec2(u, v), 0.0).rgb * u_sky_view_scale;
    float nu = dot(ray, u_sun_dir);
    float above = step(h, el);
    radiance += u_aureole.rgb * hg_phase(nu, u_aureole.w) * above;
    // The disc: anti-aliased edge as the gradient mode's, limb darkened.
    float disc = smoothstep(u_sun_cos_radius - 0.00002, u_sun_cos_radius + 0.00002, nu);
    float sin_r2 = 1.0 - u_sun_cos_radius * u_sun_cos_radius;
    float r2 = clamp((1.0 - nu * nu) / max(sin_r2, 1e-12), 0.0, 1.0);
    float limb = 1.0 - u_limb_darkening * (1.0 - sqrt(1.0 - r2));
    radiance += u_sun_radiance * (limb * disc * above);
    float grey = dot(radiance, vec3(0.2126, 0.7152, 0.0722));
    radiance = mix(radiance, vec3(grey), u_overcast.x) * u_overcast.y;
    return u_atmosphere_serial < 0.0 ? vec3(0.0) : radiance;
}

// Radiance (kcd/m^2) to display values at the atmosphere's exposure: display.glsl's one tone
// map (ACES on the largest channel, then sRGB), the curve the clouds' light is shown through
// too (scene/cloud_light.py), so a cloud as bright as the sky behind it shows as that sky.
// The layer's own exposure (u_exposure, [render] exposure) then applies in legacy_output.
vec3 display_from_scene(vec3 radiance) {
    return srgb_encode(tone_map(max(radiance, 0.0) * u_sky_scale));
}
#endif

#if SKY_PHYSICAL && !SKY_SCENE_LINEAR
// What the display variants show, baked per texel of the sky-view table (scene.sky
// display_sky_view: the table, the aureole at the table's sun, the overcast veil, the exposure
// and the tone map): one look-up a pixel instead of the tone map's powers and the aureole's
// phase in every pixel, which cost the physical sky 3.3 times the gradient's time on llvmpipe.
// Near the sun (SKY_SUN, the sun part's rectangle) the exact sky blends in.
uniform sampler2D u_sky_display;
uniform vec2 u_flat_sun;          // the sun's azimuth (east, north), unit
// The air the ground and the dome's band fade into: the sky no lower than this (sin
// elevation, and its table row): scene.sky.HAZE_MIN_ELEVATION_DEG over the horizon where a
// layer reaches it, else the eye's level (below it, that sky straight across); under a deck
// (z: scene.sky.deck_share) the dome fades toward that row at every elevation, the slab of
// haze under the deck (scene.sky `_sky_behind`): the ground's haze and the dome's are the
// sprites' air.
uniform vec3 u_air_floor;
uniform vec2 u_sun_exact;         // cos of the angles from the sun where the table takes over

// The baked sky along `ray`, below the air's floor the air straight across (`air`: what the
// ground and the dome fade into; the table holds no disc, so the haze holds none).
vec3 baked_sky(vec3 ray, out vec3 air) {
    float v = ray.z < u_air_floor.x ? u_air_floor.y : sky_view_row(asin(clamp(ray.z, -1.0, 1.0)));
    vec2 flat_ray = normalize(ray.xy + vec2(1e-6, 0.0));
    float u = acos(clamp(dot(flat_ray, u_flat_sun), -1.0, 1.0)) / PI;
    vec3 col = textureLod(u_sky_display, vec2(u, v), 0.0).rgb;
    // A new table or veil (a new bake) is a jump for the kept layer: both are compared.
    col = u_atmosphere_serial < 0.0 || u_overcast.y < 0.0 ? vec3(0.0) : col;
    air = col;
#if SKY_DOME && SKY_DECK
    // Only the dome reads the air over the floor (the ground band reads it below the eye's
    // level, where it is this row already), and only under a deck (u_air_floor.z > 0).
    vec3 slab = textureLod(u_sky_display, vec2(u, u_air_floor.y), 0.0).rgb;
    air = mix(air, slab, u_air_floor.z);
#endif
#if SKY_SUN
    // Round the sun, the exact sky (its disc and the aureole's core, which the table's
    // texels would facet), blended into the table's so the part's edge cannot show.
    float nu = dot(ray, u_sun_dir);
    if (nu > u_sun_exact.y && ray.z >= u_air_floor.x) {
        vec3 exact = display_from_scene(physical_sky(ray));
        col = mix(col, exact, smoothstep(u_sun_exact.y, u_sun_exact.x, nu));
    }
#endif
    return col;
}
#endif

#if SKY_STARS
// Celestial direction -> (face, continuous cell coordinates, face-plane coordinates) on
// the equi-angular cube map (sky_texture_gen.cube_cell_directions uses the same faces).
void cube_cell(vec3 c, out int face, out vec2 grid, out vec2 uv) {
    vec3 a = abs(c);
    if (a.x >= a.y && a.x >= a.z) {
        face = c.x > 0.0 ? 0 : 1;
        uv = c.yz / a.x;
    } else if (a.y >= a.z) {
        face = c.y > 0.0 ? 2 : 3;
        uv = c.xz / a.y;
    } else {
        face = c.z > 0.0 ? 4 : 5;
        uv = c.xy / a.z;
    }
    grid = (atan(uv) * (2.0 / PI) + 0.5) * float(STAR_FACE_PX);
}

// The stars near a celestial direction: the four cells whose centres surround it hold every
// star whose Gaussian can reach it (jitter plus three sigmas stay under one cell). Distances
// are measured in cells through the map's local metric (per pixel, not per star: a CPU
// renderer pays for every instruction of every pixel).
vec3 star_light(vec3 c, float galaxy, float up) {
    int face;
    vec2 grid, uv;
    cube_cell(c, face, grid, uv);
    // Radians per cell along each grid axis, and the cosine of the angle between the axes,
    // from the derivatives of normalize(1, tan a, tan b).
    vec2 sec2 = 1.0 + uv * uv;
    float norm2 = 1.0 + dot(uv, uv);
    vec2 per_cell = sec2 * sqrt(sec2.yx) / norm2 * (PI / 2.0 / float(STAR_FACE_PX));
    float shear = -uv.x * uv.y / sqrt(sec2.x * sec2.y);
    float inv_two_sigma2 = 0.5 / (u_star_sigma_gain.x * u_star_sigma_gain.x);
    ivec2 base = ivec2(floor(grid - 0.5));
    // Air twinkles stars more on a long slant path.
    float twinkle = 1.0 + (1.0 - up);
    vec3 sum = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        ivec2 cell = base + ivec2(k & 1, k >> 1);
        if (any(lessThan(cell, ivec2(0))) || any(greaterThanEqual(cell, ivec2(STAR_FACE_PX)))) {
            continue;
        }
        vec4 s = texelFetch(u_star_tex, ivec2(cell.x, face * STAR_FACE_PX + cell.y), 0);
        uint h = hash_u32(uint(cell.x) + hash_u32(uint(cell.y) + hash_u32(uint(face))));
        vec2 jitter = (vec2(hash_unit(h), hash_unit(h + 1u)) - 0.5) * (2.0 * STAR_JITTER);
        vec2 d = (grid - (vec2(cell) + 0.5 + jitter)) * per_cell;
        float dist2 = dot(d, d) + 2.0 * d.x * d.y * shear;
        float profile = exp(-dist2 * inv_two_sigma2);
        float phase = s.g * STAR_RATE_SCALE_HZ * u_star_clock_s + s.a;
        float brightness = s.r + s.b * twinkle * sin(2.0 * PI * phase);
        // Against a twilight or hazy sky the faint stars are lost first (and an empty cell,
        // all zeros, gives nothing).
        brightness = max(brightness - u_star_floor, 0.0);
        // Colour from blue-white to orange, most stars near white.
        float temp = hash_unit(h + 2u);
        vec3 tint = mix(vec3(1.0, 0.82, 0.66), vec3(0.82, 0.9, 1.0),
                        temp * temp * (3.0 - 2.0 * temp));
        sum += tint * brightness * profile;
    }
    // Roden & Parberry: stars inside the galaxy get brighter too.
    return sum * u_star_sigma_gain.y * (1.0 + 1.5 * galaxy);
}
#endif

#if SKY_MOON
// The moon's light in a view ray, and how much of the pixel its disc covers.
vec3 moon_light(vec3 ray, out float coverage) {
    float cos_a = dot(ray, u_moon_dir);
    vec3 q = ray - u_moon_dir * cos_a;
    float sin_a = length(q);
    coverage = clamp((u_moon_sin_radius - sin_a) / u_pixel_rad + 0.5, 0.0, 1.0);
    coverage *= step(0.0, cos_a) * step(0.0, ray.z);
    if (coverage <= 0.0) {
        return vec3(0.0);
    }
    // The visible hemisphere's normal under this pixel; lit where it faces the sun (the sun
    // is 400 times farther than the moon, so its direction from the moon is ours).
    vec3 p = q / u_moon_sin_radius;
    float r2 = min(dot(p, p), 1.0);
    vec3 n = p - u_moon_dir * sqrt(1.0 - r2);
    float l = dot(n, u_sun_dir);
    float lit = smoothstep(-0.04, 0.08, l) * (0.85 + 0.15 * max(l, 0.0));
    vec3 side = cross(u_moon_dir, vec3(0.0, 0.0, 1.0));
    side = dot(side, side) > 1e-6 ? normalize(side) : vec3(1.0, 0.0, 0.0);
    vec2 st = vec2(dot(p, side), dot(p, cross(side, u_moon_dir)));
    float maria = textureLod(u_dome_tex, st * 0.3 + vec2(0.37, 0.61), 0.0).r;
    float albedo = mix(1.0, 0.6, smoothstep(0.5, 0.8, maria));
    return (u_moon_rgb * lit + u_earthshine_rgb * (1.0 - lit)) * albedo;
}
#endif

#if SKY_DOME
// The 22 deg halo: sunlight (or moonlight) bent by the hexagonal ice prisms of a cirrostratus
// veil (their least deviation is 21.8 deg; red bends least, so the ring's inner edge is red
// and sharp and it fades bluish-white outward), and the veil inside the ring a little darker,
// where no prism sends light. Over the veil only: the dome's alpha carries it.
#if SKY_HALO
vec3 halo(vec3 ray, vec3 light_dir, vec3 light_rgb) {
    // Nothing of it past 32 deg (its outer tail is under 1 % there): most of the sky skips
    // the acos and the three exponentials.
    float cos_a = dot(ray, light_dir);
    if (light_dir.z < -0.01 || cos_a < HALO_COS_REACH) {
        return vec3(0.0);
    }
    float deg = degrees(acos(min(cos_a, 1.0)));
    vec3 off = deg - vec3(21.7, 22.0, 22.3);
    // Sharp inside (0.35 deg), a long outer tail (2.5 deg).
    vec3 width = mix(vec3(0.35), vec3(2.5), step(0.0, off));
    vec3 ring = exp(-0.5 * off * off / (width * width));
    float inside = 1.0 - smoothstep(17.0, 21.5, deg);
    return light_rgb * HALO_GAIN * ring - u_dome_rgb * HALO_DARK_INSIDE * inside;
}
#endif

// Roden & Parberry's cloud dome as a plane at the dome height: two shape layers blended,
// cover as a threshold, density smoothing and darkening, and the sunset gradient. Along the
// horizon it stands for the distant part of every layer, which carries on into the horizon
// haze: seen edge-on it closes its gaps and turns opaque, and the air in front of it (a deck
// 400 m up is 23 km away at 1° and 230 km at 0.1°) takes it over, so under a deck the
// horizon is the deck's underside in haze, never a strip of clear sky (issue 41 item 5).
vec4 cloud_dome(vec3 ray, vec3 air) {
    float z = max(ray.z, 0.002);
    vec2 plane_m = ray.xy / z * u_dome_height_m;
    // Sampled in uniform control flow so the mip level comes from true derivatives; at the
    // horizon the lowest mips average the clouds into a band.
    float c0 = texture(u_dome_tex, u_dome_m0 * plane_m + u_dome_off0).r;
    float c1 = texture(u_dome_tex, u_dome_m1 * plane_m + u_dome_off1).g;
    vec2 q = u_dome_m2 * plane_m + u_dome_off2;
    float high_cover = u_dome_controls.x, cover = u_dome_controls.y;
    float density = u_dome_controls.z, sunset = u_dome_controls.w;
    // Thin ice cloud in fibres (cirrus): the detail noise drawn out along the wind (the
    // texture's x) and packed finer across it, in the texture's A beside the detail itself
    // (sky_texture_gen._fibres), its rows bent by the broad shapes, so the fibres curve, fan
    // out and run together as mares' tails do, not in even dashes. One fetch for both: the
    // bend shifts the detail too, by at most a fortieth of a tile, which no one can see, and
    // a second fetch cost the dome a seventh of its time on a CPU renderer.
    vec4 fine = texture(u_dome_tex, q + vec2(0.0, FIBRE_BEND / FIBRE_ACROSS * (c0 - 0.5)));
    float detail = fine.b, fibre = fine.a;
    // Distant parts of every layer show below the sprites' far edge; seen ever more
    // obliquely towards the horizon, their gaps close.
    float band = 1.0 - smoothstep(u_dome_band.x, u_dome_band.y, ray.z);
    float grazing = 1.0 - smoothstep(0.0, u_dome_band.y, ray.z);
    float distant = 1.0 - (1.0 - cover) * (1.0 - grazing);
    float here = max(high_cover, distant * step(0.001, band));
    // The mean of two uniform layers is triangular: keep the share `here` of it.
    float c = 0.5 * (c0 + c1);
    float threshold = here < 0.5 ? 1.0 - sqrt(0.5 * here) : sqrt(0.5 * (1.0 - here));
    // Thin cloud is a soft-edged veil with fibres (detail cuts into it), dense cloud has
    // firmer edges, is smooth and nearly opaque; seen edge-on, every layer is opaque.
    float softness = mix(0.22, 0.1, density);
    float a = smoothstep(threshold - 0.3 * softness, threshold + softness, c) * step(0.001, here);
    float strands = mix(0.25 + 0.75 * detail, 0.15 + 0.85 * smoothstep(0.3, 0.8, fibre),
                        1.0 - smoothstep(0.1, 0.3, density));
    a *= mix(mix(strands, 1.0, density) * mix(0.45, 0.95, density), 1.0,
             grazing * step(0.001, band));
    // A cirrostratus veil is a milky sheet, not patches: where its cover reaches (the broad
    // shape alone, soft-edged), a near-even film with faint fibres, under whatever else the
    // dome shows there. One shape layer is uniform on 0..1: a threshold at 1 - x keeps x.
    float veil_threshold = 1.0 - u_dome_veil;
    float veil = smoothstep(veil_threshold - 0.15, veil_threshold + 0.15, c0)
               * step(0.001, u_dome_veil) * VEIL_ALPHA * (0.8 + 0.2 * fibre);
    // The patches are the other high cloud's (cirrus): as much fainter as the veil is of the
    // high cover.
    a *= 1.0 - VEIL_PATCHES * clamp(u_dome_veil / max(high_cover, 1e-3), 0.0, 1.0);
    a = 1.0 - (1.0 - a) * (1.0 - veil);
    // The distant band fades out upwards as a whole rather than by thinning its cover, which
    // would cut a hard edge where the averaged far texture crosses the threshold.
    // The dome is a plane above the eye: nothing of it below the eye's level.
    a *= max(band, step(0.001, high_cover)) * step(0.0, ray.z);
    vec3 rgb = u_dome_rgb * mix(0.8, 1.05, detail) * (1.0 - 0.3 * density * a);
    // Thin ice cloud glows around the sun.
    // (cos^8 by three products: pow is an exp and a log a pixel on a CPU renderer)
    float toward_sun = max(dot(ray, u_sun_dir), 0.0);
    float toward_sun2 = toward_sun * toward_sun;
    float toward_sun4 = toward_sun2 * toward_sun2;
    rgb += u_sun_rgb * (toward_sun4 * toward_sun4) * 0.35 * (1.0 - density);
    // Roden & Parberry's sunset gradient: redder low down, pinker high up, golden while the sun
    // is still well up. Scaled to the dome's light so the tint never brightens a dark sky.
    // Coordinates land on the first and last texel centres at 0 and 1.
    // Read only when the sun is low (a uniform branch): by day it added nothing but a fetch.
    if (sunset > 0.0) {
        vec2 flat_ray = normalize(ray.xy + vec2(1e-6, 0.0));
        vec2 flat_sun = normalize(u_sun_dir.xy + vec2(1e-6, 0.0));
        float sunward = 0.35 + 0.65 * max(dot(flat_ray, flat_sun), 0.0);
        vec2 sunset_px = vec2(textureSize(u_sunset_tex, 0));
        vec2 sunset_uv = (vec2(sunset, sqrt(z)) * (sunset_px - 1.0) + 0.5) / sunset_px;
        vec3 sunset_rgb = textureLod(u_sunset_tex, sunset_uv, 0.0).rgb
                          * max(max(u_dome_rgb.r, u_dome_rgb.g), 0.05) * 1.1;
        rgb = mix(rgb, sunset_rgb, clamp(sunset * sunward, 0.0, 1.0) * 0.85);
    }
#if SKY_HALO
    // Compiled into the halo's own part only (sky_textures.halo_rect_ndc): elsewhere the
    // code alone, never run, slowed the dome on a CPU renderer.
    if (u_dome_veil > 0.0) {
        rgb += halo(ray, u_sun_dir, u_sun_rgb) * u_dome_veil;
        if (u_moon_halo_rgb.r > 0.0) {
            rgb += halo(ray, u_moon_halo_dir, u_moon_halo_rgb) * u_dome_veil;
        }
    }
#endif
    // Aerial perspective as the sprites have it (scene.layout.hazed): the layer's contrast
    // falls by exp(-distance / haze distance) along the ray to its plane, towards `air`, the
    // colour the sprites fade into in this direction; at the horizon the ray is endless and
    // only the haze is left.
    float haze = 1.0 - exp(-(u_haze_depth_m / u_haze_m
                             + (u_dome_height_m - u_haze_depth_m) / u_clear_haze_m)
                           / max(ray.z, 1e-5));
    rgb = mix(rgb, air, haze);
    return vec4(rgb, a);
}
#endif

// The ground below the horizon: a smooth Earth under the eye, in its own colour where it is
// near and in aerial perspective towards `air` (the air at the horizon above it) with
// distance, so the two meet where the Earth's horizon is (0.045° below level from 2 m, 3.2°
// from 10 km), at a line as sharp as the haze allows: the ground there is 5 km off from 2 m
// and keeps three quarters of its contrast at 60 km visibility. Between the eye's level and
// that line the ray misses the Earth and the air shows.
const float EARTH_RADIUS_M = 6371000.0;
vec3 ground_band(vec3 ray, vec3 sky, vec3 air) {
    float h = max(u_ground_air.x, 0.5);
    // |eye + t ray| = R: with B = (R + h) sin(depression), t = c / (B + sqrt(B^2 - c)),
    // the near root, in a form float32 keeps accurate for small h.
    float b = (EARTH_RADIUS_M + h) * -ray.z;
    float c = h * (2.0 * EARTH_RADIUS_M + h);
    float disc = b * b - c;
    float t = c / (b + sqrt(max(disc, 0.0)));
    // Coverage of the pixel by the ground, anti-aliased across the horizon's line.
    float horizon_z = -sqrt(c) / (EARTH_RADIUS_M + h);
    float ground = clamp((horizon_z - ray.z) / u_pixel_rad + 0.5, 0.0, 1.0);
    // The part of the ray in the hazy layer over the ground, the rest in clear air.
    float hazy = clamp(u_ground_air.z / h, 0.0, 1.0);
    float depth = t * (hazy / u_ground_air.y + (1.0 - hazy) / u_ground_air.w);
    vec3 hazed = mix(u_ground * u_ground_tint, air, 1.0 - exp(-depth));
    return ray.z < 0.0 ? mix(air, hazed, ground) : sky;
}

void main() {
    vec3 ray = view_ray();
#if SKY_PHYSICAL && SKY_SCENE_LINEAR
    vec3 col = physical_sky(ray);  // into a float target: radiance, kcd/m^2
#elif SKY_PHYSICAL
    vec3 air;
    vec3 col = baked_sky(ray, air);
#else
    // Below the horizon the sky is what lies behind the ground's haze: its colour at the
    // horizon, or where a layer reaches the horizon, the air under it (`ground_band`). The
    // physical sky's table holds its own ground, in its own aerial perspective.
    vec3 look = ray.z < 0.0 ? normalize(vec3(ray.xy + vec2(1e-6, 0.0), 0.0)) : ray;
    vec3 col = sky_colour(look, u_sun_dir, u_zenith, u_horizon, u_ground, u_sun_rgb);
    vec3 air = mix(col, u_horizon_air.rgb, u_horizon_air.a);
#endif
#if SKY_DOME && SKY_PHYSICAL && !SKY_SCENE_LINEAR
    vec4 dome = cloud_dome(ray, air);
#elif SKY_DOME
    vec4 dome = cloud_dome(ray, u_dome_haze_rgb);
#else
    vec4 dome = vec4(0.0);
#endif
#if SKY_MOON
    float moon_cover;
    vec3 moon = moon_light(ray, moon_cover);
#else
    float moon_cover = 0.0;
    vec3 moon = vec3(0.0);
#endif
#if SKY_STARS
    if (ray.z > 0.0) {
        vec3 c = normalize(u_celestial_from_enu * ray);
        vec3 g = u_galactic_from_celestial * c;
        vec2 gal_uv = vec2(atan(g.y, g.x) / (2.0 * PI) + 0.5,
                           asin(clamp(g.z, -1.0, 1.0)) / PI + 0.5);
        float galaxy = textureLod(u_galaxy_tex, gal_uv, 0.0).r;
        // Starlight crosses more air low down: the horizon swallows the faint ones.
        float extinction = smoothstep(0.0, 0.15, ray.z);
        vec3 night = vec3(0.78, 0.84, 1.0) * galaxy * 0.1 + star_light(c, galaxy, ray.z);
        col += night * (u_stars * extinction * (1.0 - moon_cover) * (1.0 - dome.a));
    }
#endif
    col += moon * moon_cover * (1.0 - 0.85 * dome.a);
#if !SKY_PHYSICAL
    float disc = smoothstep(u_sun_cos_radius - 0.00002, u_sun_cos_radius + 0.00002,
                            dot(ray, u_sun_dir));
    col = mix(col, vec3(1.0, 0.98, 0.9) * 1.2, disc * step(-0.01, ray.z) * length(u_sun_rgb));
#endif
    col = mix(col, dome.rgb, dome.a);
#if !(SKY_PHYSICAL && SKY_SCENE_LINEAR)
    col = ground_band(ray, col, air);
#endif
#if SKY_PHYSICAL && SKY_SCENE_LINEAR
    f_colour = vec4(max(col, 0.0), 1.0);
#else
    f_colour = legacy_output(vec4(clamp(col, 0.0, 1.0), 1.0));
#endif
}
#endif
