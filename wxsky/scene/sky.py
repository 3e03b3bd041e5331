"""Sun, moon and stars for the sky pass, and the sky-dome parameters (Roden & Parberry's six
controls) derived from the weather.

Sun and moon come from `wxsky.scene.ephemeris` (Meeus: apparent topocentric places,
refracted; within 0.01° of PyEphem in elevation). The star field and the cloud dome are drawn
by the renderer from the values here: how dark the sky is for stars, the rotation that fixes
stars to the celestial sphere, the clock their flicker runs on, and `DomeControls`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np
import numpy.typing as npt

from wxsky.scene.atmosphere import (
    LUMA,
    MIE_PEAK_SHARE,
    MIE_SCALE_HEIGHT_M,
    AtmosphereLuts,
    display_exposure,
    horizon_elevation_rad,
    sample_table,
    sky_view_elevation,
    sky_view_v_above,
    sun_irradiance,
)
from wxsky.scene.ephemeris import (
    Matrix3,
    MoonPosition,
    SunPosition,
    celestial_from_enu,
    sun_and_moon_smooth,
)
from wxsky.scene.ephemeris import sun_position as _ephemeris_sun_position
from wxsky.scene.exposure import display
from wxsky.weather.state import CloudLayer, CloudType, Observer, WeatherState

__all__ = [
    "Bodies",
    "DomeControls",
    "MoonPosition",
    "SkyParams",
    "SunPosition",
    "bodies_for",
    "sky_params",
    "sun_position",
]

RGB = tuple[float, float, float]
F64 = npt.NDArray[np.float64]

SKY_EPOCH_UTC = datetime(2000, 1, 1, tzinfo=UTC)
# Ice clouds and anything based this high belong to the dome overhead, where the sprite
# layer's thin cirrus sheets leave the sky between them bare.
HIGH_TYPES = frozenset({CloudType.CIRRUS, CloudType.CIRROSTRATUS, CloudType.CIRROCUMULUS})
HIGH_BASE_M = 6000.0
# How much a whole sky of high ice cloud dims the moon's disc (a cirrostratus veil's optical
# depth is under one: the moon shows through it, ringed by its halo).
THIN_MOON_DIM = 0.3
# The dome's "height" control is a layer base between sea level and this (MSL).
DOME_TOP_M = 13_000.0
# The wind aloft that makes the dome's "speed" control 1.
DOME_MAX_WIND_MPS = 60.0
# Sprite clouds end here (SceneSettings.max_range_m's default); beyond, the dome stands in for
# the distant part of every layer along the horizon.
DISTANT_CLOUD_M = 40_000.0
# How dense each type looks on the dome: thin ice veils let the sky through, water decks not.
_TYPE_DENSITY = {
    CloudType.CIRRUS: 0.05,
    CloudType.CIRROCUMULUS: 0.2,
    CloudType.CIRROSTRATUS: 0.35,
    CloudType.ALTOCUMULUS: 0.45,
    CloudType.CUMULUS: 0.5,
    CloudType.STRATOCUMULUS: 0.6,
    CloudType.ALTOSTRATUS: 0.75,
    CloudType.STRATUS: 0.85,
    CloudType.CUMULONIMBUS: 0.9,
    CloudType.NIMBOSTRATUS: 0.95,
}
# The sun, moon and the sky's colours are worked out for the time down to an eighth of a
# second (`on_sky_step`): the sun moves 9e-6 rad in that, under half of what the sky layer
# redraws a strip for (render.sky_layer.SKY_REUSE_TOLERANCE), and at 30 fps seven frames in
# eight find the sky of the frame before (`sky_params`), and with it its lights. The clock
# the stars twinkle and the cloud dome drifts on (`SkyParams.sky_time_s`) runs every frame.
SKY_STEP_US = 125_000
_IDENTITY: Matrix3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
_MOON_DOWN = MoonPosition(-90.0, 0.0, 0.0, 0.0, 0.0, 384_400.0)


@dataclass(frozen=True)
class DomeControls:
    """Roden & Parberry's six controls of the cloud dome, each 0..1, plus where it shows.

    The dome is a textured plane at the highest layer's base: drawn overhead for thin high
    cloud (`high_cover`) and, for every layer, along the horizon below `horizon_deg`, where
    the sprite clouds have ended. Sprite clouds are composited over it.
    """

    cover: float = 0.0  # total cloud cover (SkyParams.cover)
    height: float = 0.0  # highest layer's base / DOME_TOP_M: stretches the texture
    density: float = 0.0  # cover-weighted by type: dense is smooth and opaque, thin is wispy
    sunset: float = 0.0  # the red gradient's share (SkyParams.sunset)
    speed: float = 0.0  # wind at the highest layer / DOME_MAX_WIND_MPS: moves the texture
    time: float = 0.0  # local mean solar time as a fraction of the day
    high_cover: float = 0.0  # cover of ice/high layers: the part shown overhead
    horizon_deg: float = 0.0  # the sprites' far edge seen from the ground, elevation
    drift_toward_deg: float = 0.0  # where the wind aloft carries the dome, true
    # Cover of cirrostratus, the veil of ice prisms that bends sunlight into the 22° halo.
    veil: float = 0.0
    # The ground band below the horizon (sky.glsl `ground_band`): the flat ground under the
    # observer, MSL, and the haze distance in the air over it (the surface visibility's, also
    # when the eye is above the hazy layer and SkyParams.haze_m is the clear air's).
    ground_m: float = 0.0
    surface_haze_m: float = 0.0

    def to_dict(self) -> dict[str, float]:
        return {
            "cover": self.cover,
            "height": self.height,
            "density": self.density,
            "sunset": self.sunset,
            "speed": self.speed,
            "time": self.time,
            "high_cover": self.high_cover,
            "horizon_deg": self.horizon_deg,
            "drift_toward_deg": self.drift_toward_deg,
            "veil": self.veil,
            "ground_m": self.ground_m,
            "surface_haze_m": self.surface_haze_m,
        }


@dataclass(frozen=True)
class SkyParams:
    """Everything the sky pass and cloud shading need; also published to hosts."""

    sun: SunPosition
    zenith_rgb: RGB
    horizon_rgb: RGB
    ground_rgb: RGB
    sun_rgb: RGB  # colour of direct sunlight on clouds
    ambient: float  # 0 (night) .. 1 (full day): scales the clouds' ambient colour levels
    sunset: float  # 0..1: how much of the red sunset gradient tints the sky and clouds
    cover: float  # 0..1: total cloud cover, Roden & Parberry's "cover" control
    haze_m: float  # distance over which clouds fade into the horizon colour
    moon: MoonPosition = _MOON_DOWN
    moon_rgb: RGB = (0.0, 0.0, 0.0)  # light of the moon's sunlit face over the sky
    moon_seen: float = 1.0  # the share of that light the cloud lets through (moon_veiled)
    # The sky above all cloud (what lights the top of a deck); None: as zenith/horizon_rgb.
    open_zenith_rgb: RGB | None = None
    open_horizon_rgb: RGB | None = None
    stars: float = 0.0  # 0 (day, overcast) .. 1 (clear astronomical night): star brightness
    dome: DomeControls = field(default_factory=DomeControls)
    # Clock of the star flicker and the dome drift: UTC seconds since SKY_EPOCH_UTC.
    sky_time_s: float = 0.0
    # Turns east-north-up into the equatorial frame of date, at the whole second, so that
    # the star field is pixel-still within a second and only flickers (it turns 0.004° a
    # second, far below a pixel).
    celestial_from_enu: Matrix3 = _IDENTITY
    # Top of the hazy boundary layer, MSL: haze_m holds below it, clear air above (the sky
    # pass fades the high-cloud dome only over the part of its ray below this).
    haze_top_m: float = math.inf
    # The physical atmosphere's tables (`[scene] sky = "physical"`, made off the frame path
    # by engine/atmosphere_work.py); None: Roden & Parberry's gradient (`zenith_rgb`, ...).
    atmosphere: AtmosphereLuts | None = None
    # The ground under the observer, MSL: the physical atmosphere's altitudes are above it
    # (the engine builds its tables with the observer's ground as the model's).
    ground_m: float = 0.0

    def with_atmosphere(self, luts: AtmosphereLuts | None) -> SkyParams:
        """This sky drawn from `luts` (None: from its gradient); every other field is this
        one's, the same objects (as `at_clock`)."""
        if luts is self.atmosphere:
            return self
        out = object.__new__(SkyParams)
        out.__dict__.update(self.__dict__)
        out.__dict__["atmosphere"] = luts
        return out

    def at_clock(self, sky_time_s: float) -> SkyParams:
        """This sky with its clock at sky_time_s (a later frame of the same sky step): every
        other field is this one's, the same objects, so what is kept by them still holds."""
        out = object.__new__(SkyParams)
        out.__dict__.update(self.__dict__)
        out.__dict__["sky_time_s"] = sky_time_s
        return out

    def haze_of(self, dist_m: F64 | float, up_m: F64 | float, eye_alt_m: float) -> F64:
        """The share of a cloud's colour that is air (`haze_share`) for clouds `dist_m` away
        and `up_m` above the eye (MSL `eye_alt_m`), in this sky's haze."""
        return haze_share(dist_m, up_m, eye_alt_m, self.haze_m, self.haze_top_m)

    @property
    def haze_rgb(self) -> RGB:
        """The colour distant clouds fade into (the airlight): the horizon's, greyed as far as
        cloud covers the sky. Under a full deck the haze is lit by the grey light through it,
        not by the dawn glow the sky's horizon keeps a touch of. With the physical atmosphere:
        the physical sky's own horizon as the sky pass shows it (`physical_haze_rgb`, averaged
        round the horizon; `haze_toward` gives it direction by direction)."""
        if self.atmosphere is not None:
            return physical_haze_rgb(self.atmosphere, self.cover)
        r, g, b = self.horizon_rgb
        luma = 0.2126 * r + 0.7152 * g + 0.0722 * b
        return _mix(self.horizon_rgb, (luma, luma, luma), smoothstep(0.6, 1.0, self.cover))

    def haze_toward(self, offsets_m: F64, eye_alt_m: float | None = None) -> F64:
        """(3, N) the colour each of N clouds at `offsets_m` ((3, N) from the eye, ENU) fades
        into: with the physical atmosphere the sky as the sky pass shows it right behind the
        cloud (its direction, no lower than just over the horizon), so a distant cloud melts
        into the sky behind it whichever way it lies from the sun; under a deck (`deck_share`
        from `eye_alt_m`), toward the air just over the horizon in the cloud's azimuth, at
        every elevation; else `haze_rgb`."""
        n = offsets_m.shape[1]
        luts = self.atmosphere
        if luts is None or n == 0:
            return np.repeat(np.asarray(self.haze_rgb, np.float64)[:, None], n, axis=1)
        deck = 0.0 if eye_alt_m is None else deck_share(self, eye_alt_m)
        return _sky_behind(luts, self.sun.direction_enu, self.cover, offsets_m, deck)

    def to_dict(self) -> dict[str, object]:
        return {
            "sun_elevation_deg": self.sun.elevation_deg,
            "sun_azimuth_deg": self.sun.azimuth_deg,
            "sun_direction_enu": list(self.sun.direction_enu),
            "moon_elevation_deg": self.moon.elevation_deg,
            "moon_azimuth_deg": self.moon.azimuth_deg,
            "moon_direction_enu": list(self.moon.direction_enu),
            "moon_illuminated_fraction": self.moon.illuminated_fraction,
            "moon_bright_limb_angle_deg": self.moon.bright_limb_angle_deg,
            "moon_rgb": list(self.moon_rgb),
            "zenith_rgb": list(self.zenith_rgb),
            "horizon_rgb": list(self.horizon_rgb),
            "ground_rgb": list(self.ground_rgb),
            "sun_rgb": list(self.sun_rgb),
            "ambient": self.ambient,
            "sunset": self.sunset,
            "cover": self.cover,
            "haze_m": self.haze_m,
            "haze_rgb": list(self.haze_rgb),
            "stars": self.stars,
            "dome": self.dome.to_dict(),
        }


