"""wxsky's CIGI 3.3 encoder checked by a decoder it shares nothing with: Wireshark's CIGI
dissector (issue 15, item 5). Every message the encoder makes (`cigi_examples.messages()`), and
one packet per value field with that field set to a value of its own, go into one pcap in both
byte orders (tools/pcap.py); one tshark run decodes the whole file, and each field tshark shows
must be the value that was encoded.

tshark reads CIGI 3.x in both byte orders but walks a datagram by its own idea of each packet's
length and never compares the size byte with it, so the size bytes are compared here, with
the table's sizes. It labels the timestamp "microseconds"; the wire carries 10 µs ticks and the
raw number is compared. It prints f32 values to 6 significant digits and f64 to 15 (FLT_DIG,
DBL_DIG), so floats are compared to that precision.

TSHARK maps every value field of every packet of the table to the tshark field that shows it;
NOT_SHOWN would list, with the reason, any that tshark does not show. A packet added to the
table without either fails `test_every_table_field_is_mapped`.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import pytest
from tool_loader import load_tool

from wxsky.protocols.cigi import ByteOrder, Packet, encode_datagram, make
from wxsky.protocols.cigi_examples import examples
from wxsky.protocols.cigi_fields import Field, PacketSpec
from wxsky.protocols.cigi_packets import PACKETS

pcap = load_tool("pcap")

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


def _tshark_fields() -> list[str]:
    named = {s if isinstance(s, str) else s.field for m in TSHARK.values() for s in m.values()}
    return [*FRAME_FIELDS, *PACKET_FIELDS, *PROBLEM_FIELDS, *sorted(named)]


# -- the mapping ------------------------------------------------------------------------------


def test_every_table_field_is_mapped() -> None:
    assert list(TSHARK) == [spec.key for spec in PACKETS], "TSHARK lists the table's packets"
    for spec in PACKETS:
        names = [f.name for f in spec.value_fields]
        mapped, skipped = TSHARK[spec.key], NOT_SHOWN.get(spec.key, {})
        missing = [n for n in names if n not in mapped and n not in skipped]
        assert not missing, f"{spec.name}: map {missing} to tshark fields or list in NOT_SHOWN"
        assert not set(mapped) & set(skipped), f"{spec.name}: both mapped and NOT_SHOWN"
        assert set(mapped) | set(skipped) <= set(names), f"{spec.name}: unknown fields mapped"
        assert all(skipped.values()), f"{spec.name}: NOT_SHOWN says why"
    assert set(NOT_SHOWN) <= set(TSHARK)
    # Each tshark field belongs to one packet type, so its n-th value in a datagram is the
    # n-th packet of that type.
    owners: dict[str, set[str]] = {}
    for key, mapping in TSHARK.items():
        for shown in mapping.values():
            owners.setdefault(shown if isinstance(shown, str) else shown.field, set()).add(key)
    assert {f: k for f, k in owners.items() if len(k) > 1} == {}


# -- what goes into the pcap ------------------------------------------------------------------


def _probe_value(f: Field) -> int | float:
    """A value of the field's own, in range and not its default, so that a field swapped with
    or shifted into another shows."""
    if f.kind == "bits":
        return int(f.hi) if f.hi is not None else (1 << f.width) - 1
    if f.kind in ("f32", "f64"):
        x = 1234.5678901 if f.kind == "f64" else 1234.5678  # neither exact in binary
        x = -x if f.lo is None else x
        if (f.lo is not None and x < f.lo) or (f.hi is not None and x > f.hi):
            assert f.lo is not None and f.hi is not None
            x = f.lo + (f.hi - f.lo) * 0.6180339887  # inside, not on a round number
        return x
    pattern = {"u8": 0xA5, "s8": -0x5B, "u16": 0xA55A, "u32": 0xA1B2_C3D4}[f.kind]
    return min(pattern, int(f.hi)) if f.hi is not None else pattern


def _probes(spec: PacketSpec) -> list[Packet]:
    """One packet per value field, that field set to its probe value, the rest default (or
    the example's, where the probe turns on a condition). The minor version stays 3: tshark
    picks the 3.3 layouts by it."""
    out = []
    for f in spec.value_fields:
        if f.name == "minor_version":
            continue
        values: dict[str, int | float] = {f.name: _probe_value(f)}
        if any(g.when == (f.name, values[f.name]) for g in spec.value_fields):
            # a field it turns a condition on for (date_time_valid -> a calendar date)
            values = {**examples()[spec.key].as_dict(), **values}
        out.append(make(spec.key, **values))
    return out


@dataclass(frozen=True)
class Sent:
    order: ByteOrder
    packets: list[Packet]
    datagram: Any  # pcap.Datagram (tools/pcap.py, loaded at run time)


def _sent() -> list[Sent]:
    """The example messages (as `tools/pcap.py cigi-examples` writes them), then per packet
    type in each byte order the probe packets behind their direction's first packet."""
    sent = [Sent(o, m, d) for o, m, d in pcap.cigi_example_datagrams()]
    ex = examples()
    first = {spec.direction: ex[spec.key] for spec in PACKETS if spec.starts_message}
    orders: tuple[ByteOrder, ...] = ("big", "little")
    for order in orders:
        for spec in PACKETS:
            probes = _probes(spec)
            to_ig = spec.direction == "host_to_ig"
            src, dst = (pcap.CIGI_HOST, pcap.CIGI_IG) if to_ig else (pcap.CIGI_IG, pcap.CIGI_HOST)
            messages = (
                [[p] for p in probes] if spec.starts_message else [[first[spec.direction], *probes]]
            )
            for m in messages:
                d = pcap.Datagram(len(sent) / 1000, src, dst, encode_datagram(m, order))
                sent.append(Sent(order, m, d))
    return sent


def test_the_pcap_holds_every_packet_type_in_both_orders() -> None:
    seen = Counter((s.order, p.key) for s in _sent() for p in s.packets)
    for order in ("big", "little"):
        for spec in PACKETS:
            assert seen[order, spec.key] >= len(spec.value_fields), (order, spec.key)


def test_each_probe_sets_its_own_field() -> None:
    for spec in PACKETS:
        default = make(spec.key)
        probed = [f.name for f in spec.value_fields if f.name != "minor_version"]
        probes = _probes(spec)
        assert len(probes) == len(probed), spec.name
        for name, probe in zip(probed, probes, strict=True):
            assert probe[name] != default[name], f"{spec.name}: the {name} probe leaves it"


# -- tshark -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Decoded:
    sent: list[Sent]
    rows: list[dict[str, list[str]]]  # per frame: tshark field -> its values, in order


@pytest.fixture(scope="module")
def decoded(tmp_path_factory: pytest.TempPathFactory) -> Decoded:
    assert TSHARK_EXE is not None
    work = tmp_path_factory.mktemp("tshark")
    sent = _sent()
    path = work / "cigi.pcap"
    pcap.write_pcap(path, [s.datagram for s in sent])
    fields = _tshark_fields()
    cmd = [TSHARK_EXE, "-n", "-r", str(path), "-T", "fields", "-E", "separator=/t"]
    cmd += ["-e", "frame.number"] + [a for f in fields for a in ("-e", f)]
    # An empty configuration folder: no personal preference (a forced CIGI version or byte
    # order, heuristics turned off) changes how the dissector reads the file.
    conf = work / "wireshark-config"
    conf.mkdir()
    env = {**os.environ, "WIRESHARK_CONFIG_DIR": str(conf)}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    rows: list[dict[str, list[str]]] = []
    for line in proc.stdout.splitlines():
        number, *cells = line.split("\t")
        assert len(cells) == len(fields), line
        assert int(number) == len(rows) + 1
        rows.append({f: c.split(",") if c else [] for f, c in zip(fields, cells, strict=True)})
    assert len(rows) == len(sent), proc.stderr
    return Decoded(sent, rows)


def _number(text: str) -> float:
    if text in ("True", "False"):  # booleans print as 1/0 in tshark 4.0, True/False later
        return float(text == "True")
    if text.lstrip("-").isdigit() or text.startswith("0x"):
        return float(int(text, 0))
    return float(text)


def _where(s: Sent, frame: int) -> str:
    """`frame 45 (big-endian: IG Control, 15 × View Control)`"""
    kinds = Counter(p.spec.name for p in s.packets)  # in datagram order
    parts = [name if n == 1 else f"{n} × {name}" for name, n in kinds.items()]
    return f"frame {frame} ({s.order}-endian: {', '.join(parts)})"


@needs_tshark
def test_tshark_decodes_every_datagram_as_cigi_without_complaint(decoded: Decoded) -> None:
    for frame, (s, row) in enumerate(zip(decoded.sent, decoded.rows, strict=True), 1):
        where = _where(s, frame)
        assert row["cigi.packet_id"], f"{where}: tshark did not take it for CIGI"
        assert row["_ws.expert.message"] == [], f"{where}: {row['_ws.expert.message']}"
        assert row["_ws.malformed"] == [], f"{where}: malformed"


@needs_tshark
def test_packet_ids_size_bytes_version_and_magic(decoded: Decoded) -> None:
    """tshark walks the datagram by its own packet lengths: the ids it finds say it walked in
    step with the table; the size bytes it shows must be the table's (it does not check)."""
    for frame, (s, row) in enumerate(zip(decoded.sent, decoded.rows, strict=True), 1):
        where = _where(s, frame)
        assert [int(v) for v in row["cigi.packet_id"]] == [p.opcode for p in s.packets], where
        assert [int(v) for v in row["cigi.packet_size"]] == [p.spec.size for p in s.packets], where
        assert [int(v) for v in row["cigi.frame_size"]] == [len(s.datagram.payload)], where
        assert row["cigi.version"] == ["3"], where
        assert [int(v, 0) for v in row["cigi.byte_swap"]] == [MAGIC_SHOWN[s.order]], where


def _mismatches(s: Sent, row: dict[str, list[str]], frame: int) -> list[str]:
    found = []
    keys = Counter(p.key for p in s.packets)
    nth: Counter[str] = Counter()
    for p in s.packets:
        n = nth[p.key]
        nth[p.key] += 1
        for f in p.spec.value_fields:
            shown = TSHARK[p.key].get(f.name)
            if shown is None:
                continue
            name = shown if isinstance(shown, str) else shown.field
            values = row[name]
            where = f"{_where(s, frame)}: {p.spec.name} #{n + 1} {f.name} ({name})"
            if len(values) != keys[p.key]:
                found.append(f"{where}: {len(values)} values for {keys[p.key]} packets")
                continue
            got = _number(values[n])
            if isinstance(shown, Bit):
                got = float(int(got) >> shown.bit & 1)
            want = p[f.name]
            ok = (
                math.isclose(got, want, rel_tol=REL_TOL[f.kind], abs_tol=0.0)
                if f.is_float
                else got == want
            )
            if not ok:
                found.append(f"{where}: tshark shows {values[n]}, encoded {want!r}")
    return found


@needs_tshark
@pytest.mark.parametrize("order", ["big", "little"])
def test_tshark_shows_every_encoded_value(decoded: Decoded, order: ByteOrder) -> None:
    found = []
    for frame, (s, row) in enumerate(zip(decoded.sent, decoded.rows, strict=True), 1):
        if s.order == order:
            found += _mismatches(s, row, frame)
    assert not found, "\n".join(found)


def test_pcap_writes_a_readable_ipv4_udp_record(tmp_path: Path) -> None:
    """The pcap writer alone: header, record lengths, IPv4 checksum (sums to 0xFFFF)."""
    d = pcap.Datagram(1.25, ("192.0.2.1", 8000), ("192.0.2.2", 8001), b"\x01\x18abc")
    path = tmp_path / "one.pcap"
    assert pcap.write_pcap(path, [d]) == 1
    data = path.read_bytes()
    assert data[:4] == bytes.fromhex("d4c3b2a1") and data[20:24] == (101).to_bytes(4, "little")
    sec, usec, incl, orig = (int.from_bytes(data[i : i + 4], "little") for i in (24, 28, 32, 36))
    assert (sec, usec) == (1, 250_000) and incl == orig == 20 + 8 + 5 == len(data) - 40
    ip = data[40:60]
    total = sum(int.from_bytes(ip[i : i + 2], "big") for i in range(0, 20, 2))
    assert (total & 0xFFFF) + (total >> 16) == 0xFFFF
    assert data[60:68] == bytes.fromhex("1f401f41000d0000") and data[68:] == d.payload
    with pytest.raises(ValueError):
        pcap.Datagram(0.0, ("::1", 8000), ("192.0.2.2", 8001), b"")
    with pytest.raises(ValueError):
        pcap.Datagram(0.0, ("192.0.2.1", 70_000), ("192.0.2.2", 8001), b"")
