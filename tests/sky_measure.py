"""Measurements of sky pictures, shared by issue 41's picture checks (tests/test_horizon_deck.py
and those to come: the CIE sky, backlit cumulus, twilight).

Everything is measured on linear light: a composited 8-bit picture is decoded from sRGB first
(`srgb_to_linear`); a scene-linear picture (`.npy` float32 H x W x 3 or `.pfm`, rows top
first, as `wxsky snapshot --linear-out` is to write them) is taken as it is (`load_linear`).
Directions come from the picture's camera (`wxsky.scene.camera.Camera`: heading, pitch, fov,
size), so a region is named by elevation and azimuth, not by rows: "the band from 1° below to
1° above the horizon", "the sky 5-15° up, opposite the sun".

The times for a wanted sun elevation are tools/gallery/light_sheet.py's (`sun_time`,
`preset_sun`): the same moments as the before | after sheet.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

import numpy as np
import numpy.typing as npt
from tool_loader import load_tool

from wxsky.app.snapshot import take_snapshot
from wxsky.png import read_png
from wxsky.render.renderer import Renderer
from wxsky.scene.camera import Camera
from wxsky.settings.config import DaemonConfig
from wxsky.settings.presets import load_preset
from wxsky.weather.state import WeatherState

F64 = npt.NDArray[np.float64]

EARTH_RADIUS_M = 6_371_000.0
# Rec. 709 / sRGB primaries, D65: the luminance of linear RGB.
LUMINANCE_WEIGHTS = (0.2126, 0.7152, 0.0722)

_sheet = load_tool("gallery/light_sheet")
SunMoment = _sheet.SunMoment
sun_time = _sheet.sun_time  # (day, lat_deg, lon_deg, elevation_deg | None) -> SunMoment
preset_sun = _sheet.preset_sun  # (preset, elevation_deg | None) -> SunMoment


# --- light ------------------------------------------------------------------------------------


def srgb_to_linear(image: npt.ArrayLike) -> F64:
    """sRGB-encoded values (uint8 0..255, or floats 0..1) to linear light 0..1 (IEC 61966-2-1).
    An alpha channel, where the input has 4, is dropped."""
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[-1] == 4:
        a = a[..., :3]
    v = a.astype(np.float64) / 255.0 if a.dtype == np.uint8 else a.astype(np.float64)
    out: F64 = np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)
    return out


def relative_luminance(rgb_linear: npt.ArrayLike) -> F64:
    """Y of linear RGB (..., 3)."""
    out: F64 = np.asarray(rgb_linear, np.float64) @ np.asarray(LUMINANCE_WEIGHTS)
    return out


def load_linear(path: Path) -> F64:
    """(H, W, 3) linear light from a picture file: a PNG is decoded from sRGB; `.npy`
    (float32 H x W x 3) and `.pfm` (Portable Float Map, bottom row first in the file) are
    scene-linear already. Rows top first."""
    suffix = path.suffix.lower()
    if suffix == ".png":
        return srgb_to_linear(read_png(path))
    if suffix == ".npy":
        return np.asarray(np.load(path), np.float64)[..., :3]
    if suffix == ".pfm":
        return _read_pfm(path)
    raise ValueError(f"{path}: not a .png, .npy or .pfm picture")


def _read_pfm(path: Path) -> F64:
    data = path.read_bytes()
    fields: list[bytes] = []
    pos = 0
    while len(fields) < 4:  # "PF", width, height, scale: whitespace-separated
        while data[pos : pos + 1].isspace():
            pos += 1
        end = pos
        while not data[end : end + 1].isspace():
            end += 1
        fields.append(data[pos:end])
        pos = end
    pos += 1  # the single whitespace character after the scale
    if fields[0] not in (b"PF", b"Pf"):
        raise ValueError(f"{path}: not a PFM file")
    channels = 3 if fields[0] == b"PF" else 1
    width, height, scale = int(fields[1]), int(fields[2]), float(fields[3])
    dtype = "<f4" if scale < 0 else ">f4"
    pixels = np.frombuffer(data, dtype, width * height * channels, pos)
    image = pixels.reshape(height, width, channels)[::-1].astype(np.float64)
    return np.repeat(image, 3, axis=-1) if channels == 1 else image


# --- directions -------------------------------------------------------------------------------


def pixel_elevation_deg(camera: Camera) -> F64:
    """(H, W) elevation of each pixel's ray, degrees above the eye's level."""
    up = camera.pixel_rays()[..., 2]
    return np.degrees(np.arcsin(np.clip(up, -1.0, 1.0)))


def pixel_azimuth_deg(camera: Camera) -> F64:
    """(H, W) azimuth of each pixel's ray, degrees from north, clockwise, 0..360."""
    rays = camera.pixel_rays()
    return np.degrees(np.arctan2(rays[..., 0], rays[..., 1])) % 360.0


def horizon_dip_deg(eye_agl_m: float) -> float:
    """How far below the eye's level the horizon of a smooth Earth lies (no refraction):
    0.045° from 2 m, 3.2° from 10 km."""
    return math.degrees(math.acos(EARTH_RADIUS_M / (EARTH_RADIUS_M + max(eye_agl_m, 0.0))))