def sun_position(time_utc: datetime, lat_deg: float, lon_deg: float) -> SunPosition:
    """The sun as an observer at sea level sees it (refracted); see `wxsky.scene.ephemeris`."""
    return _ephemeris_sun_position(time_utc, lat_deg, lon_deg)


BOUNDARY_LAYER_M = 2_000.0  # depth of the hazy mixed layer over the ground, at most
CLEAR_AIR_HAZE_M = 60_000.0  # haze distance in the clear air above it
KOSCHMIEDER = 3.912  # -ln(0.02): the contrast threshold that defines visibility
MIN_HAZE_M = 10.0  # in fog of no visibility at all, still a distance to divide by


@dataclass(frozen=True)
class Bodies:
    """The sun and moon of one moment and site, with the moment and site they are for."""

    time_utc: datetime
    observer: Observer
    sun: SunPosition
    moon: MoonPosition


def bodies_for(state: WeatherState, known: Bodies | None = None) -> Bodies:
    """The sun and moon at the state's site, for its time on the sky's step (`on_sky_step`):
    `known` where it is for exactly those, else worked out afresh (`sun_and_moon_smooth`:
    exact every two seconds, interpolated between). The ephemeris is the dearest part of the
    sky, and a frame asks for it more than once (its own sky, the scene the daemon reports)."""
    obs = state.observer
    at = on_sky_step(state.time_utc)
    if known is not None and known.time_utc == at and known.observer == obs:
        return known
    sun, moon = sun_and_moon_smooth(at, obs.lat_deg, obs.lon_deg, obs.alt_m)
    return Bodies(at, obs, sun, moon)


