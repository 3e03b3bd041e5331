// Fog over the ground (issue 43 item 3, docs/fog.md): the view ray marched through the fog
// field of wxsky/scene/fog.py (FogField, its numpy twin: the same banks, the same sum, the
// same steps as FogField.optical_depth), drawn as premultiplied airlight over what the near
// layer holds after its sprites (the fog is the lowest thing in the sky). The fog takes the
// colour of the air at the horizon (SkyParams.haze_rgb), the sky's own light on it, lifted
// toward white by day (fog_pass.fog_rgb): white-grey by day, warm at dusk, dark at night.

#if defined VERTEX_SHADER
#include "screen_triangle.glsl"
#endif

#if defined FRAGMENT_SHADER
#include "display.glsl"
uniform vec4 u_fog_banks[FOG_BANKS];   // east, north, radius (0: everywhere), extinction /m
uniform float u_fog_depth_m[FOG_BANKS];  // each bank's top over the ground
uniform int u_fog_count;
uniform float u_fog_top_m;    // the highest top
uniform float u_fog_reach_m;  // how far from the field's middle any bank reaches
uniform vec3 u_eye;           // east, north, height over the ground
#include "view_ray.glsl"
uniform vec3 u_fog_rgb;
out vec4 f_colour;

float fog_extinction(vec2 p, float h) {
    float sum = 0.0;
    for (int i = 0; i < FOG_BANKS; ++i) {
        if (i >= u_fog_count) {
            break;
        }
        vec4 b = u_fog_banks[i];
        float depth = u_fog_depth_m[i];
        float v = clamp((depth - h) / (TOP_FADE * depth), 0.0, 1.0);
        vec2 d = p - b.xy;
        float across = b.z > 0.0 ? exp(-dot(d, d) / (b.z * b.z)) : 1.0;
        sum += b.w * across * v;
    }
    return max(sum, 0.0);
}

void main() {
    vec3 ray = view_ray();
    float h0 = u_eye.z;
    float t0 = 0.0;
    float t1 = MAX_RANGE_M;
    if (ray.z < 0.0) {
        t1 = min(t1, max(h0, 0.0) / -ray.z);
    }
    if (h0 > u_fog_top_m) {
        if (ray.z >= 0.0) {
            discard;
        }
        t0 = (h0 - u_fog_top_m) / -ray.z;
    } else if (ray.z > 0.0) {
        t1 = min(t1, (u_fog_top_m - h0) / ray.z);
    }
    t1 = min(t1, (length(u_eye.xy) + u_fog_reach_m) / max(length(ray.xy), 1e-4));
    if (t1 <= t0) {
        discard;
    }
    float span = t1 - t0;
    float tau = 0.0;
    for (int k = 0; k < FOG_STEPS; ++k) {
        float s = (float(k) + 0.5) / float(FOG_STEPS);
        vec3 p = u_eye + ray * (t0 + span * s * s);
        tau += fog_extinction(p.xy, p.z) * span * 2.0 * s / float(FOG_STEPS);
    }
    float alpha = 1.0 - exp(-tau);
    if (alpha < 1.0 / 512.0) {
        discard;
    }
    f_colour = legacy_output(vec4(u_fog_rgb * alpha, alpha));
}
#endif