def _azimuth_offset_deg(azimuth_deg: F64, toward_deg: float) -> F64:
    out: F64 = np.abs((azimuth_deg - toward_deg + 180.0) % 360.0 - 180.0)
    return out


# --- regions ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Patch:
    """The mean linear colour of a region of a picture, and how many pixels it has."""

    rgb: tuple[float, float, float]
    pixels: int

    @property
    def luminance(self) -> float:
        return float(relative_luminance(np.asarray(self.rgb)))

    @property
    def blue_over_red(self) -> float:
        return self.rgb[2] / self.rgb[0] if self.rgb[0] > 0.0 else math.inf

    def __str__(self) -> str:
        return f"Y {self.luminance:.4f} B/R {self.blue_over_red:.3f} ({self.pixels} px)"


def mean_where(linear: F64, mask: npt.NDArray[np.bool_]) -> Patch:
    """The mean colour of the pixels where `mask` holds. ValueError if none does: a check
    whose region is out of the picture must not pass on an empty mean."""
    n = int(mask.sum())
    if n == 0:
        raise ValueError("the region has no pixels in this picture")
    r, g, b = (float(v) for v in linear[mask].mean(axis=0))
    return Patch((r, g, b), n)


def sky_region(
    linear: F64,
    camera: Camera,
    elevation_deg: tuple[float, float],
    azimuth_deg: float | None = None,
    azimuth_half_width_deg: float = 180.0,
) -> Patch:
    """The mean colour of the pixels between two elevations (degrees, inclusive), and within
    `azimuth_half_width_deg` of `azimuth_deg` where one is given (else every column)."""
    el = pixel_elevation_deg(camera)
    mask = (el >= elevation_deg[0]) & (el <= elevation_deg[1])
    if azimuth_deg is not None:
        mask &= _azimuth_offset_deg(pixel_azimuth_deg(camera), azimuth_deg) <= (
            azimuth_half_width_deg
        )
    return mean_where(linear, mask)


@dataclass(frozen=True)
class HorizonDeck:
    """The band around the horizon against the deck (or sky) a few degrees above it."""

    band: Patch
    deck: Patch

    @property
    def bluer(self) -> float:
        """The band's B/R over the deck's: 1.05 is 5 % bluer."""
        return self.band.blue_over_red / self.deck.blue_over_red

    @property
    def brighter(self) -> float:
        """The band's luminance over the deck's: 1.15 is 15 % brighter."""
        return self.band.luminance / self.deck.luminance

    def __str__(self) -> str:
        return (
            f"band {self.band}, deck {self.deck}: "
            f"bluer x{self.bluer:.3f}, brighter x{self.brighter:.3f}"
        )


def horizon_band_vs_deck(
    linear: F64,
    camera: Camera,
    eye_agl_m: float,
    band_half_deg: float = 1.0,
    deck_above_deg: float = 5.0,
    deck_half_deg: float = 0.5,
) -> HorizonDeck:
    """Issue 41's "horizon under a deck": the band from `band_half_deg` below to above the
    horizon (the smooth Earth's, `horizon_dip_deg` below the eye's level) against the rows
    `deck_above_deg` (± `deck_half_deg`) above it, across the whole picture."""
    horizon = -horizon_dip_deg(eye_agl_m)
    band = sky_region(linear, camera, (horizon - band_half_deg, horizon + band_half_deg))
    deck_el = horizon + deck_above_deg
    deck = sky_region(linear, camera, (deck_el - deck_half_deg, deck_el + deck_half_deg))
    return HorizonDeck(band, deck)


# --- pictures ---------------------------------------------------------------------------------


def preset_state(name: str, time_utc: datetime | None = None) -> WeatherState:
    """A built-in preset's weather, at `time_utc` where given."""
    state = WeatherState().apply(load_preset(name, ()))
    return state if time_utc is None else dataclasses.replace(state, time_utc=time_utc)


def eye_camera(
    state: WeatherState,
    heading_deg: float,
    pitch_deg: float,
    size: tuple[int, int] = (320, 180),
    fov_deg: float = 60.0,
    eye_agl_m: float = 2.0,
) -> Camera:
    """A camera `eye_agl_m` above the state's observer."""
    return Camera(
        position_m=(0.0, 0.0, state.observer.alt_m + eye_agl_m),
        heading_deg=heading_deg % 360.0,
        pitch_deg=pitch_deg,
        fov_deg=fov_deg,
        width_px=size[0],
        height_px=size[1],
    )


def snapshot_linear(renderer: Renderer, state: WeatherState, camera: Camera) -> F64:
    """(H, W, 3) linear light of the composited picture a host gets (the daemon's stages,
    `take_snapshot`), decoded from its sRGB bytes. The one place to change when the picture
    checks move to the scene-linear output."""
    shot = take_snapshot(state, camera, DaemonConfig().scene.settings(), renderer)
    return srgb_to_linear(shot.image)
