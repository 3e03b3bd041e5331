// Camera-facing cloud sprites (Wang), instanced, drawn back to front, premultiplied alpha.
// Sprite centres arrive relative to the eye so float32 keeps centimetre precision.

#if defined VERTEX_SHADER
in vec2 in_corner;        // per vertex: (-1..1, -1..1)
in vec3 in_centre;        // per instance: centre minus eye, metres
in float in_size;
in float in_rotation;
in float in_texture;
in vec4 in_rgba;
uniform mat3 u_view_rot;
uniform mat4 u_proj;
out vec2 v_uv;
out vec4 v_rgba;
void main() {
    vec3 c = u_view_rot * in_centre;
    float s = sin(in_rotation), k = cos(in_rotation);
    vec2 corner = mat2(k, s, -s, k) * in_corner;
    vec3 pos = c + vec3(corner * 0.5 * in_size, 0.0);
    gl_Position = u_proj * vec4(pos, 1.0);
    float cell = in_texture;
    vec2 origin = vec2(mod(cell, float(SHEET_CELLS)), floor(cell / float(SHEET_CELLS)));
    v_uv = (origin + in_corner * vec2(0.5, -0.5) + 0.5) / float(SHEET_CELLS);
    // Sprites the eye is about to pass through fade out instead of filling the screen.
    float dist = length(c);
    float near_fade = smoothstep(0.1 * in_size, 0.6 * in_size, dist);
    v_rgba = vec4(in_rgba.rgb, in_rgba.a * near_fade);
}
#endif

#if defined FRAGMENT_SHADER
in vec2 v_uv;
in vec4 v_rgba;
uniform sampler2D u_sheet;
out vec4 f_colour;
void main() {
    vec4 t = texture(u_sheet, v_uv);
    float a = t.a * v_rgba.a;
    f_colour = vec4(v_rgba.rgb * t.rgb * a, a);
}
#endif