def on_sky_step(time_utc: datetime) -> datetime:
    """The time the sun, moon and sky colours are worked out for: time_utc down to a whole
    SKY_STEP_US."""
    return time_utc.replace(microsecond=time_utc.microsecond - time_utc.microsecond % SKY_STEP_US)


def sky_params(
    state: WeatherState, eye_alt_m: float | None = None, bodies: Bodies | None = None
) -> SkyParams:
    """The sky seen from eye_alt_m MSL (default: the observer's): only cloud above the eye
    greys and dims it, so a pilot who climbs out of an overcast deck sees the blue above it.
    `bodies`: the sun and moon already worked out for this moment, if they are (`bodies_for`).
    The sky of the last call is reused, on this moment's clock (`SkyParams.at_clock`), while
    what it is made from is the same: the frames of one sky step, at one cover and haze."""
    global _last_sky
    obs = state.observer
    known = bodies_for(state, bodies)
    eye_m = obs.alt_m if eye_alt_m is None else eye_alt_m
    clear, haze_top_m, haze_m, thick_clear = _seen_from(state, eye_m)
    whole_second = state.time_utc.replace(microsecond=0)
    clock_s = (state.time_utc - SKY_EPOCH_UTC).total_seconds()
    # The eye's height only through the cover and haze it sees, so a climb in clear air
    # reuses the sky too; the whole second for the dome's solar time and the star field; the
    # site through the bodies, which are for it.
    key = (known, clear, haze_m, whole_second, state.layers, state.wind, state.visibility_m)
    last = _last_sky  # one read: another thread may replace it
    if last is not None and last[0] == key:
        return last[1].at_clock(clock_s)
    made = _sky_params(
        state, known, 1.0 - clear, haze_m, haze_top_m, whole_second, clock_s, 1.0 - thick_clear
    )
    _last_sky = (key, made)
    return made


