// Shared helpers. Colours are linear 0..1; outputs are premultiplied alpha.

vec3 sky_colour(vec3 ray, vec3 sun_dir, vec3 zenith, vec3 horizon, vec3 ground, vec3 sun_rgb) {
    float up = ray.z;
    vec3 col;
    if (up >= 0.0) {
        // A square-root ramp keeps the horizon band narrow, as a real sky's is.
        col = mix(horizon, zenith, sqrt(up));
    } else {
        col = mix(horizon, ground, smoothstep(0.0, 0.08, -up));
    }
    float cos_sun = dot(ray, sun_dir);
    // Forward-scattering glow around the sun, strongest near the horizon.
    float glow = pow(max(cos_sun, 0.0), 48.0) * 0.35 + pow(max(cos_sun, 0.0), 6.0) * 0.08;
    col += sun_rgb * glow * (up >= 0.0 ? 1.0 : 0.2);
    return col;
}

// Integer hash (Chris Wellons' lowbias32): decorrelated bits from neighbouring cell indices,
// for per-star details that the star texture has no channel left for.
uint hash_u32(uint x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

float hash_unit(uint x) {
    return float(hash_u32(x) >> 8) / 16777216.0;
}
