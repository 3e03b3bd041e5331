/* HDR layers (protocol §1.2, RGBA16F): half floats to floats, and the daemon's display
 * transform (wxsky/scene/exposure.py `display`, render/shaders/display.glsl), so a host that
 * composites RGBA16F layers in linear shows them through the same exposure and tone map. */
#include "internal.h"

#include <math.h>
#include <string.h>

float wxsky_half_to_float(uint16_t half) {
    uint32_t sign = (uint32_t)(half >> 15) << 31;
    uint32_t exponent = (half >> 10) & 0x1fu;
    uint32_t mantissa = half & 0x3ffu;
    uint32_t bits;
    if (exponent == 0x1fu) { /* inf or NaN: keep the payload */
        bits = sign | 0x7f800000u | (mantissa << 13);
    } else if (exponent != 0) { /* normal: rebias 15 -> 127 */
        bits = sign | ((exponent + 112u) << 23) | (mantissa << 13);
    } else if (mantissa == 0) { /* signed zero */
        bits = sign;
    } else { /* subnormal: mantissa * 2^-24, exact in a float */
        float value = (float)mantissa * 5.9604644775390625e-8f;
        memcpy(&bits, &value, sizeof bits);
        bits |= sign;
    }
    float out;
    memcpy(&out, &bits, sizeof out);
    return out;
}

/* exposure.py's constants: Narkowicz's form of the ACES RRT+ODT fit with a toe of slope 1. */
#define TM_A 2.51
#define TM_B 0.14
#define TM_C 2.43
#define TM_D 0.70
#define TM_E 0.14
/* Past the curve's white (TM_WHITE) a colour burns toward white: BURN_MAX of the way at
 * BURN_FULL times the white (exposure.py burn). */
#define TM_WHITE 7.241657386773973
#define BURN_FULL 4.0
#define BURN_MAX 0.9

static double burn(double m) {
    double t = (m / TM_WHITE - 1.0) / (BURN_FULL - 1.0);
    t = t < 0.0 ? 0.0 : (t > 1.0 ? 1.0 : t);
    return BURN_MAX * t * t * (3.0 - 2.0 * t);
}

static double tone_curve(double x) {
    double y = x * (TM_A * x + TM_B) / (x * (TM_C * x + TM_D) + TM_E);
    return y < 0.0 ? 0.0 : (y > 1.0 ? 1.0 : y);
}

static double srgb_encode(double x) {
    x = x < 0.0 ? 0.0 : (x > 1.0 ? 1.0 : x);
    return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}

void wxsky_display(const float linear_rgb[3], float exposure, float out_rgb[3]) {
    double c[3];
    double m = 0.0;
    for (int i = 0; i < 3; i++) {
        double v = (double)linear_rgb[i] * (double)exposure;
        c[i] = v > 0.0 ? v : 0.0; /* also NaN -> 0: the comparison is false */
        m = c[i] > m ? c[i] : m;
    }
    /* Max-RGB: the curve on the largest channel, every channel scaled by the same factor
     * (exposure.py tone_map); an infinite channel saturates to 1 with the others at 0. */
    double scale = 0.0, y = 0.0;
    if (m > 0.0 && isfinite(m)) {
        y = tone_curve(m);
        scale = y / m;
    }
    double w = isfinite(m) ? burn(m) : BURN_MAX; /* the sun's disc burns white */
    if (!isfinite(m))
        y = 1.0;
    for (int i = 0; i < 3; i++) {
        double v = isfinite(m) ? c[i] * scale : (isinf(c[i]) ? 1.0 : 0.0);
        out_rgb[i] = (float)srgb_encode(v + (y - v) * w);
    }
}