_last_sky: tuple[tuple[object, ...], SkyParams] | None = None


def _seen_from(state: WeatherState, eye_m: float) -> tuple[float, float, float, float]:
    """(clear share of the sky, top of the hazy layer, haze distance, the share clear of all
    but high ice cloud) for an eye at eye_m:
    kept for the last layers (by identity: a state's frames share them), visibility, ground
    and eye, which a level flight's frames share."""
    global _last_seen
    layers = state.layers
    key = (state.visibility_m, state.observer.alt_m, eye_m)
    last = _last_seen  # one read: another thread may replace it
    if last is not None and last[0] is layers and last[1] == key:
        return last[2]
    # Layers overlap at random (the usual assumption for total cloud amount): two 4/8 layers
    # hide 3/4 of the sky, not all of it, so a forming layer darkens the sky gradually.
    hidden = [min(1.0, lay.cover_oktas / 8.0) * _share_above(lay, eye_m) for lay in layers]
    clear = math.prod(1.0 - h for h in hidden)
    thick_clear = math.prod(
        1.0 - h for h, lay in zip(hidden, layers, strict=True) if not _is_high(lay)
    )
    haze_top_m = _haze_top_m(state)
    seen = (clear, haze_top_m, _haze_m(state, eye_m, haze_top_m), thick_clear)
    _last_seen = (layers, key, seen)
    return seen


_last_seen: (
    tuple[tuple[CloudLayer, ...], tuple[float, ...], tuple[float, float, float, float]] | None
)
_last_seen = None


def _sky_params(
    state: WeatherState,
    known: Bodies,
    cover: float,
    haze_m: float,
    haze_top_m: float,
    whole_second: datetime,
    clock_s: float,
    thick_cover: float,
) -> SkyParams:
    obs = state.observer
    sun, moon = known.sun, known.moon
    el = sun.elevation_deg
    day = smoothstep(-6.0, 10.0, el)  # civil twilight to well-lit day
    sunset = smoothstep(-8.0, 0.0, el) * (1.0 - smoothstep(2.0, 18.0, el))
    overcast_dim = 1.0 - 0.45 * smoothstep(0.6, 1.0, cover)

    night_zenith, night_horizon = (0.008, 0.012, 0.035), (0.025, 0.035, 0.07)
    day_zenith, day_horizon = (0.20, 0.40, 0.78), (0.68, 0.80, 0.94)
    zenith = _mix(night_zenith, day_zenith, day)
    horizon = _mix(night_horizon, day_horizon, day)
    horizon = _mix(horizon, (0.98, 0.58, 0.32), sunset * 0.85)
    zenith = _mix(zenith, (0.28, 0.30, 0.52), sunset * 0.4)
    open_zenith, open_horizon = zenith, horizon
    grey = (0.55, 0.57, 0.60)
    zenith = _mix(zenith, _scale(grey, day + 0.05), smoothstep(0.6, 1.0, cover) * 0.8)
    horizon = _mix(horizon, _scale(grey, day + 0.05), smoothstep(0.6, 1.0, cover) * 0.6)
    zenith, horizon = _scale(zenith, overcast_dim), _scale(horizon, overcast_dim)
    ground = _scale((0.30, 0.31, 0.28), 0.08 + 0.92 * day)
    sun_rgb = _mix((1.0, 0.98, 0.92), (1.0, 0.55, 0.25), sunset)
    sun_rgb = _scale(sun_rgb, smoothstep(-2.0, 4.0, el))

    # The first stars show at the end of civil twilight, all of them by astronomical night;
    # cloud thins them with the share of sky it hides.
    dark = 1.0 - smoothstep(-15.0, -4.0, el)
    stars = dark * math.sqrt(max(0.0, 1.0 - cover))
    # By day the moon is a pale disc a little brighter than the blue around it; near the
    # horizon the long path through the air reddens and dims it.
    low = 1.0 - smoothstep(0.0, 12.0, moon.elevation_deg)
    moon_rgb = _mix((0.96, 0.94, 0.88), (1.0, 0.72, 0.48), low * 0.8)
    moon_gain = (0.95 - 0.65 * day) * (1.0 - 0.35 * low)
    # Thin ice cloud dims the moon a little; water cloud hides it (`moon_veiled`).
    moon_seen = moon_veiled(thick_cover, cover)
    moon_gain *= moon_seen
    moon_rgb = _scale(moon_rgb, moon_gain * smoothstep(-1.0, 0.0, moon.elevation_deg))

    return SkyParams(
        sun=sun,
        zenith_rgb=zenith,
        horizon_rgb=horizon,
        ground_rgb=ground,
        sun_rgb=sun_rgb,
        ambient=0.06 + 0.94 * day,
        sunset=sunset,
        cover=cover,
        haze_m=haze_m,
        haze_top_m=haze_top_m,
        moon=moon,
        moon_rgb=moon_rgb,
        moon_seen=moon_seen,
        open_zenith_rgb=open_zenith,
        open_horizon_rgb=open_horizon,
        stars=stars,
        dome=dome_controls(state, cover, sunset),
        sky_time_s=clock_s,
        celestial_from_enu=celestial_from_enu(whole_second, obs.lat_deg, obs.lon_deg),
        ground_m=obs.alt_m,
    )


