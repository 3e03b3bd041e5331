// The automatic exposure's meter (issue 41): the sky layer with the near layer over it, point
// sampled at a small grid's texel centres (a 64x36 target) for a read-back of a few kilobytes.
// The ring's impostors are left out: they are world quads a host places, and the near layer and
// sky hold most of what an eye adapts to.

#if defined VERTEX_SHADER
#include "screen_triangle.glsl"
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_sky;
uniform sampler2D u_near;
uniform vec2 u_target_size;
out vec4 f_colour;
void main() {
    vec2 uv = gl_FragCoord.xy / u_target_size;
    vec4 sky = texture(u_sky, uv);
    vec4 near = texture(u_near, uv);
    f_colour = vec4(near.rgb + (1.0 - near.a) * sky.rgb, 1.0);
}
#endif
