"""The CIGI 3.3 packets wxsky reads and writes, as one table.

`PACKETS` is the single source for the decoder and encoder (`cigi`), the tests and the
packet tables in docs/cigi.md (`table_markdown`). Each packet lists its fields in byte order:
offset, wire type, name with its unit, and the range where the standard gives one. Bytes the
table does not name are reserved: the encoder zeroes them and the decoder does not read them
(CCL 3.3.3's `Pack()` zeroes them in these packets, but a host need not be built on CCL).

Layouts are SISO-STD-013 CIGI 3.3 as read from CCL's `Pack()` (protocols reference §6.3-§6.8,
§6.10a); what the reference lacks is taken from the 3.3 ICD and said so in a `source` note.
Angles are accepted in ±360° and normalised: CCL's Weather Control sends its wind direction
as -180..180 where the ICD says 0..360, and a host with CCL's range checks off (or none) may
send any angle either way.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

from wxsky.protocols.cigi_fields import (
    DIRECTION_TEXT,
    HEADER_SIZE,
    KIND_SIZES,
    PacketSpec,
    angle,
    bits,
    calendar_mmddyyyy,
    f32,
    f64,
    flag,
    magic,
    minor_version,
    range_text,
    s8,
    table_problems,
    type_text,
    u8,
    u16,
    u32,
    version,
)

_ANIMATION = "0 stop, 1 pause, 2 play, 3 continue"
_ICD = "SISO-STD-013 CIGI 3.3 ICD"

IG_CONTROL = PacketSpec(
    1,
    "ig_control",
    "IG Control",
    24,
    "host_to_ig",
    (
        version("a host→IG message's first packet"),
        s8("database_number", 3, note="0 no change; positive: load that database"),
        bits("ig_mode", 4, 0, 2, 2, "0 reset/standby, 1 operate, 2 debug"),
        flag("timestamp_valid", 4, 2),
        flag("smoothing_enable", 4, 3, "extrapolation/interpolation"),
        minor_version(4),
        magic(),
        u32("host_frame_number", 8),
        u32("timestamp_10us", 12, note="10 µs ticks"),
        u32("last_ig_frame_number", 16),
    ),
    "protocols §6.3 (CCL CigiIGCtrlV3_3)",
    starts_message=True,
)

ENTITY_CONTROL = PacketSpec(
    2,
    "entity_control",
    "Entity Control",
    48,
    "host_to_ig",
    (
        u16("entity_id", 2, note="0 = ownship"),
        bits("entity_state", 4, 0, 2, 2, "0 inactive/standby, 1 active, 2 destroyed"),
        flag("attach_state", 4, 2, "1: lat/lon/alt are x/y/z offsets in m from the parent"),
        flag("collision_detection_enable", 4, 3),
        flag("inherit_alpha", 4, 4),
        bits("ground_clamp", 4, 5, 2, 2, "0 none, 1 non-conformal, 2 conformal"),
        flag("animation_direction", 5, 0, "0 forward, 1 backward"),
        flag("animation_loop_mode", 5, 1, "0 one-shot, 1 continuous"),
        bits("animation_state", 5, 2, 2, 3, _ANIMATION),
        flag("smoothing_enable", 5, 4, "extrapolation/interpolation"),
        u8("alpha", 6, note="0 transparent, 255 opaque"),
        u16("entity_type", 8),
        u16("parent_id", 10),
        angle("roll_deg", 12, -180.0),
        f32("pitch_deg", 16, -90.0, 90.0),
        angle("yaw_deg", 20, 0.0, "true heading"),
        f64("lat_deg", 24, -90.0, 90.0, when=("attach_state", 0)),
        f64("lon_deg", 32, -180.0, 180.0, when=("attach_state", 0)),
        f64("alt_m", 40, note="MSL; z offset when attached"),
    ),
    # Byte 5's bits and byte 7 (reserved) are the ICD's: §6.10a says only "animation bits".
    f"protocols §6.10a (CCL CigiEntityCtrlV3_3); byte 5 bits from the {_ICD}",
)

CELESTIAL_SPHERE_CONTROL = PacketSpec(
    9,
    "celestial_sphere_control",
    "Celestial Sphere Control",
    16,
    "host_to_ig",
    (
        u8("hour", 2, 0, 23, note="UTC"),
        u8("minute", 3, 0, 59),
        flag("ephemeris_enable", 4, 0, "1: the IG advances its own clock"),
        flag("sun_enable", 4, 1),
        flag("moon_enable", 4, 2),
        flag("star_field_enable", 4, 3),
        flag("date_time_valid", 4, 4, "1: the packet's date and time set the IG's clock"),
        u32(
            "date_mmddyyyy",
            8,
            when=("date_time_valid", 1),
            rule=calendar_mmddyyyy,
            rule_text="a calendar date in the clock's years 1900..2199",
            note="MM·1 000 000 + DD·10 000 + YYYY; a calendar date when date_time_valid = 1",
        ),
        f32("star_field_intensity_pct", 12, 0.0, 100.0),
    ),
    "protocols §6.7 (CCL CigiCelestialCtrlV3)",
)

ATMOSPHERE_CONTROL = PacketSpec(
    10,
    "atmosphere_control",
    "Atmosphere Control",
    32,
    "host_to_ig",
    (
        flag("atmospheric_model_enable", 2, 0),
        u8("humidity_pct", 3, 0, 100),
        f32("temperature_c", 4, -273.15),
        f32("visibility_m", 8, 0.0),
        f32("wind_speed_mps", 12, 0.0, note="horizontal"),
        f32("vertical_wind_speed_mps", 16, note="positive up"),
        angle("wind_dir_deg", 20, 0.0, "true, from"),
        f32("pressure_hpa", 24, 0.0, note="millibars on the wire (= hPa)"),
    ),
    "protocols §6.6 (CCL CigiAtmosCtrlV3); the global values weather layers override",
)

ENVIRONMENTAL_REGION_CONTROL = PacketSpec(
    11,
    "environmental_region_control",
    "Environmental Region Control",
    48,
    "host_to_ig",
    (
        u16("region_id", 2),
        bits("region_state", 4, 0, 2, 2, "0 inactive, 1 active, 2 destroyed"),
        flag("merge_weather", 4, 2, "0 use last, 1 merge"),
        flag("merge_aerosol", 4, 3),
        flag("merge_maritime", 4, 4),
        flag("merge_terrestrial", 4, 5),
        f64("lat_deg", 8, -90.0, 90.0, note="the region's centre"),
        f64("lon_deg", 16, -180.0, 180.0),
        f32("size_x_m", 24, 0.0),
        f32("size_y_m", 28, 0.0),
        f32("corner_radius_m", 32, 0.0),
        f32("rotation_deg", 36, -180.0, 180.0, note="clockwise from north"),
        f32("transition_perimeter_m", 40, 0.0),
    ),
    "protocols §6.8 (CCL CigiEnvRgnCtrlV3)",
)

WEATHER_CONTROL = PacketSpec(
    12,
    "weather_control",
    "Weather Control",
    56,
    "host_to_ig",
    (
        u16("entity_or_region_id", 2, note="0 when scope = global"),
        u8("layer_id", 4, note="0 ground fog, 1-3 cloud layers, 4 rain … 9 dust, ≥ 10 IG's"),
        u8("humidity_pct", 5, 0, 100),
        flag("weather_enable", 6, 0),
        flag("scud_enable", 6, 1),
        flag("random_winds_enable", 6, 2),
        flag("random_lightning_enable", 6, 3),
        bits(
            "cloud_type",
            6,
            4,
            4,
            15,
            "0 none, 1 Ac, 2 As, 3 Cc, 4 Cs, 5 Ci, 6 Cb, 7 Cu, 8 Ns, 9 Sc, 10 St, 11-15 other",
        ),
        bits("scope", 7, 0, 2, 2, "0 global, 1 regional, 2 entity"),
        bits("severity", 7, 2, 3, 5),
        f32("temperature_c", 8, -273.15),
        f32("visibility_m", 12, 0.0),
        f32("scud_frequency_pct", 16, 0.0, 100.0),
        f32("coverage_pct", 20, 0.0, 100.0),
        # The ICD gives no floor; below the Dead Sea shore is an encoding error, not weather.
        f32("base_elevation_m", 24, -500.0, note="MSL"),
        f32("thickness_m", 28, 0.0, note="top = base + thickness"),
        f32("transition_band_m", 32, 0.0, note="above and below the layer"),
        f32("wind_speed_mps", 36, 0.0, note="horizontal"),
        f32("vertical_wind_speed_mps", 40, note="positive up"),
        angle("wind_dir_deg", 44, 0.0, "true, from; CCL sends -180..180"),
        f32("pressure_hpa", 48, 0.0, note="millibars on the wire (= hPa)"),
        f32("aerosol_concentration_gpm3", 52, 0.0, note="g/m³"),
    ),
    "protocols §6.5 (CCL CigiWeatherCtrlV3), units from Rinchi WeatherControl",
)

VIEW_CONTROL = PacketSpec(
    16,
    "view_control",
    "View Control",
    32,
    "host_to_ig",
    (
        u16("view_id", 2),
        u8("group_id", 4),
        flag("x_enable", 5, 0),
        flag("y_enable", 5, 1),
        flag("z_enable", 5, 2),
        flag("roll_enable", 5, 3),
        flag("pitch_enable", 5, 4),
        flag("yaw_enable", 5, 5),
        u16("entity_id", 6, note="the entity the view is attached to"),
        f32("x_offset_m", 8),
        f32("y_offset_m", 12),
        f32("z_offset_m", 16),
        angle("roll_deg", 20, -180.0),
        f32("pitch_deg", 24, -90.0, 90.0),
        angle("yaw_deg", 28, 0.0),
    ),
    # The angle ranges are the ICD's; §6.10a gives the layout only.
    f"protocols §6.10a (CCL CigiViewCtrlV3); angle ranges from the {_ICD}",
)

VIEW_DEFINITION = PacketSpec(
    21,
    "view_definition",
    "View Definition",
    32,
    "host_to_ig",
    (
        u16("view_id", 2),
        u8("group_id", 4),
        flag("near_enable", 5, 0),
        flag("far_enable", 5, 1),
        flag("left_enable", 5, 2),
        flag("right_enable", 5, 3),
        flag("top_enable", 5, 4),
        flag("bottom_enable", 5, 5),
        bits("mirror_mode", 5, 6, 2, 3, "0 none, 1 horizontal, 2 vertical, 3 both"),
        # 3.3 defines 0-3; 4-7 are passed on rather than costing the whole view.
        bits("pixel_replication", 6, 0, 3, 7, "0 none, 1 1x2, 2 2x1, 3 2x2"),
        flag("projection_type", 6, 3, "0 perspective, 1 orthographic"),
        flag("reorder", 6, 4, "1: bring to top"),
        bits("view_type", 6, 5, 3, 7, "IG-defined"),
        f32("near_m", 8, 0.0),
        f32("far_m", 12, 0.0),
        f32("left_deg", 16, -90.0, 90.0, note="half-angles from the view axis"),
        f32("right_deg", 20, -90.0, 90.0),
        f32("top_deg", 24, -90.0, 90.0),
        f32("bottom_deg", 28, -90.0, 90.0),
    ),
    # Bit meanings and the ±90° half-angle bound are the ICD's; §6.10a gives the layout.
    f"protocols §6.10a (CCL CigiViewDefV3); value meanings from the {_ICD}",
)

ENVIRONMENTAL_CONDITIONS_REQUEST = PacketSpec(
    28,
    "environmental_conditions_request",
    "Environmental Conditions Request",
    32,
    "host_to_ig",
    (
        flag("request_maritime", 2, 0, "type bit 1: Maritime Surface Conditions Response"),
        flag("request_terrestrial", 2, 1, "type bit 2: Terrestrial Surface Conditions"),
        flag("request_weather", 2, 2, "type bit 4: Weather Conditions Response"),
        flag("request_aerosol", 2, 3, "type bit 8: Aerosol Concentration Responses"),
        u8("request_id", 3),
        f64("lat_deg", 8, -90.0, 90.0),
        f64("lon_deg", 16, -180.0, 180.0),
        f64("alt_m", 24, note="MSL"),
    ),
    "issue 15 and protocols §6.10a (CCL CigiEnvCondReqV3); bytes 4-7 reserved",
)

START_OF_FRAME = PacketSpec(
    101,
    "start_of_frame",
    "Start of Frame",
    24,
    "ig_to_host",
    (
        version("an IG→host message's first packet"),
        s8("database_number", 3),
        u8("ig_status", 4, note="0 normal; IG-defined error codes"),
        bits("ig_mode", 5, 0, 2, 3, "0 reset/standby, 1 operate, 2 debug, 3 offline"),
        flag("timestamp_valid", 5, 2),
        flag("earth_reference_model", 5, 3, "0 WGS 84, 1 host-defined"),
        minor_version(5),
        magic(),
        u32("ig_frame_number", 8),
        u32("timestamp_10us", 12, note="10 µs ticks"),
        u32("last_host_frame_number", 16),
    ),
    "protocols §6.4 (CCL CigiSOFV3_2)",
    starts_message=True,
)

WEATHER_CONDITIONS_RESPONSE = PacketSpec(
    109,
    "weather_conditions_response",
    "Weather Conditions Response",
    32,
    "ig_to_host",
    (
        u8("request_id", 2),
        u8("humidity_pct", 3, 0, 100),
        f32("temperature_c", 4, -273.15),
        f32("visibility_m", 8, 0.0),
        f32("wind_speed_mps", 12, 0.0, note="horizontal"),
        f32("vertical_wind_speed_mps", 16, note="positive up"),
        angle("wind_dir_deg", 20, 0.0, "true, from"),
        f32("pressure_hpa", 24, 0.0, note="millibars on the wire (= hPa)"),
    ),
    "issue 15 and protocols §6.10a (CCL CigiWeatherCondRespV3)",
)

AEROSOL_CONCENTRATION_RESPONSE = PacketSpec(
    110,
    "aerosol_concentration_response",
    "Aerosol Concentration Response",
    8,
    "ig_to_host",
    (
        u8("request_id", 2),
        u8("layer_id", 3, note="one packet per layer"),
        f32("aerosol_concentration_gpm3", 4, 0.0, note="g/m³"),
    ),
    "issue 15 and protocols §6.10a (CCL CigiAerosolRespV3)",
)

PACKETS: tuple[PacketSpec, ...] = (
    IG_CONTROL,
    ENTITY_CONTROL,
    CELESTIAL_SPHERE_CONTROL,
    ATMOSPHERE_CONTROL,
    ENVIRONMENTAL_REGION_CONTROL,
    WEATHER_CONTROL,
    VIEW_CONTROL,
    VIEW_DEFINITION,
    ENVIRONMENTAL_CONDITIONS_REQUEST,
    START_OF_FRAME,
    WEATHER_CONDITIONS_RESPONSE,
    AEROSOL_CONCENTRATION_RESPONSE,
)
BY_OPCODE: Mapping[int, PacketSpec] = MappingProxyType({p.opcode: p for p in PACKETS})
BY_KEY: Mapping[str, PacketSpec] = MappingProxyType({p.key: p for p in PACKETS})
START_PACKETS: Mapping[str, PacketSpec] = MappingProxyType(
    {p.direction: p for p in PACKETS if p.starts_message}
)


def _check_table() -> None:
    # A table mistake would misread every datagram: refuse to import rather than assert,
    # which -O would strip.
    for spec in PACKETS:
        if problems := table_problems(spec):
            raise ValueError(f"CIGI table, {spec.name}: {'; '.join(problems)}")
    if len(BY_OPCODE) != len(PACKETS) or len(BY_KEY) != len(PACKETS):
        raise ValueError("CIGI table: duplicate opcode or key")


_check_table()


# --- docs -------------------------------------------------------------------------------------


def _rows(spec: PacketSpec) -> list[tuple[int, str]]:
    rows = [
        (0, f"| 0 | u8 | packet id | = {spec.opcode} | |"),
        (1, f"| 1 | u8 | packet size | = {spec.size} | |"),
    ]
    taken: set[int] = set(range(HEADER_SIZE))
    for f in spec.fields:
        name = f"`{f.name}`" if f.fixed is None else f.name.replace("_", " ")
        rows.append(
            (f.offset, f"| {f.offset} | {type_text(f)} | {name} | {range_text(f)} | {f.note} |")
        )
        taken |= set(range(f.offset, f.offset + KIND_SIZES[f.kind]))
    start = None
    for byte in range(spec.size + 1):
        if byte not in taken and byte < spec.size:
            start = byte if start is None else start
        elif start is not None:
            span = f"{start}" if byte - 1 == start else f"{start}–{byte - 1}"
            rows.append((start, f"| {span} | - | reserved | 0 | |"))
            start = None
    return sorted(rows, key=lambda row: row[0])  # stable: bit fields keep table order


def table_markdown() -> str:
    """Every packet's layout for docs/cigi.md, generated so the doc cannot drift."""
    out: list[str] = []
    for spec in PACKETS:
        out += [
            f"### {spec.name} ({spec.opcode}, {spec.size} bytes, {DIRECTION_TEXT[spec.direction]})",
            "",
            f"Source: {spec.source}.",
            "",
            "| Byte | Type | Field | Accepts | Notes |",
            "|---:|---|---|---|---|",
            *(row for _, row in _rows(spec)),
            "",
        ]
    return "\n".join(out)