def _combined_cover(layers: Iterable[CloudLayer]) -> float:
    """The sky share the layers cover together, each independent of the others (0..1)."""
    return 1.0 - math.prod(1.0 - min(1.0, lay.cover_oktas / 8.0) for lay in layers)


def dome_controls(state: WeatherState, cover: float, sunset: float) -> DomeControls:
    """The cloud dome's controls from the weather (cover and sunset as sky_params has them)."""
    layers = state.layers
    seconds_of_day = (
        state.time_utc.hour * 3600.0 + state.time_utc.minute * 60.0 + state.time_utc.second
    )
    solar_time = (seconds_of_day / 86400.0 + state.observer.lon_deg / 360.0) % 1.0
    ground_m = state.observer.alt_m
    surface_haze_m = _haze_m(state, ground_m, _haze_top_m(state))
    if not layers:
        return DomeControls(
            sunset=sunset, time=solar_time, ground_m=ground_m, surface_haze_m=surface_haze_m
        )
    high_cover = _combined_cover(lay for lay in layers if _is_high(lay))
    veil = _combined_cover(lay for lay in layers if lay.type is CloudType.CIRROSTRATUS)
    weight = sum(lay.cover_oktas for lay in layers)
    type_density = (
        sum(_TYPE_DENSITY.get(lay.type, 0.5) * lay.cover_oktas for lay in layers) / weight
        if weight > 0.0
        else 0.0
    )
    top = max(layers, key=lambda lay: lay.base_m)
    wind_e, wind_n = state.wind_at(0.5 * (top.base_m + top.top_m))
    # Seen from the ground, the sprites' far edge lies lowest for the lowest layer; above the
    # edge of the highest non-high layer every layer is still drawn as sprites.
    low_layers = [lay for lay in layers if not _is_high(lay)] or layers
    edge_m = max(lay.base_m for lay in low_layers) - state.observer.alt_m
    return DomeControls(
        cover=cover,
        height=min(max(top.base_m / DOME_TOP_M, 0.0), 1.0),
        density=type_density * (0.6 + 0.4 * cover),
        sunset=sunset,
        speed=min(1.0, math.hypot(wind_e, wind_n) / DOME_MAX_WIND_MPS),
        time=solar_time,
        high_cover=high_cover,
        veil=veil,
        horizon_deg=math.degrees(math.atan2(max(edge_m, 0.0), DISTANT_CLOUD_M)),
        drift_toward_deg=math.degrees(math.atan2(wind_e, wind_n)) % 360.0,
        ground_m=ground_m,
        surface_haze_m=surface_haze_m,
    )


def _haze_m(state: WeatherState, eye_m: float, mixed_top_m: float) -> float:
    """Distance over which clouds fade into the horizon colour (the e-folding distance of
    their contrast). In the boundary layer Koschmieder's: the visibility is where a dark
    object's contrast has fallen to 2 %, exp(-3.912), so clouds 15-30 km off at 25 km
    visibility keep 2-10 % of theirs (issue 17; it was 3 times the visibility, and distant
    cumulus stood as crisp as cumulus overhead). The reported visibility is the surface's: haze
    and mist stay in the boundary layer, no higher than the top of the lowest cloud layer (an
    inversion caps both; `mixed_top_m`, `_haze_top_m`), so an eye above it looks through clear
    air."""
    surface_m = max(MIN_HAZE_M, state.visibility_m / KOSCHMIEDER)
    aloft = smoothstep(mixed_top_m, mixed_top_m + 500.0, eye_m)
    return surface_m + (max(surface_m, CLEAR_AIR_HAZE_M) - surface_m) * aloft


def haze_share(
    dist_m: F64 | float,
    up_m: F64 | float,
    eye_alt_m: float,
    haze_m: float,
    haze_top_m: float,
) -> F64:
    """Aerial perspective along a straight path `dist_m` long to a point `up_m` above the eye
    (MSL `eye_alt_m`): 1 - exp(-optical depth), the haze distance `haze_m` on the part of the
    path under the top of the hazy layer (`haze_top_m`) and the clear air's above it, as the
    sky pass's dome has it. A cumulonimbus's tower and anvil over a hazy boundary layer stand
    out from 20 km in 20 km visibility; a cloud in the layer fades as before."""
    dist = np.asarray(dist_m, np.float64)
    up = np.asarray(up_m, np.float64)
    clear_m = max(haze_m, CLEAR_AIR_HAZE_M)
    if not math.isfinite(haze_m):
        return np.zeros(np.broadcast(dist, up).shape)
    if not math.isfinite(haze_top_m):
        below: F64 | float = 1.0
    else:
        lo = np.minimum(up, 0.0)
        hi = np.maximum(up, 0.0)
        below = np.clip((haze_top_m - eye_alt_m - lo) / np.maximum(hi - lo, 1e-3), 0.0, 1.0)
    out: F64 = 1.0 - np.exp(-dist * (below / haze_m + (1.0 - below) / clear_m))
    return out


