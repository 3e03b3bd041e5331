"""wxsky's CIGI 3.3 encoder checked by a decoder it shares nothing with: Wireshark's CIGI
dissector (issue 15, item 5). Every message the encoder makes (`cigi_examples.messages()`), and
one packet per value field with that field set to a value of its own, go into one pcap in both
byte orders (tools/emulators/pcap.py); one tshark run decodes the whole file, and each field
tshark shows must be the value that was encoded.

tshark reads CIGI 3.x in both byte orders but walks a datagram by its own idea of each packet's
length and never compares the size byte with it, so the size bytes are compared here, with
the table's sizes. It labels the timestamp "microseconds"; the wire carries 10 µs ticks and the
raw number is compared. It prints f32 values to 6 significant digits and f64 to 15 (FLT_DIG,
DBL_DIG), so floats are compared to that precision.

TSHARK (tests/cigi_tshark_helpers.py) maps every value field of every packet of the table to
the tshark field that shows it; NOT_SHOWN would list, with the reason, any that tshark does not
show. A packet added to the table without either fails `test_every_table_field_is_mapped`.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from cigi_tshark_helpers import (
    MAGIC_SHOWN,
    NOT_SHOWN,
    REL_TOL,
    TSHARK,
    Bit,
    decode_pcap,
    needs_tshark,
    number,
)
from tool_loader import load_tool

from wxsky.protocols.cigi import ByteOrder, Packet, encode_datagram, make
from wxsky.protocols.cigi_examples import examples
from wxsky.protocols.cigi_fields import Field, PacketSpec
from wxsky.protocols.cigi_packets import PACKETS

pcap = load_tool("emulators/pcap")

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
    datagram: Any  # pcap.Datagram (tools/emulators/pcap.py, loaded at run time)


def _sent() -> list[Sent]:
    """The example messages (as `tools/emulators/pcap.py cigi-examples` writes them), then per
    packet type in each byte order the probe packets behind their direction's first packet."""
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
    work = tmp_path_factory.mktemp("tshark")
    sent = _sent()
    path = work / "cigi.pcap"
    pcap.write_pcap(path, [s.datagram for s in sent])
    rows = decode_pcap(path, work)
    assert len(rows) == len(sent)
    return Decoded(sent, rows)


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
            got = number(values[n])
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
