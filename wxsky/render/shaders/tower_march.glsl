// A convective tower's volume drawn into its own impostor (Domański's volumes, issue 17): for
// each texel of a quad through the box's middle, facing the eye, a ray from the eye through it
// is marched through the box front to back. The light reaching each cell from each of the
// sky's lights is in two 3D textures (scene/tower_field.py: lights 0-3; lights 4-5 and the
// density); the eye's phase and the lights' colours come as one weight per light
// (tower_shading.view_weights), and the radiance is exposed as the sprite clouds' is
// (shading_harris.shown_channels), so numpy's tower colours and these agree.

#if defined VERTEX_SHADER
out vec2 v_uv;  // -1..1 across the quad
void main() {
    vec2 p = vec2(float(gl_VertexID & 1) * 2.0 - 1.0, float((gl_VertexID >> 1) & 1) * 2.0 - 1.0);
    v_uv = p;
    gl_Position = vec4(p, 0.0, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
in vec2 v_uv;
uniform sampler3D u_light0;
uniform sampler3D u_light1;
uniform sampler3D u_noise;  // tileable detail noise (towers.detail_noise)
uniform vec3 u_eye;       // the eye minus the box's middle, metres (ENU)
uniform vec3 u_centre;    // the quad's middle minus the box's middle
uniform vec3 u_axis_u;    // the quad's half extent across, metres
uniform vec3 u_axis_v;    // and up it
uniform vec3 u_half;      // the box's half size
uniform vec3 u_lo;        // the part of the box holding cloud, from its middle
uniform vec3 u_hi;
uniform float u_noise_per_m;
uniform float u_erosion;  // how much of a thin cell's density the noise may take
uniform float u_sharpen;
uniform int u_steps;       // samples along a ray through the cloudy part
uniform vec3 u_weights[6];
uniform vec3 u_ambient;
uniform float u_ext_per_m;  // extinction per metre at density 1
uniform vec3 u_key_dir;     // toward the key light (the sun or moon), unit
uniform float u_billow_shadow;  // how deep a billow's own shade goes (0: none)
out vec4 f_colour;

#if CLOUD_DISPLAY_SHARED
// Under the physical sky: the one tone map every pass shares (display.glsl, at the light's
// own exposure: the clouds' light is in exposed units), as shading_harris.shown_channels.
#include "display.glsl"
vec3 exposed(vec3 r) {
    return srgb_encode(tone_map(r));
}
#else
vec3 exposed(vec3 r) {
    float peak = max(max(r.r, r.g), max(r.b, 1e-6));
    float e = 1.0 - exp(-EXPOSURE * peak);
    vec3 kept = r * (e * (e + TOE) / (1.0 + TOE) / peak);
    // Far past white (a silver lining) the highlight bleaches toward white.
    float bleach = clamp((EXPOSURE * peak - WHITEN_FROM) / (WHITEN_TO - WHITEN_FROM), 0.0, 1.0);
    vec3 each = 1.0 - exp(-EXPOSURE * r);
    return mix(kept, each * (each + TOE) / (1.0 + TOE), bleach);
}
#endif

void main() {
    vec3 dir = normalize(u_centre + v_uv.x * u_axis_u + v_uv.y * u_axis_v - u_eye);
    // Where the ray is inside the cloudy part of the box (slabs); a zero component of the
    // direction never limits it.
    vec3 safe = mix(dir, vec3(1e-9), lessThan(abs(dir), vec3(1e-9)));
    vec3 t0 = (u_lo - u_eye) / safe;
    vec3 t1 = (u_hi - u_eye) / safe;
    vec3 lo = min(t0, t1);
    vec3 hi = max(t0, t1);
    float enter = max(max(lo.x, lo.y), max(lo.z, 0.0));
    float leave = min(min(hi.x, hi.y), hi.z);
    vec4 acc = vec4(0.0);
    if (leave > enter) {
        float dt = (leave - enter) / float(u_steps);
        // Each texel's samples start at its own fraction of a step (interleaved gradient
        // noise): samples at the same depths for every texel would cut the volume into
        // slices, shelves stacked up a tower; staggered, what is left is a texel-fine dither
        // that the impostor's filtering evens out. A hash, not interleaved gradient noise:
        // IGN's rows of near-equal offsets showed as vertical streaks once the edge was sharp.
        float jitter = fract(sin(dot(gl_FragCoord.xy, vec2(12.9898, 78.233))) * 43758.5453);
        float keep = 1.0;
        for (int i = 0; i < u_steps; ++i) {
            vec3 p = u_eye + dir * (enter + (float(i) + jitter) * dt);
            vec3 tc = p / (2.0 * u_half) + 0.5;
            vec4 b = texture(u_light1, tc);
            if (b.b > DENSITY_FLOOR) {
                // Billows finer than the automaton's cells: the noise eats thin cloud, the
                // core keeps its density (a remap of the density by the noise).
                vec3 q = (p + u_half) * u_noise_per_m;
                float billow = texture(u_noise, q).r;
                float bite = u_erosion * billow;
                float dens = clamp((b.b - bite) / max(1.0 - bite, 1e-3), 0.0, 1.0);
                // A cumulus's edge is sharp: thin cloud firms up quickly (u_sharpen 0: as is).
                dens = mix(dens, smoothstep(0.15, 0.35, dens), u_sharpen);
                vec4 a = texture(u_light0, tc);
                // The billows' own light, finer than the lit cells: where the billows
                // thicken toward the light, this point is on a billow's shaded side (the
                // noise's rise over BILLOW_PROBE_M toward the light, as a depth).
                float toward = texture(u_noise, q + u_key_dir * (BILLOW_PROBE_M * u_noise_per_m)).r;
                float own = exp(-u_billow_shadow * max(toward - billow, 0.0));
                vec3 rad = (a.r * u_weights[0] + a.g * u_weights[1] + a.b * u_weights[2]
                          + a.a * u_weights[3] + b.r * u_weights[4] + b.g * u_weights[5]) * own
                         + u_ambient;
                float alpha = 1.0 - exp(-u_ext_per_m * dens * dt);
                acc.rgb += keep * alpha * exposed(rad);
                keep *= 1.0 - alpha;
                if (keep < 0.004) {
                    break;
                }
            }
        }
        acc.a = 1.0 - keep;
    }
    f_colour = acc;  // premultiplied
}
#endif
