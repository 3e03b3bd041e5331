"""Scene-linear colour, exposure and the tone map: how a layer's colour becomes display values.

Every pass computes scene-linear RGB (premultiplied by alpha), and `render/shaders/display.glsl`
turns it into what an 8-bit layer holds: `display(x) = srgb_encode(tone_map(x * exposure))`.
This module is its numpy mirror (tests hold the two together), the `[render] exposure` kind,
and the automatic exposure's controller.

The tone map is the ACES filmic curve fitted by Narkowicz (2015), applied to the largest of
the three channels and the colour scaled by the same factor ("max-RGB"): a bright sky blue
keeps its hue (the per-channel curve saturates blue first, then green catches up, and the sky
turns cyan), and the curve's long shoulder rolls highlights off over almost 3 EV above the
mid-tones instead of clipping them (it reaches 1 at 7.24 times the exposed white). It has a
closed-form inverse (a quadratic), which the legacy path needs.

Today's passes still compute display-referred colours, 0..1 (the artist colours that were the
look before issue 41): `from_legacy` is the scene-linear colour that `display` turns back into
exactly that value at LEGACY_EXPOSURE, so their look does not change at the default exposure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from wxsky.schema import Custom, Number

F64 = npt.NDArray[np.float64]

# Narkowicz's form of the ACES RRT+ODT fit, x (A x + B) / (x (C x + D) + E) clamped to 0..1,
# with a toe of slope 1 (B = E) instead of the fit's 0.21 (B 0.03): the fit's toe showed a
# level field under a 5 deg sun, a tenth of the sky's luminance, at a fortieth of its display
# light, black, where a camera or an eye shows it dark but with its colour. D (0.59 in the
# fit) is raised so the curve reaches white at the same 7.24 and the mid-tones stay (an
# exposed 0.12 shows at sRGB 0.50 as before, the shoulder within 0.03).
TM_A, TM_B, TM_C, TM_D, TM_E = 2.51, 0.14, 2.43, 0.70, 0.14
# The exposed value at which the curve reaches 1 (its clip): the larger root of
# (A - C) x^2 + (B - D) x - E = 0.
TM_WHITE = (-(TM_B - TM_D) + math.sqrt((TM_B - TM_D) ** 2 + 4 * (TM_A - TM_C) * TM_E)) / (
    2 * (TM_A - TM_C)
)
# The exposure (a scale on scene-linear colour) at which a legacy display colour comes back
# unchanged: today's look is scene-linear = from_legacy(value) at this exposure.
LEGACY_EXPOSURE = 1.0
# A legacy value of 1 has no finite scene-linear colour (the curve reaches 1 at TM_WHITE and
# stays there): it is read as this, a quarter of an 8-bit level below 1, which display turns
# back into 255.
LEGACY_MAX = 1.0 - 1.0 / 1024.0

# [render] exposure as a number: EV relative to LEGACY_EXPOSURE, the scale being 2^EV
# (+1 is twice as bright). The range spans a physical sky's luminances in cd/m^2 (a clear
# noon sky ~ 8000, 2^-13) to a moonless night's (~ 0.001, 2^+10) with room either side.
EXPOSURE_EV = Number(-20.0, 20.0, unit="EV")
AUTO = "auto"
# The automatic exposure keeps within this range (EV) and aims the log-average luminance of the
# composite at KEY (the mid-grey of photography: 18 % reflectance, about 0.18 scene-linear).
AUTO_EV_RANGE = (-16.0, 16.0)
KEY = 0.18
# Eye and camera adapt over about a second: the exposure moves toward its target with this time
# constant (63 % of the way in ADAPT_S, 95 % in 3 ADAPT_S).
ADAPT_S = 0.4
# The metered luminance's floor: a black frame (or a black layer) must not ask for infinity.
MIN_LUMINANCE = 1e-6
# Whether the passes compute physical (scene-referred) colour, so that "auto" meters the
# frames: False while they draw the artist colours of before issue 41 (from_legacy), whose
# look "auto" keeps; the physical atmosphere (issue 41 item 1) turns it on.
SCENE_REFERRED = False
# Past the curve's white, colours burn toward white: fully (BURN_MAX of the way) at BURN_FULL
# times the white. The sun's disc is thousands of times it; a silver lining a few times.
BURN_FULL = 4.0
BURN_MAX = 0.9
# Rec. 709 luminance weights (the layers' primaries are sRGB's).
LUMA = np.array([0.2126, 0.7152, 0.0722])


def _exposure(value: object) -> float | str:
    if value == AUTO:
        return AUTO
    if isinstance(value, str):
        raise ValueError(f'must be "auto" or a number of EV in -20..20, got {value!r}')
    try:
        return float(EXPOSURE_EV._convert(value))
    except ValueError:
        raise ValueError(f'must be "auto" or a number of EV in -20..20, got {value!r}') from None


EXPOSURE = Custom(_exposure, '"auto" or a number of EV in -20..20 (scale 2^EV)')
"""The `[render] exposure` kind: "auto" or EV (a float, scale = 2^EV)."""


def scale_of_ev(ev: float) -> float:
    """The scale on scene-linear colour for `ev` (ValueError if it is not in EXPOSURE_EV)."""
    checked = float(EXPOSURE_EV.validate("exposure", ev))
    return float(LEGACY_EXPOSURE * 2.0**checked)


def initial_scale(setting: float | str) -> float:
    """The scale to draw with for a `[render] exposure` setting before any metering: its EV's,
    or for "auto" the legacy one: the passes' colours are display-referred until the physical
    sky and cloud light land (SCENE_REFERRED), and metering them would only undo their
    artists' exposure."""
    return LEGACY_EXPOSURE if setting == AUTO else scale_of_ev(float(setting))


