"""Wireshark's CIGI dissector as a second opinion on what wxsky sends: the one map from the
packet table's fields to the tshark fields that show them, and one tshark run over a pcap
(tools/emulators/pcap.py). Shared by tests/test_cigi_tshark.py (every field of every packet) and
tests/test_cigi_send.py (what `wxsky cigi send` sends for a daemon's weather)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import NamedTuple

import pytest

TSHARK_EXE = shutil.which("tshark")
needs_tshark = pytest.mark.skipif(
    TSHARK_EXE is None,
    reason="tshark is not installed (Debian: apt-get install tshark; tools/setup installs it)",
)


class Bit(NamedTuple):
    """A flag that tshark shows as one bit of a wider field."""

    field: str
    bit: int


# Table key -> value field -> the tshark (Wireshark 4.0) field showing it.
TSHARK: dict[str, dict[str, str | Bit]] = {
    "ig_control": {
        "database_number": "cigi.ig_control.db_number",
        "ig_mode": "cigi.ig_control.ig_mode",
        "timestamp_valid": "cigi.ig_control.timestamp_valid",
        "smoothing_enable": "cigi.ig_control.extrapolation_enable",
        "minor_version": "cigi.ig_control.minor_version",
        "host_frame_number": "cigi.ig_control.host_frame_number",
        "timestamp_10us": "cigi.ig_control.timestamp",  # labelled microseconds
        "last_ig_frame_number": "cigi.ig_control.last_ig_frame_number",
    },
    "entity_control": {
        "entity_id": "cigi.entity_control.entity_id",
        "entity_state": "cigi.entity_control.entity_state",
        "attach_state": "cigi.entity_control.attach_state",
        "collision_detection_enable": "cigi.entity_control.coll_det_request",
        "inherit_alpha": "cigi.entity_control.inherit_alpha",
        "ground_clamp": "cigi.entity_control.ground_ocean_clamp",
        "animation_direction": "cigi.entity_control.animation_dir",
        "animation_loop_mode": "cigi.entity_control.animation_loop_mode",
        "animation_state": "cigi.entity_control.animation_state",
        "smoothing_enable": "cigi.entity_control.extrapolation_enable",
        "alpha": "cigi.entity_control.alpha",
        "entity_type": "cigi.entity_control.entity_type",
        "parent_id": "cigi.entity_control.parent_id",
        "roll_deg": "cigi.entity_control.roll",
        "pitch_deg": "cigi.entity_control.pitch",
        "yaw_deg": "cigi.entity_control.yaw",
        "lat_deg": "cigi.entity_control.lat_xoff",
        "lon_deg": "cigi.entity_control.lon_yoff",
        "alt_m": "cigi.entity_control.alt_zoff",
    },
    "celestial_sphere_control": {
        "hour": "cigi.celestial_sphere_control.hour",
        "minute": "cigi.celestial_sphere_control.minute",
        "ephemeris_enable": "cigi.celestial_sphere_control.ephemeris_enable",
        "sun_enable": "cigi.celestial_sphere_control.sun_enable",
        "moon_enable": "cigi.celestial_sphere_control.moon_enable",
        "star_field_enable": "cigi.celestial_sphere_control.star_enable",
        "date_time_valid": "cigi.celestial_sphere_control.date_time_valid",
        "date_mmddyyyy": "cigi.celestial_sphere_control.date",
        "star_field_intensity_pct": "cigi.celestial_sphere_control.star_intensity",
    },
    "atmosphere_control": {
        "atmospheric_model_enable": "cigi.atmosphere_control.atmospheric_model_enable",
        "humidity_pct": "cigi.atmosphere_control.humidity",
        "temperature_c": "cigi.atmosphere_control.air_temp",
        "visibility_m": "cigi.atmosphere_control.visibility_range",
        "wind_speed_mps": "cigi.atmosphere_control.horiz_wind",
        "vertical_wind_speed_mps": "cigi.atmosphere_control.vert_wind",
        "wind_dir_deg": "cigi.atmosphere_control.wind_direction",
        "pressure_hpa": "cigi.atmosphere_control.barometric_pressure",
    },
    "environmental_region_control": {
        "region_id": "cigi.env_region_control.region_id",
        "region_state": "cigi.env_region_control.region_state",
        "merge_weather": "cigi.env_region_control.merge_weather",
        "merge_aerosol": "cigi.env_region_control.merge_aerosol",
        "merge_maritime": "cigi.env_region_control.merge_maritime",
        "merge_terrestrial": "cigi.env_region_control.merge_terrestrial",
        "lat_deg": "cigi.env_region_control.lat",
        "lon_deg": "cigi.env_region_control.lon",
        "size_x_m": "cigi.env_region_control.size_x",
        "size_y_m": "cigi.env_region_control.size_y",
        "corner_radius_m": "cigi.env_region_control.corner_radius",
        "rotation_deg": "cigi.env_region_control.rotation",
        "transition_perimeter_m": "cigi.env_region_control.transition_perimeter",
    },
    "weather_control": {
        "entity_or_region_id": "cigi.weather_control.entity_region_id",
        "layer_id": "cigi.weather_control.layer_id",
        "humidity_pct": "cigi.weather_control.humidity",
        "weather_enable": "cigi.weather_control.weather_enable",
        "scud_enable": "cigi.weather_control.scud_enable",
        "random_winds_enable": "cigi.weather_control.random_winds_enable",
        "random_lightning_enable": "cigi.weather_control.random_lightning_enable",
        "cloud_type": "cigi.weather_control.cloud_type",
        "scope": "cigi.weather_control.scope",
        "severity": "cigi.weather_control.severity",
        "temperature_c": "cigi.weather_control.air_temp",
        "visibility_m": "cigi.weather_control.visibility_range",
        "scud_frequency_pct": "cigi.weather_control.scud_frequency",
        "coverage_pct": "cigi.weather_control.coverage",
        "base_elevation_m": "cigi.weather_control.base_elevation",
        "thickness_m": "cigi.weather_control.thickness",
        "transition_band_m": "cigi.weather_control.transition_band",
        "wind_speed_mps": "cigi.weather_control.horiz_wind",
        "vertical_wind_speed_mps": "cigi.weather_control.vert_wind",
        "wind_dir_deg": "cigi.weather_control.wind_direction",
        "pressure_hpa": "cigi.weather_control.barometric_pressure",
        "aerosol_concentration_gpm3": "cigi.weather_control.aerosol_concentration",
    },
    "view_control": {
        "view_id": "cigi.view_control.view_id",
        "group_id": "cigi.view_control.group_id",
        "x_enable": "cigi.view_control.xoff_enable",
        "y_enable": "cigi.view_control.yoff_enable",
        "z_enable": "cigi.view_control.zoff_enable",
        "roll_enable": "cigi.view_control.roll_enable",
        "pitch_enable": "cigi.view_control.pitch_enable",
        "yaw_enable": "cigi.view_control.yaw_enable",
        "entity_id": "cigi.view_control.entity_id",
        "x_offset_m": "cigi.view_control.xoff",
        "y_offset_m": "cigi.view_control.yoff",
        "z_offset_m": "cigi.view_control.zoff",
        "roll_deg": "cigi.view_control.roll",
        "pitch_deg": "cigi.view_control.pitch",
        "yaw_deg": "cigi.view_control.yaw",
    },
    "view_definition": {
        "view_id": "cigi.view_def.view_id",
        "group_id": "cigi.view_def.group_id",
        "near_enable": "cigi.view_def.near_enable",
        "far_enable": "cigi.view_def.far_enable",
        "left_enable": "cigi.view_def.left_enable",
        "right_enable": "cigi.view_def.right_enable",
        "top_enable": "cigi.view_def.top_enable",
        "bottom_enable": "cigi.view_def.bottom_enable",
        "mirror_mode": "cigi.view_def.mirror_mode",
        "pixel_replication": "cigi.view_def.pixel_replication",
        "projection_type": "cigi.view_def.projection_type",
        "reorder": "cigi.view_def.reorder",
        "view_type": "cigi.view_def.view_type",
        "near_m": "cigi.view_def.near",
        "far_m": "cigi.view_def.far",
        "left_deg": "cigi.view_def.left",
        "right_deg": "cigi.view_def.right",
        "top_deg": "cigi.view_def.top",
        "bottom_deg": "cigi.view_def.bottom",
    },
    "environmental_conditions_request": {
        # tshark shows the four request bits as one 4-bit "Request Type" (1, 2, 4, 8)
        "request_maritime": Bit("cigi.env_cond_request.type", 0),
        "request_terrestrial": Bit("cigi.env_cond_request.type", 1),
        "request_weather": Bit("cigi.env_cond_request.type", 2),
        "request_aerosol": Bit("cigi.env_cond_request.type", 3),
        "request_id": "cigi.env_cond_request.id",
        "lat_deg": "cigi.env_cond_request.lat",
        "lon_deg": "cigi.env_cond_request.lon",
        "alt_m": "cigi.env_cond_request.alt",
    },
    "start_of_frame": {
        "database_number": "cigi.sof.db_number",
        "ig_status": "cigi.sof.ig_status",
        "ig_mode": "cigi.sof.ig_mode",
        "timestamp_valid": "cigi.sof.timestamp_valid",
        "earth_reference_model": "cigi.sof.earth_reference_model",
        "minor_version": "cigi.sof.minor_version",
        "ig_frame_number": "cigi.sof.ig_frame_number",
        "timestamp_10us": "cigi.sof.timestamp",  # labelled microseconds
        "last_host_frame_number": "cigi.sof.last_host_frame_number",
    },
    "weather_conditions_response": {
        "request_id": "cigi.wea_cond_response.request_id",
        "humidity_pct": "cigi.wea_cond_response.humidity",
        "temperature_c": "cigi.wea_cond_response.air_temp",
        "visibility_m": "cigi.wea_cond_response.visibility_range",
        "wind_speed_mps": "cigi.wea_cond_response.horiz_speed",
        "vertical_wind_speed_mps": "cigi.wea_cond_response.vert_speed",
        "wind_dir_deg": "cigi.wea_cond_response.wind_direction",
        "pressure_hpa": "cigi.wea_cond_response.barometric_pressure",
    },
    "aerosol_concentration_response": {
        "request_id": "cigi.aerosol_concentration_response.request_id",
        "layer_id": "cigi.aerosol_concentration_response.layer_id",
        "aerosol_concentration_gpm3": "cigi.aerosol_concentration_response.aerosol_concentration",
    },
}
# Table key -> value field -> why tshark does not show it (none so far: it shows them all).
NOT_SHOWN: dict[str, dict[str, str]] = {}
# Shown once a datagram, by its first packet; the rest each packet (in datagram order).
FRAME_FIELDS = ("cigi.frame_size", "cigi.version", "cigi.byte_swap")
PACKET_FIELDS = ("cigi.packet_id", "cigi.packet_size")
PROBLEM_FIELDS = ("_ws.expert.message", "_ws.malformed")
# tshark prints f32 with %.6g and f64 with %.15g: half a unit of the last digit, relative.
REL_TOL = {"f32": 5e-6, "f64": 5e-15}
# What a big- or little-endian sender's magic (80 00 / 00 80) reads as: tshark reads it
# big-endian and then decodes the datagram in the order it names.
MAGIC_SHOWN = {"big": 0x8000, "little": 0x0080}


def tshark_fields() -> list[str]:
    named = {s if isinstance(s, str) else s.field for m in TSHARK.values() for s in m.values()}
    return [*FRAME_FIELDS, *PACKET_FIELDS, *PROBLEM_FIELDS, *sorted(named)]


def decode_pcap(path: Path, work: Path) -> list[dict[str, list[str]]]:
    """One tshark run over the pcap: per frame, every field of `tshark_fields()` -> its values
    in datagram order (empty when the frame has none)."""
    assert TSHARK_EXE is not None
    fields = tshark_fields()
    cmd = [TSHARK_EXE, "-n", "-r", str(path), "-T", "fields", "-E", "separator=/t"]
    cmd += ["-e", "frame.number"] + [a for f in fields for a in ("-e", f)]
    # An empty configuration folder: no personal preference (a forced CIGI version or byte
    # order, heuristics turned off) changes how the dissector reads the file.
    conf = work / "wireshark-config"
    conf.mkdir(exist_ok=True)
    env = {**os.environ, "WIRESHARK_CONFIG_DIR": str(conf)}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    rows: list[dict[str, list[str]]] = []
    for line in proc.stdout.splitlines():
        number, *cells = line.split("\t")
        assert len(cells) == len(fields), line
        assert int(number) == len(rows) + 1
        rows.append({f: c.split(",") if c else [] for f, c in zip(fields, cells, strict=True)})
    return rows


def number(text: str) -> float:
    """A value as tshark prints it."""
    if text in ("True", "False"):  # booleans print as 1/0 in tshark 4.0, True/False later
        return float(text == "True")
    if text.lstrip("-").isdigit() or text.startswith("0x"):
        return float(int(text, 0))
    return float(text)