def _haze_top_m(state: WeatherState) -> float:
    """Top of the hazy mixed layer, MSL: BOUNDARY_LAYER_M over the ground at most, capped by
    the top of the lowest cloud layer."""
    top_m = state.observer.alt_m + BOUNDARY_LAYER_M
    if state.layers:
        top_m = min(top_m, min(lay.top_m for lay in state.layers))
    return top_m


def _share_above(layer: CloudLayer, eye_m: float) -> float:
    """How much of the layer is above the eye: 1 under its base, 0 over its top, linear
    between, so the sky clears gradually while the eye climbs through the layer."""
    depth_m = max(layer.top_m - layer.base_m, 1.0)
    return min(1.0, max(0.0, (layer.top_m - eye_m) / depth_m))


def _is_high(layer: CloudLayer) -> bool:
    return layer.type in HIGH_TYPES or layer.base_m >= HIGH_BASE_M


def smoothstep(lo: float, hi: float, x: float) -> float:
    """0 below lo, 1 above hi, Hermite between (on plain floats: a frame makes a dozen)."""
    t = min(1.0, max(0.0, (x - lo) / (hi - lo)))
    return t * t * (3.0 - 2.0 * t)


def _mix(a: RGB, b: RGB, t: float) -> RGB:
    return (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t)


def _scale(a: RGB, k: float) -> RGB:
    return (a[0] * k, a[1] * k, a[2] * k)


# -- the physical sky's haze (issue 41, item 2) -----------------------------------------------

# A cloud fades toward the sky behind it, but never toward a sky lower than this over the
# horizon: below it the sky-view table holds the ground.
HAZE_MIN_ELEVATION_DEG = 0.5
# `physical_haze_rgb` averages the horizon over these azimuths from the sun (0..180 degrees,
# the table is symmetric about the sun's vertical), at HAZE_AVERAGE_ELEVATION_DEG.
HAZE_AVERAGE_AZIMUTHS = 16
HAZE_AVERAGE_ELEVATION_DEG = 2.0


def moon_veiled(thick_cover: float, cover: float) -> float:
    """What of the moon's disc shows through the sky's cloud (`SkyParams.moon_rgb`): all of
    it under broken cloud, 15 % under a whole deck of water cloud (`thick_cover`, 0..1: every
    layer but high ice cloud), and THIN_MOON_DIM less where high ice cloud makes up the rest
    of `cover` (a cirrostratus veil lets the moon through, ringed by its halo)."""
    thin = max(0.0, cover - thick_cover)
    return (1.0 - 0.85 * smoothstep(0.6, 1.0, thick_cover)) * (1.0 - THIN_MOON_DIM * thin)


def overcast_veil(cover: float) -> tuple[float, float]:
    """(share of grey, dimming) the sky pass lays over the physical sky under cover (the
    uniform u_overcast): the clear-sky model knows nothing of a deck, and under overcast its
    bright horizon showed as a white slot below the deck (issue 41). Dimmer than the
    gradient's 0.55: at 0.55 the slot under overcast-stratus still stood 55 % brighter."""
    t = smoothstep(0.6, 1.0, cover)
    return (0.8 * t, 1.0 - 0.7 * t)


# A layer whose top is less than this above the eye is not drawn as the sky pass's dome (the
# eye is in it or over it): render.sky_textures `dome_frame`.
DOME_MIN_CLEARANCE_M = 300.0


def layer_reaches_horizon(sky: SkyParams, eye_alt_m: float) -> bool:
    """Whether a layer over the eye carries on into the horizon (the sky pass draws its
    distant band): some cover, its top at least DOME_MIN_CLEARANCE_M over the eye."""
    dome = sky.dome
    return dome.cover > 0.0 and dome.height * DOME_TOP_M - eye_alt_m >= DOME_MIN_CLEARANCE_M


def deck_share(sky: SkyParams, eye_alt_m: float) -> float:
    """How far the air under the cover is a slab of haze under a deck (`_sky_behind`): none
    under scattered cloud (half the sky or less: the clear sky shows between the clouds and
    the air before a cloud is the sky's), all under broken cloud and more (three quarters),
    when the layer reaches the horizon."""
    if not layer_reaches_horizon(sky, eye_alt_m):
        return 0.0
    return smoothstep(0.5, 0.75, sky.cover)