def needs_variable(setting: float | str) -> bool:
    """Whether a renderer for this `[render] exposure` must draw at exposures other than EV 0
    (Renderer's `variable_exposure`): a number other than 0, or "auto" once it meters."""
    if setting == AUTO:
        return SCENE_REFERRED
    return initial_scale(setting) != LEGACY_EXPOSURE


def check_scale(scale: float) -> float:
    """`scale` if it is a finite exposure scale within EXPOSURE_EV, else ValueError: what the
    renderer accepts before a value becomes a shader's uniform (NaN and inf never do)."""
    if not isinstance(scale, (int, float)) or isinstance(scale, bool):
        raise ValueError(f"exposure scale must be a number, got {scale!r}")
    lo, hi = (LEGACY_EXPOSURE * 2.0**ev for ev in EXPOSURE_EV.bounds)
    if not (math.isfinite(scale) and lo <= scale <= hi):
        raise ValueError(f"exposure scale must be finite and in 2^-20..2^20, got {scale!r}")
    return float(scale)


# -- the tone map (display.glsl's twin) -----------------------------------------------------


# The tone map runs on every frame's sprites: np.minimum/np.maximum rather than np.clip, whose
# Python wrapper cost more than the arithmetic on a few hundred values.


def tone_curve(x: F64) -> F64:
    x = np.maximum(np.asarray(x, np.float64), 0.0)
    y: F64 = np.minimum(x * (TM_A * x + TM_B) / (x * (TM_C * x + TM_D) + TM_E), 1.0)
    return y


def tone_curve_inverse(y: F64) -> F64:
    """x >= 0 with tone_curve(x) = y, for y in 0..1 (1 gives TM_WHITE)."""
    y = np.clip(np.asarray(y, np.float64), 0.0, 1.0)
    a = y * TM_C - TM_A  # < 0 for every y <= 1
    b = y * TM_D - TM_B
    c = y * TM_E
    x: F64 = (-b - np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))) / (2.0 * a)
    return x


def burn(m: F64) -> F64:
    """How far a colour whose largest exposed channel is `m` is burnt toward white: 0 up to
    the curve's white (TM_WHITE), rising smoothly to BURN_MAX at BURN_FULL times it. Only
    what the curve has already clipped burns (the sun's disc, a blazing silver lining): the
    colours below it keep their hue exactly, and `tone_map_inverse` stays exact for them."""
    t = (np.asarray(m, np.float64) / TM_WHITE - 1.0) / (BURN_FULL - 1.0)
    t = np.minimum(np.maximum(t, 0.0), 1.0)
    out: F64 = BURN_MAX * t * t * (3.0 - 2.0 * t)
    return out


def tone_map(rgb: F64) -> F64:
    """Max-RGB: the curve on the largest channel, the colour scaled by the same factor; past
    the curve's white the colour burns toward white (`burn`), as film and an eye see the
    low sun's disc: white-hot, not an orange dot."""
    rgb = np.maximum(np.asarray(rgb, np.float64), 0.0)
    m = rgb.max(axis=-1, keepdims=True)
    safe = np.where(m > 0.0, m, 1.0)
    y = tone_curve(safe)
    hue: F64 = np.where(m > 0.0, rgb * (y / safe), 0.0)
    out: F64 = hue + (y - hue) * burn(m)
    return out


