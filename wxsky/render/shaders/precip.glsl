// Precipitation (scene/precip_view.py): with CURTAINS, the rain and snow curtains under the
// near storms over the picture (a full-screen quad, u_rect); with LINES, screen-space streaks
// (the drops and flakes about the eye, lightning's channels), a quad per instance.
// Premultiplied alpha, display-referred legacy colours as the sprites' (display.glsl).
// Needs MAX_CURTAINS (precip_view.py's, defined by render/precip_pass.py).
#include "display.glsl"

#if defined CURTAINS
#define VEIL_RANGE_M 30000.0
#define BASE_ALPHA 0.95
#define BASE_SHADE 0.15

#if defined VERTEX_SHADER
#include "rect_quad.glsl"
#endif

#if defined FRAGMENT_SHADER
#include "view_ray.glsl"
uniform float u_eye_z;           // MSL
uniform float u_clip_top_m;      // the lowest cloud base under the storms, MSL
uniform vec3 u_veil;             // a nimbostratus's rain: extinction /m, its base, the ground (MSL)
uniform vec3 u_veil_rgb;
uniform int u_count;
uniform vec4 u_axis[MAX_CURTAINS];   // axis east, north less the eye's; e-folding radius; extinction /m
uniform vec4 u_span[MAX_CURTAINS];   // top, bottom MSL; 1 where it ends in the air (virga); seed
uniform vec4 u_base[MAX_CURTAINS];   // the cloud's base radius (0: none drawn)
uniform vec3 u_body[MAX_CURTAINS];   // the rain's colour, lit under the storm
uniform vec3 u_air[MAX_CURTAINS];    // the air's colour toward it (the haze it fades into)
uniform float u_inv_haze_m;
uniform float u_pixel_rad;       // the angle one pixel of the layer spans
uniform float u_fall_m;          // how far the streaks have fallen (the clock times their speed)
out vec4 f_colour;

float hash12(vec2 p) {
    vec3 p3 = fract(vec3(p.xyx) * 0.1031);
    p3 += dot(p3, p3.yzx + 33.33);
    return fract((p3.x + p3.y) * p3.z);
}

float value_noise(vec2 p) {
    vec2 i = floor(p);
    vec2 f = fract(p);
    vec2 w = f * f * (3.0 - 2.0 * f);
    return mix(mix(hash12(i), hash12(i + vec2(1.0, 0.0)), w.x),
               mix(hash12(i + vec2(0.0, 1.0)), hash12(i + vec2(1.0, 1.0)), w.x), w.y);
}

// erf, Abramowitz & Stegun 7.1.26's tanh form (error under 4e-4: far finer than a byte).
float erf_approx(float x) {
    return tanh(1.1283792 * x + 0.1009109 * x * x * x);
}

// The curtain's density across its breadth and down its fall: sheets of rain 60-250 m
// across, drawn out ten times as long, falling; the core's extinction scaled 0.2..1.8 by them
// (their mean 1: the radar and the eye see the mean).
// Sheets narrower than a few pixels where they are seen give way to their mean (0.5), or far
// curtains would alias into pin stripes: each from about six pixels a period down to two and
// a half (a value noise's period is its cell; `pixel_m` is how far the sheets move a pixel).
float sheets(float across_m, float z_m, float seed, float pixel_m) {
    float fall = (z_m + u_fall_m) / 1400.0;
    float finest = mix(value_noise(vec2(across_m / 19.0 - seed, fall * 2.1)), 0.5,
                       smoothstep(3.2, 7.5, pixel_m));
    float fine = 0.7 * mix(value_noise(vec2(across_m / 70.0 + seed, fall * 1.3)), 0.5,
                           smoothstep(11.5, 27.0, pixel_m))
                 + 0.3 * finest;
    float coarse = mix(value_noise(vec2(across_m / 260.0 - seed, fall * 0.5 + 7.0)), 0.5,
                       smoothstep(44.0, 100.0, pixel_m));
    return 0.2 + 1.6 * clamp(0.45 * fine + 0.55 * coarse + (fine - 0.5) * 0.4, 0.0, 1.0);
}

