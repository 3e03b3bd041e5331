// A tower's impostor (tower_march.glsl) drawn into the near layer between the sprites at its
// distance: the two impostors of the automaton steps around the tower's age cross-faded (so
// growth is continuous), faded into the haze as a sprite at its distance is
// (layout.fade_by_range), premultiplied alpha.

#if defined VERTEX_SHADER
uniform mat3 u_view_rot;
uniform mat4 u_proj;
uniform vec3 u_centre;   // the box's middle minus the eye, metres
uniform vec3 u_axis_u;   // the impostor quad's half extents (as it was drawn)
uniform vec3 u_axis_v;
out vec2 v_uv;
void main() {
    vec2 p = vec2(float(gl_VertexID & 1) * 2.0 - 1.0, float((gl_VertexID >> 1) & 1) * 2.0 - 1.0);
    v_uv = p * 0.5 + 0.5;
    vec3 world = u_centre + p.x * u_axis_u + p.y * u_axis_v;
    gl_Position = u_proj * vec4(u_view_rot * world, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
#include "display.glsl"
in vec2 v_uv;
uniform sampler2D u_first;
uniform sampler2D u_second;
uniform float u_mix;
uniform float u_haze;
uniform vec3 u_haze_rgb;
uniform float u_alpha;
uniform vec3 u_flash_rgb;  // lightning's light on the tower (scene/lightning.py), or 0
out vec4 f_colour;
void main() {
    vec4 c = mix(texture(u_first, v_uv), texture(u_second, v_uv), u_mix);
    c.rgb = min(c.rgb + u_flash_rgb * c.a, vec3(c.a));
    c.rgb = c.rgb * (1.0 - u_haze) + u_haze_rgb * (c.a * u_haze);
    c *= u_alpha;
    if (c.a < 1.0 / 512.0) {
        discard;
    }
    f_colour = legacy_output(c);
}
#endif
