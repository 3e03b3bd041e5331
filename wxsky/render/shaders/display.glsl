// The one place where a pass's colour becomes what its layer holds (issue 41): every pass that
// writes a layer ends with `f_colour = layer_output(c)` (c scene-linear, premultiplied) or,
// while its colours are still the display-referred artist colours of before,
// `f_colour = legacy_output(c)`. wxsky/scene/exposure.py is this file's numpy twin; read its
// docstring for why this tone map.
//
// OUTPUT_LINEAR (defined by the shader library for a linear renderer: float layers for
// `snapshot --linear-out` and HDR hosts): the layer holds scene-linear colour, no exposure or
// tone map. Otherwise: display(x) = srgb_encode(tone_map(x * u_exposure)), on the straight
// colour, alpha kept. Legacy colours go through display(from_legacy(c)) only in a renderer
// made for exposures other than EV 0 (EXPOSURE_VARIABLE): at EV 0 that round trip is c, and
// compiled out rather than branched over (llvmpipe runs both sides of a uniform branch, and
// the round trip doubled the sprites' fragment cost). A layer blends its fragments (and the host composites its layers) after
// this, in display values: tone-mapping each fragment is not tone-mapping the composite, but
// the curve is the identity's neighbour below the shoulder and the two differ only where
// translucent edges overlap highlights.

#if !defined WXSKY_DISPLAY_GLSL
#define WXSKY_DISPLAY_GLSL

uniform float u_exposure;  // scale on scene-linear colour; exposure.py checks it is finite

const float TM_A = 2.51;
const float TM_B = 0.14;
const float TM_C = 2.43;
const float TM_D = 0.70;
const float TM_E = 0.14;
const float LEGACY_EXPOSURE = 1.0;
const float LEGACY_MAX = 1.0 - 1.0 / 1024.0;

float tone_curve(float x) {
    return clamp(x * (TM_A * x + TM_B) / (x * (TM_C * x + TM_D) + TM_E), 0.0, 1.0);
}

// The root x >= 0 of (y C - A) x^2 + (y D - B) x + y E = 0, for y in 0..1.
float tone_curve_inverse(float y) {
    y = clamp(y, 0.0, 1.0);
    float a = y * TM_C - TM_A;
    float b = y * TM_D - TM_B;
    float c = y * TM_E;
    return (-b - sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a);
}

// Past the curve's white a colour burns toward white (exposure.py `burn`).
const float TM_WHITE = 7.241657386773973;  // exposure.TM_WHITE: where the curve reaches 1
const float BURN_FULL = 4.0;
const float BURN_MAX = 0.9;

vec3 tone_map(vec3 c) {
    c = max(c, vec3(0.0));
    float m = max(max(c.r, c.g), c.b);
    if (m <= 0.0) {
        return vec3(0.0);
    }
    float y = tone_curve(m);
    vec3 hue = c * (y / m);
    float t = clamp((m / TM_WHITE - 1.0) / (BURN_FULL - 1.0), 0.0, 1.0);
    return mix(hue, vec3(y), BURN_MAX * t * t * (3.0 - 2.0 * t));
}

vec3 tone_map_inverse(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    float n = max(max(c.r, c.g), c.b);
    return n > 0.0 ? c * (tone_curve_inverse(n) / n) : vec3(0.0);
}

vec3 srgb_encode(vec3 x) {
    x = clamp(x, 0.0, 1.0);
    return mix(12.92 * x, 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, x));
}

vec3 srgb_decode(vec3 x) {
    x = clamp(x, 0.0, 1.0);
    return mix(x / 12.92, pow((x + 0.055) / 1.055, vec3(2.4)), step(0.04045, x));
}

// Straight scene-linear colour -> display values 0..1.
vec3 display(vec3 linear) {
    return srgb_encode(tone_map(linear * u_exposure));
}

// The scene-linear colour that display() at LEGACY_EXPOSURE turns into `legacy`.
vec3 from_legacy(vec3 legacy) {
    return tone_map_inverse(srgb_decode(min(legacy, vec3(LEGACY_MAX)))) / LEGACY_EXPOSURE;
}

// Premultiplied scene-linear colour -> what the layer holds.
vec4 layer_output(vec4 c) {
#if defined OUTPUT_LINEAR
    return c;
#else
    if (c.a <= 0.0) {
        return vec4(0.0);
    }
    return vec4(display(c.rgb / c.a) * c.a, c.a);
#endif
}

// Premultiplied display-referred legacy colour -> what the layer holds.
vec4 legacy_output(vec4 c) {
#if defined OUTPUT_LINEAR || defined EXPOSURE_VARIABLE
    if (c.a <= 0.0) {
        return vec4(0.0);
    }
    return layer_output(vec4(from_legacy(c.rgb / c.a) * c.a, c.a));
#else
    return c;  // display(from_legacy(c)) at LEGACY_EXPOSURE
#endif
}

#endif
