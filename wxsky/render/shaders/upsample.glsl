// Bilinear upscale of a premultiplied layer drawn at reduced resolution to the full viewport.
// Soft cloud sprites lose nothing visible at half resolution, and llvmpipe's fill rate is
// the daemon's bottleneck (docs/ARCHITECTURE.md).

#if defined VERTEX_SHADER
#include "screen_triangle.glsl"
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_source;
uniform vec2 u_target_size;
out vec4 f_colour;
void main() {
    f_colour = texture(u_source, gl_FragCoord.xy / u_target_size);
}
#endif