def deck_sun_share(sky: SkyParams, eye_alt_m: float) -> float:
    """The share of the sun's beam that reaches a cell of a deck over the eye past the other
    cells (`deck_share`): a cloud's own light is worked out over that cloud alone, but in a
    deck the beam toward a low sun crosses the layer for kilometres and meets the cover's
    other cells on the way (1 - cover of it gets through at a grazing sun), while a high
    sun's leaves the layer within a cell (all of it overhead). 1 under scattered cloud."""
    deck = deck_share(sky, eye_alt_m)
    if deck <= 0.0:
        return 1.0
    grazing = 1.0 - max(math.sin(math.radians(sky.sun.elevation_deg)), 0.0)
    return 1.0 - deck * min(max(sky.cover, 0.0), 1.0) * grazing


def scene_exposure(luts: AtmosphereLuts, cover: float) -> float:
    """The automatic exposure of a scene under `cover` (`display_exposure` of the sky the
    overcast veil has dimmed): the one every part of the picture is shown at, the sky's,
    the clouds' and the ground's."""
    return display_exposure(luts, display_veil(cover)[1])


# The veil's steps (`display_veil`): a step moves a display value by half a level at most, and
# the sky pass's baked table (`display_sky_view`) is made again only when the veil steps.
VEIL_STEPS = 512


def display_veil(cover: float) -> tuple[float, float]:
    """`overcast_veil` on its steps: what the sky pass and its baked table use."""
    share, dim = overcast_veil(cover)
    return (round(share * VEIL_STEPS) / VEIL_STEPS, round(dim * VEIL_STEPS) / VEIL_STEPS)


def _sky_behind(
    luts: AtmosphereLuts,
    sun_enu: tuple[float, float, float],
    cover: float,
    offsets_m: F64,
    deck: float = 0.0,
) -> F64:
    """The sky pass's air (sky.glsl `baked_sky`) toward each offset: its baked display table
    (`display_sky_view`), no lower than HAZE_MIN_ELEVATION_DEG over the horizon (below it,
    that row straight across; under a `deck` (`deck_share`), toward that row at every
    elevation). The same table the
    shader reads, so a cloud fades into the very colour the sky shows behind it, and one
    look-up a cloud instead of the radiance, the aureole and the tone map (a quarter of the
    frame's CPU time with 250 sprites).

    Under a layer that reaches the horizon the air between the eye and the layer is a slab of
    haze lit by the layer's light alike at every elevation under it: a cloud of the deck 5 deg
    up (14 km off under a 1.2 km base, nine tenths haze at 20 km visibility) fades into the
    same air as the deck at the horizon. The clear sky's own rise through the sun's glow (more
    orange 5 deg up toward a low sun than just over the horizon) is the air above the haze,
    which the deck hides; taking it had the deck 5 deg up oranger than the horizon under it
    (B/R 0.32 against 0.41 with the sun 5 deg up), a bluish strip under the deck."""
    # Channel by channel on rows of N (as shading_harris.view_rays): a frame's few hundred
    # sprites each frame, where the numpy calls' own cost is most of it.
    d = np.asarray(offsets_m, np.float64)
    x, y, z = d[0], d[1], d[2]
    horizon = luts.horizon_rad
    floor_rad = horizon + math.radians(HAZE_MIN_ELEVATION_DEG)
    norm = np.sqrt(x * x + y * y + z * z)
    np.maximum(norm, 1e-9, out=norm)
    z = z / norm
    v_floor = float(sky_view_v_above(floor_rad, horizon))
    # The level part of each direction, nudged east as the shader nudges it (never zero).
    fx = x / norm + 1e-6
    fy = y / norm
    flat_norm = np.sqrt(fx * fx + fy * fy)
    np.maximum(flat_norm, 1e-12, out=flat_norm)
    sx, sy = sun_enu[0] + 1e-6, sun_enu[1]
    sun_norm = max(math.hypot(sx, sy), 1e-12)
    cos_az = (fx * (sx / sun_norm) + fy * (sy / sun_norm)) / flat_norm
    np.minimum(np.maximum(cos_az, -1.0, out=cos_az), 1.0, out=cos_az)
    u = np.arccos(cos_az, out=cos_az)
    u *= 1.0 / math.pi
    table = display_sky_view(luts, cover)
    slab: F64 | None = sample_table(table, u, np.full_like(z, v_floor)).T if deck > 0.0 else None
    if slab is not None and deck >= 1.0:
        return slab  # under a full deck the sky behind is not looked up at all
    # Every direction here is over the horizon: those below the floor take its row.
    el = np.arcsin(np.minimum(np.maximum(z, -1.0), 1.0))
    v = np.where(z < math.sin(floor_rad), v_floor, sky_view_v_above(el, horizon))
    out: F64 = sample_table(table, u, v).T
    if slab is not None:
        out += (slab - out) * deck
    return out


# Within this angle of the sun the sky pass draws the sky per pixel (its sun part: the disc, and
# the aureole, which the baked table's 1-2 deg texels would facet: 8 display levels off at 1 deg
# with the sun 60 deg up), blending into the baked table from SUN_EXACT_BLEND_DEG out; beyond
# 3-5 deg the table is within a display level of the exact sky (measured at sun 5-60 deg, 5-40 km
# visibility).
SUN_EXACT_DEG = 6.0
SUN_EXACT_BLEND_DEG = 4.0