def tone_map_inverse(rgb: F64) -> F64:
    rgb = np.clip(np.asarray(rgb, np.float64), 0.0, 1.0)
    n = rgb.max(axis=-1, keepdims=True)
    safe = np.where(n > 0.0, n, 1.0)
    # Below the curve's white nothing burnt (exact); a clipped value reads as the smallest
    # colour giving it, at TM_WHITE, which does not burn either.
    out: F64 = np.where(n > 0.0, rgb * (tone_curve_inverse(safe) / safe), 0.0)
    return out


def srgb_encode(linear: F64) -> F64:
    x = np.minimum(np.maximum(np.asarray(linear, np.float64), 0.0), 1.0)
    out: F64 = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return out


def srgb_decode(encoded: F64) -> F64:
    x = np.clip(np.asarray(encoded, np.float64), 0.0, 1.0)
    out: F64 = np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))
    return out


def display(linear_rgb: F64, exposure: float) -> F64:
    """Straight (not premultiplied) scene-linear colour -> display values 0..1."""
    return srgb_encode(tone_map(np.asarray(linear_rgb, np.float64) * exposure))


def display_channels(linear: F64, exposure: float) -> F64:
    """`display` of (3, N) colours channel by channel, (3, N): a frame's sprites (and their
    rims) every frame. The same values (to rounding): the largest channel as two maxima of
    rows rather than a reduction over each colour's three, and the burn left out when nothing
    reaches the curve's white (almost every frame)."""
    rgb = np.asarray(linear, np.float64) * exposure
    np.maximum(rgb, 0.0, out=rgb)
    m = np.maximum(np.maximum(rgb[0], rgb[1]), rgb[2])
    lit = m > 0.0
    safe = np.where(lit, m, 1.0)
    scale = np.where(lit, tone_curve(safe) / safe, 0.0)
    out: F64 = rgb * scale
    if len(m) and float(m.max()) > TM_WHITE:
        y = m * scale
        out += (y - out) * burn(m)
    return srgb_encode(out)


def display_inverse(display_rgb: F64, exposure: float) -> F64:
    """The scene-linear colour `display` turns into `display_rgb` (clipped values: their
    smallest such colour)."""
    return tone_map_inverse(srgb_decode(display_rgb)) / exposure


def from_legacy(legacy_rgb: F64) -> F64:
    """The scene-linear colour of a display-referred legacy colour (display.glsl's
    from_legacy)."""
    return display_inverse(np.minimum(np.asarray(legacy_rgb, np.float64), LEGACY_MAX), 1.0) / (
        LEGACY_EXPOSURE
    )


def luminance(linear_rgb: F64) -> F64:
    out: F64 = np.asarray(linear_rgb, np.float64) @ LUMA
    return out


def log_average_luminance(linear_rgb: F64) -> float:
    """exp(mean(log(L))) over the pixels of a (..., 3) scene-linear picture, each L at least
    MIN_LUMINANCE; non-finite pixels are left out (and a picture of none meters as
    MIN_LUMINANCE)."""
    lum = luminance(linear_rgb).reshape(-1)
    lum = lum[np.isfinite(lum)]
    if lum.size == 0:
        return MIN_LUMINANCE
    return float(np.exp(np.mean(np.log(np.maximum(lum, MIN_LUMINANCE)))))


def auto_target_ev(log_average: float) -> float:
    """The EV that puts a picture of this log-average luminance at KEY, within AUTO_EV_RANGE."""
    if not math.isfinite(log_average) or log_average <= 0.0:
        log_average = MIN_LUMINANCE
    ev = math.log2(KEY / (max(log_average, MIN_LUMINANCE) * LEGACY_EXPOSURE))
    return min(max(ev, AUTO_EV_RANGE[0]), AUTO_EV_RANGE[1])


@dataclass
class AutoExposure:
    """An eye's adaptation: `ev` moves toward the target of each metered frame exponentially
    with time constant ADAPT_S, so a cut from a dark to a bright scene settles in about a
    second. Starts at `ev` (0: LEGACY_EXPOSURE) until the first metering."""

    ev: float = 0.0
    adapt_s: float = ADAPT_S

    def update(self, log_average: float, dt_s: float) -> float:
        """Move toward the target for a frame metered at `log_average`, `dt_s` after the last
        update (a negative or non-finite dt moves nothing); the new EV."""
        target = auto_target_ev(log_average)
        if math.isfinite(dt_s) and dt_s > 0.0:
            keep = math.exp(-dt_s / self.adapt_s)
            self.ev = target + (self.ev - target) * keep
        return self.ev

    @property
    def scale(self) -> float:
        return float(LEGACY_EXPOSURE * 2.0**self.ev)
