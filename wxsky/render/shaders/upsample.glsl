// Bilinear upscale of a premultiplied layer drawn at reduced resolution to the full viewport.
// Soft cloud sprites lose nothing visible at half resolution, and llvmpipe's fill rate is
// the daemon's bottleneck (docs/ARCHITECTURE.md).

#if defined VERTEX_SHADER
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_source;
uniform vec2 u_target_size;
out vec4 f_colour;
void main() {
    f_colour = texture(u_source, gl_FragCoord.xy / u_target_size);
}
#endif