def display_sky_view(luts: AtmosphereLuts, cover: float) -> F64:
    """(rows, cols, 3) what the sky pass shows (display values 0..1) at each texel of the
    sky-view table: its radiance with the aureole (at the table's own sun), the overcast veil
    (`display_veil`), the exposure and the one tone map. The sky pass looks the picture up in
    this instead of tone-mapping every pixel (on llvmpipe the per-pixel sky cost 3.3 times the
    gradient's); near the sun it draws the exact sky (SUN_EXACT_DEG)."""
    return _display_sky_view(luts, display_veil(cover))


@functools.lru_cache(maxsize=4)
def _display_sky_view(luts: AtmosphereLuts, veil: tuple[float, float]) -> F64:
    radiance = np.nan_to_num(
        np.asarray(luts.sky_view_radiance(), np.float64), nan=0.0, posinf=0.0, neginf=0.0
    )
    rows, cols = radiance.shape[:2]
    horizon = luts.horizon_rad
    el = sky_view_elevation((np.arange(rows) + 0.5) / rows, horizon)[:, None]
    az = ((np.arange(cols) + 0.5) / cols * math.pi)[None, :]
    sun_el = math.radians(luts.sun_elevation_deg)
    nu = np.cos(el) * np.cos(az) * math.cos(sun_el) + np.sin(el) * math.sin(sun_el)
    strength, g = aureole(luts)
    k = 1.0 + g * g - 2.0 * g * np.clip(nu, -1.0, 1.0)
    phase = (1.0 - g * g) / (4.0 * math.pi * k * np.sqrt(k)) * (el >= horizon)
    radiance = radiance + strength * phase[..., None]
    share, dim = veil
    grey = radiance @ LUMA
    radiance = (radiance + (grey[..., None] - radiance) * share) * dim
    # Float64: the sprites' haze samples it every frame (`_sky_behind`), without a copy.
    out: F64 = display(np.maximum(radiance, 0.0), display_exposure(luts, dim))
    out.flags.writeable = False
    return out


# The sky pass's aureole (render.sky_textures `_physical_uniforms` takes it from here): the
# narrow forward lobe of the aerosol's diffraction that the table's smooth Cornette-Shanks lobe
# (and its 1 deg texels) leave out. Its share of the aerosol's light (the table keeps the
# rest: atmosphere.MIE_PEAK_SHARE), and its Henyey-Greenstein g from clean air (narrow) to
# haze (broadened by multiple scattering).
AUREOLE_SHARE = MIE_PEAK_SHARE
AUREOLE_G_CLEAN = 0.985
AUREOLE_G_HAZE = 0.93
AUREOLE_HAZE_DEPTH = 1.0  # Mie optical depth to the sun at which g is AUREOLE_G_HAZE


@functools.lru_cache(maxsize=8)  # once per table, not per frame (its strength is read-only)
def aureole(luts: AtmosphereLuts) -> tuple[F64, float]:
    """(strength kcd/m^2 per unit phase (3,), Henyey-Greenstein g) of the sky pass's aureole:
    from the aerosol's optical depth from the eye toward the sun (per channel: the aerosol's
    Angstrom law, `Medium.mie_spectral`; g from 550 nm's), as the sky pass has it."""
    el = luts.sun_elevation_deg
    eye_m = luts.eye_alt_m
    sun_klx = sun_irradiance(luts, eye_m, el)
    vertical = (
        luts.medium.mie_extinction_per_m
        * MIE_SCALE_HEIGHT_M
        * math.exp(-eye_m / MIE_SCALE_HEIGHT_M)
    )
    tau = vertical / max(math.sin(math.radians(max(el, 0.0))), 1.0 / 40.0)
    haze = min(tau / AUREOLE_HAZE_DEPTH, 1.0)
    g = AUREOLE_G_CLEAN + (AUREOLE_G_HAZE - AUREOLE_G_CLEAN) * haze
    strength: F64 = sun_klx * (AUREOLE_SHARE * (1.0 - np.exp(-tau * luts.medium.mie_spectral)))
    strength.flags.writeable = False
    return strength, g


@functools.lru_cache(maxsize=8)
def physical_haze_rgb(luts: AtmosphereLuts, cover: float) -> RGB:
    """The physical sky's horizon as the sky pass shows it (display values), averaged round
    the horizon (HAZE_AVERAGE_ELEVATION_DEG up): the one colour for what takes a single haze
    colour (the tower quads); sprite clouds take `SkyParams.haze_toward`."""
    az = np.radians((np.arange(HAZE_AVERAGE_AZIMUTHS) + 0.5) / HAZE_AVERAGE_AZIMUTHS * 180.0)
    el = horizon_elevation_rad(luts.eye_alt_m) + math.radians(HAZE_AVERAGE_ELEVATION_DEG)
    dirs = np.stack(
        [np.sin(az) * math.cos(el), np.cos(az) * math.cos(el), np.full_like(az, math.sin(el))]
    )
    # The sun due north in this frame: the azimuths above are from the sun's.
    rgb = _sky_behind(luts, (0.0, 1.0, 0.0), cover, dirs).mean(axis=1)
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))