void main() {
    vec3 ray = view_ray();
    float ch = max(length(ray.xy), 1e-4);  // cos of the ray's elevation
    vec2 u = ray.xy / ch;
    float slope = ray.z / ch;  // height gained per horizontal metre
    vec3 colour = vec3(0.0);
    float seen = 1.0;  // the light from behind that still gets through, front to back
    for (int i = 0; i < MAX_CURTAINS; ++i) {
        if (i >= u_count) {
            break;
        }
        vec2 a = u_axis[i].xy;
        float radius = u_axis[i].z;
        float s0 = dot(a, u);  // horizontal distance to the ray's nearest point to the axis
        vec2 off = a - s0 * u;
        float p2 = dot(off, off) / (radius * radius);
        if (p2 > 9.0) {
            continue;
        }
        // Where along the ray (horizontal metres) it is between the curtain's bottom and top
        // (the top no higher than the lowest cloud under the storm, seen from below it: the
        // clouds there are drawn, and the rain in front of them over them).
        float top = (u_eye_z < u_clip_top_m ? min(u_span[i].x, u_clip_top_m) : u_span[i].x)
                    - u_eye_z;
        float bottom = u_span[i].y - u_eye_z;
        float lo = 0.0;
        float hi = 1e7;
        if (abs(slope) > 1e-6) {
            float s_top = top / slope;
            float s_bottom = bottom / slope;
            lo = max(0.0, min(s_top, s_bottom));
            hi = max(s_top, s_bottom);
        } else if (top < 0.0 || bottom > 0.0) {
            continue;
        }
        lo = max(lo, s0 - 3.0 * radius);
        hi = min(hi, s0 + 3.0 * radius);
        if (hi <= lo) {
            continue;
        }
        // Across the curtain as the eye sees it (fixed to the world: the sheets stay put as
        // the view turns).
        vec2 side = normalize(vec2(-a.y, a.x) + vec2(1e-6, 0.0));
        float axis_m = length(a);
        float cos_off = s0 / max(axis_m, 1e-3);
        // The Gaussian column integrated along the ray in three stretches front to back (its
        // near side, its core, its far side: boundaries half a radius either side of the
        // ray's nearest point to the axis), each with the sheets where it lies, so near
        // sheets stand out against far ones. The sheets are sampled at points fixed by the
        // ray's azimuth and the stretch, so they run down the curtain, never across it.
        float across_gauss = 0.886227 * radius * exp(-p2) / ch;
        float fade_top = top + u_eye_z;
        float e0 = erf_approx((lo - s0) / radius);
        for (int k = 0; k < 3; ++k) {
            float s_start = k == 0 ? lo : clamp(s0 + (float(k) - 1.5) * radius, lo, hi);
            float s_end = k == 2 ? hi : clamp(s0 + (float(k) - 0.5) * radius, lo, hi);
            float s_at = 0.5 * (s_start + s_end);
            float e1 = erf_approx((s_end - s0) / radius);
            float z = u_eye_z + s_at * slope;
            float across = dot((s0 + (float(k) - 1.0) * radius) * u - a, side);
            // How fast `across` moves as the ray turns (metres a radian of azimuth, d/dphi of
            // (D cos phi + (k-1) r) sin phi, phi the ray's angle off the axis): a pixel's
            // breadth in the sheets, so those finer than a few pixels fade to their mean.
            // (The distance along the ray is not it: beside or under a storm the sampled
            // point swings round far faster, and the sheets aliased into pin stripes.)
            float across_rate = abs(axis_m * (2.0 * cos_off * cos_off - 1.0)
                                    + (float(k) - 1.0) * radius * cos_off);
            float sheet = sheets(across, z, u_span[i].w + 31.0 * float(k),
                                 across_rate / ch * u_pixel_rad);
            // Up into the cloud it falls from, the rain fades into it (no edge at its base).
            float ragged_top = value_noise(vec2(across / 110.0, 3.0 + u_span[i].w));
            float tau = u_axis[i].w * across_gauss * (e1 - e0) * sheet
                        * (1.0 - smoothstep(fade_top - (0.3 + 0.5 * ragged_top)
                                                * (fade_top - u_span[i].y),
                                            fade_top, z));
            if (u_span[i].z > 0.5) {
                // Virga: a ragged end where the last drops evaporate.
                float ragged = 250.0 * value_noise(vec2(across / 150.0, u_span[i].w));
                tau *= smoothstep(u_span[i].y, u_span[i].y + 150.0 + ragged, z);
            }
            float alpha = 1.0 - exp(-tau);
            float haze = 1.0 - exp(-(s_start / ch) * u_inv_haze_m);
            // Thick sheets are darker (less of the light gets in), thin ones lighter.
            vec3 body = u_body[i] * (1.45 - 0.55 * sheet);
            colour += seen * alpha * mix(body, u_air[i], haze);
            seen *= 1.0 - alpha;
            e0 = e1;
        }
        // The storm's underside, dark (in the shadow of ten kilometres of cloud) and lumpy,
        // where the ray meets its base: seen from below it when nothing lower hides it.
        if (u_base[i].x > 0.0 && slope > 1e-4 && u_span[i].x <= u_clip_top_m + 1.0) {
            float s_base = (u_span[i].x - u_eye_z) / slope;
            vec2 at = s_base * u - a;
            float d = length(at) / u_base[i].x;
            if (s_base > 0.0 && d < 1.2) {
                float lumps = 0.6 * value_noise(at / 650.0 + u_span[i].w)
                              + 0.4 * value_noise(at / 230.0 - u_span[i].w);
                float alpha = BASE_ALPHA * (1.0 - smoothstep(0.75, 1.15, d + 0.2 * lumps));
                float haze = 1.0 - exp(-(s_base / ch) * u_inv_haze_m);
                vec3 under = u_air[i] * (BASE_SHADE + 0.3 * lumps);
                colour += seen * alpha * mix(under, u_air[i], haze);
                seen *= 1.0 - alpha;
            }
        }
    }
    if (u_veil.x > 0.0) {
        // A nimbostratus's rain, even under its base out to VEIL_RANGE_M (behind the
        // curtains: where both fall, the storm's is the nearer and the heavier).
        float top = u_veil.y - u_eye_z;
        float bottom = u_veil.z - u_eye_z;
        float s_lo = 0.0;
        float s_hi = VEIL_RANGE_M;
        if (abs(slope) > 1e-6) {
            float s_top = top / slope;
            float s_bottom = bottom / slope;
            s_lo = max(0.0, min(s_top, s_bottom));
            s_hi = min(s_hi, max(s_top, s_bottom));
        } else if (top < 0.0 || bottom > 0.0) {
            s_hi = 0.0;
        }
        float alpha = 1.0 - exp(-u_veil.x * max(s_hi - s_lo, 0.0) / ch);
        colour += seen * alpha * u_veil_rgb;
        seen *= 1.0 - alpha;
    }
    float a = 1.0 - seen;
    if (a < 1.0 / 512.0) {
        discard;
    }
    f_colour = legacy_output(vec4(colour, a));
}
#endif
#endif

