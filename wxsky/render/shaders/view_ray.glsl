// The camera (ENU basis, field of view, the target's size in pixels) and the view ray through
// a fragment's pixel (include in a fragment stage). From the pixel's own position, not a
// varying, so that every quad the pixel is drawn by gives it the same ray to the last bit.
// NDC y is flipped with respect to the image (row 0 is the top), as in every projection.
uniform vec3 u_right;
uniform vec3 u_up;
uniform vec3 u_forward;
uniform vec2 u_tan_half_fov;
uniform vec2 u_target_size;       // pixels

vec3 view_ray() {
    vec2 ndc = gl_FragCoord.xy / u_target_size * 2.0 - 1.0;
    return normalize(u_forward + ndc.x * u_tan_half_fov.x * u_right
                     - ndc.y * u_tan_half_fov.y * u_up);
}
