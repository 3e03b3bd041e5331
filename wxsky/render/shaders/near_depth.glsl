// The near layer's depth as the segment's RGBA8 `near_depth` layer: each pixel's distance to
// the nearest sprite that shows there (the NEAR_DEPTH sprite pass's MIN, metres, in a float
// target) as q = log2(1 + d) / NEAR_DEPTH_LOG2_RANGE in 24 bits, R the high byte, G, B the
// lower ones, A 255; a pixel no sprite shows at is (0, 0, 0, 0). docs/protocol.md §1.5.

#if defined VERTEX_SHADER
#include "screen_triangle.glsl"
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_depth;
out vec4 f_colour;
void main() {
    float d = texelFetch(u_depth, ivec2(gl_FragCoord.xy), 0).r;
    if (!(d < NEAR_DEPTH_NONE)) {
        f_colour = vec4(0.0);
        return;
    }
    float q = clamp(log2(1.0 + max(d, 0.0)) / NEAR_DEPTH_LOG2_RANGE, 0.0, 1.0);
    float v = floor(q * 16777215.0 + 0.5);
    float r = floor(v / 65536.0);
    float g = floor((v - r * 65536.0) / 256.0);
    float b = v - r * 65536.0 - g * 256.0;
    f_colour = vec4(r, g, b, 255.0) / 255.0;
}
#endif