#if defined LINES
#if defined VERTEX_SHADER
uniform mat4 u_view_proj;   // from eye-relative ENU to clip
uniform vec2 u_target_size;
in vec3 in_head;            // eye-relative ENU, metres
in vec3 in_tail;
in vec4 in_rgba;            // straight colour and alpha at the head
in float in_width_px;
out vec2 v_across_along;
flat out vec4 v_rgba;
void main() {
    vec4 h = u_view_proj * vec4(in_head, 1.0);
    vec4 t = u_view_proj * vec4(in_tail, 1.0);
    v_rgba = in_rgba;
    if (h.w < 0.05 || t.w < 0.05) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // behind the eye: nothing
        v_across_along = vec2(0.0);
        return;
    }
    vec2 hs = h.xy / h.w * 0.5 * u_target_size;
    vec2 ts = t.xy / t.w * 0.5 * u_target_size;
    vec2 d = hs - ts;
    float len = length(d);
    vec2 dir = len > 1e-3 ? d / len : vec2(0.0, 1.0);
    vec2 n = vec2(-dir.y, dir.x) * (0.5 * in_width_px);
    // A cap of half the width at each end keeps a short streak (a flake) a dot; long ones
    // (a channel's segments, end to end) have none, or their joints would bead.
    vec2 cap = dir * (0.5 * in_width_px * clamp(1.5 - len / in_width_px, 0.0, 1.0));
    int k = gl_VertexID;  // two triangles: 0 1 2, 2 1 3 as a strip of 4 corners
    int corner = k < 3 ? k : (k == 3 ? 2 : (k == 4 ? 1 : 3));
    bool at_head = (corner & 1) == 1;
    float side = (corner & 2) == 0 ? -1.0 : 1.0;
    vec2 p = (at_head ? hs + cap : ts - cap) + n * side;
    float w = at_head ? h.w : t.w;
    v_across_along = vec2(side, at_head ? 1.0 : 0.0);
    gl_Position = vec4(p / (0.5 * u_target_size) * w, at_head ? h.z : t.z, w);
}
#endif

#if defined FRAGMENT_SHADER
in vec2 v_across_along;
flat in vec4 v_rgba;
out vec4 f_colour;
void main() {
    float across = 1.0 - v_across_along.x * v_across_along.x;
    float alpha = v_rgba.a * across * mix(0.35, 1.0, v_across_along.y);
    if (alpha < 1.0 / 512.0) {
        discard;
    }
    f_colour = legacy_output(vec4(v_rgba.rgb * alpha, alpha));
}
#endif
#endif
