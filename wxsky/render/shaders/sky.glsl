// Sky dome for one camera: gradient by elevation and sun, sun disc. Full-screen triangle.
#include "common.glsl"

#if defined VERTEX_SHADER
out vec2 v_ndc;
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    v_ndc = p;
    gl_Position = vec4(p, 0.0, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
in vec2 v_ndc;
out vec4 f_colour;
uniform vec3 u_right;
uniform vec3 u_up;
uniform vec3 u_forward;
uniform vec2 u_tan_half_fov;
uniform vec3 u_sun_dir;
uniform vec3 u_zenith;
uniform vec3 u_horizon;
uniform vec3 u_ground;
uniform vec3 u_sun_rgb;
uniform float u_sun_cos_radius;
void main() {
    // NDC y is flipped with respect to the image (row 0 is the top), as in every projection.
    vec3 ray = normalize(u_forward + v_ndc.x * u_tan_half_fov.x * u_right
                         - v_ndc.y * u_tan_half_fov.y * u_up);
    vec3 col = sky_colour(ray, u_sun_dir, u_zenith, u_horizon, u_ground, u_sun_rgb);
    float disc = smoothstep(u_sun_cos_radius - 0.00002, u_sun_cos_radius + 0.00002,
                            dot(ray, u_sun_dir));
    col = mix(col, vec3(1.0, 0.98, 0.9) * 1.2, disc * step(-0.01, ray.z) * length(u_sun_rgb));
    f_colour = vec4(clamp(col, 0.0, 1.0), 1.0);
}
#endif
