// The vertex stage of a pass over a rectangle of the target: u_rect, NDC x0, y0, x1, y1, drawn
// as a strip of 4 vertices (include inside `#if defined VERTEX_SHADER`).
uniform vec4 u_rect;
void main() {
    vec2 p = vec2((gl_VertexID & 1) == 0 ? u_rect.x : u_rect.z,
                  (gl_VertexID & 2) == 0 ? u_rect.y : u_rect.w);
    gl_Position = vec4(p, 0.0, 1.0);
}
