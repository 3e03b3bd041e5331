// The vertex stage of a pass over the whole target: one triangle of 3 vertices that covers it
// (include inside `#if defined VERTEX_SHADER`; the fragment stage works from gl_FragCoord).
void main() {
    vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, float((gl_VertexID & 2) << 1) - 1.0);
    gl_Position = vec4(p, 0.0, 1.0);
}
