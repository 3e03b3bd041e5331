"""The C host kit's frames half (plugins/host-c: segment.c, frame.c, record.c), driven through
its test program `wxsky_frames_check` against real segments: written by the Python
`FrameWriter`, or by hand from its bytes for the bad ones. The hostile-input tests also run
the sanitizer build, where any AddressSanitizer or UBSan finding fails the program (exit 99
or 98)."""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import signal
import struct
import subprocess
import sys
import textwrap
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
from host_kit import host_kit, host_kit_sanitized, sanitizer_env  # noqa: F401

from wxsky.output import shm
from wxsky.output.frame_meta import RECORD_SIZE, FrameMeta, ShadowPlacement
from wxsky.output.shm import FrameWriter, LayerSpec
from wxsky.scene.camera import Camera

PROGRAM = "wxsky_frames_check"
SANITIZER_EXIT = (98, 99)
# The layers the pixel and record tests use: the daemon's kinds, small.
LAYERS = [
    LayerSpec("sky", 48, 32),
    LayerSpec("near", 48, 32),
    LayerSpec("near_front", 48, 32),
    LayerSpec("ring_0", 16, 16),
    LayerSpec("ring_in_0", 16, 16),
]
# The test pattern the checker verifies with --pattern (see wxsky_frames_check.c).
PATTERN_FRAME = 2654435761
PATTERN_LAYER = 40503


# ---- helpers -------------------------------------------------------------------------------


def unlink(name: str) -> None:
    with contextlib.suppress(FileNotFoundError):
        shm._shm_unlink(name)


@pytest.fixture
def names() -> Iterator[Callable[[], str]]:
    """A maker of unique segment names; every segment of those names is removed afterwards."""
    made: list[str] = []

    def make() -> str:
        made.append(f"wxsky-hc-{os.getpid()}-{uuid.uuid4().hex[:10]}")
        return made[-1]

    yield make
    for name in made:
        unlink(name)


@pytest.fixture
def name(names: Callable[[], str]) -> str:
    return names()


@pytest.fixture(params=[False, True], ids=["plain", "sanitized"])
def build(request: pytest.FixtureRequest) -> tuple[Path, bool]:
    """Either build of the kit, and whether it is the sanitizer one."""
    sanitized: bool = request.param
    folder = request.getfixturevalue("host_kit_sanitized" if sanitized else "host_kit")
    return folder, sanitized


def run(
    folder: Path, *args: str, sanitized: bool = False, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    proc = subprocess.run(
        [str(folder / PROGRAM), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=sanitizer_env() if sanitized else None,
        check=False,
    )
    assert proc.returncode not in SANITIZER_EXIT, proc.stderr
    assert "Sanitizer" not in proc.stderr and "runtime error" not in proc.stderr, proc.stderr
    return proc


def run_json(folder: Path, *args: str, sanitized: bool = False) -> list[dict[str, Any]]:
    proc = run(folder, *args, sanitized=sanitized)
    assert proc.returncode == 0, proc.stderr
    return [json.loads(line) for line in proc.stdout.splitlines()]


class Repl:
    """`wxsky_frames_check repl NAME`: one command in, one JSON reply out."""

    def __init__(self, folder: Path, name: str, sanitized: bool = False) -> None:
        self.sanitized = sanitized
        self.proc = subprocess.Popen(
            [str(folder / PROGRAM), "repl", name],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=sanitizer_env() if sanitized else None,
        )

    def __call__(self, command: str) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        assert line, f"{PROGRAM} repl died on {command!r}: {self.finish()}"
        reply: dict[str, Any] = json.loads(line)
        assert reply["cmd"] == command.split()[0]
        return reply

    def finish(self) -> str:
        _, stderr = self.proc.communicate("quit\n", timeout=60)
        assert self.proc.returncode not in SANITIZER_EXIT, stderr
        assert "Sanitizer" not in stderr and "runtime error" not in stderr, stderr
        return stderr

    def __enter__(self) -> Repl:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.proc.poll() is None:
            self.finish()
        assert self.proc.returncode == 0


def fnv1a64(data: bytes) -> str:
    h = 0xCBF29CE484222325
    for byte in data:
        h = ((h ^ byte) * 0x100000001B3) & 0xFFFF_FFFF_FFFF_FFFF
    return f"{h:016x}"


def fill(writer: FrameWriter, layer: str, pixels: npt.NDArray[np.uint8]) -> None:
    height, width, _ = pixels.shape
    np.frombuffer(writer.layer_buffer(layer, width, height), dtype=np.uint8)[:] = pixels.ravel()


def quads(rng: np.random.Generator) -> npt.NDArray[np.float64]:
    return rng.normal(scale=12_000.0, size=(8, 4, 3))


def make_record(frame: int, fading: bool, seed: int = 0) -> FrameMeta:
    rng = np.random.default_rng(seed + frame)
    return FrameMeta(
        frame_number=frame,
        ring_version=3 * frame + 1,
        time_utc_unix_s=1_718_000_000.0 + frame / 30.0,
        camera=Camera(
            position_m=(1210.5, -35.25, 1500.0 + frame),
            heading_deg=123.4,
            pitch_deg=-5.5,
            roll_deg=12.25,
            fov_deg=70.0,
            width_px=48,
            height_px=32,
        ),
        sun_direction_enu=(0.1, -0.2, float(np.sqrt(1 - 0.05))),
        ring_centre_m=(1000.0 / 3.0, -2.0, 1499.75),
        ring_radius_m=20_000.0,
        ring_quads_m=quads(rng),
        ring_set=1,
        ring_fade=0.375 if fading else 0.0,
        incoming_centre_m=(4000.125, 17.5, 1600.0) if fading else None,
        incoming_radius_m=21_000.5 if fading else 0.0,
        incoming_quads_m=quads(rng) if fading else None,
        # A shadow map on odd frames, none on even ones.
        shadow=ShadowPlacement(
            version=2 * frame + 5,
            centre_m=(1000.0 / 7.0, -2500.125, 432.0),
            size_m=16_000.0,
            sun_direction_enu=(0.6, 0.0, 0.8),
        )
        if frame % 2
        else None,
    )


def expected_record(meta: FrameMeta) -> dict[str, Any]:
    cam = meta.camera
    no_quads = np.zeros((8, 4, 3))
    return {
        "record_version": 3,
        "frame_number": meta.frame_number,
        "ring_version": meta.ring_version,
        "time_utc_unix_s": meta.time_utc_unix_s,
        "position_m": list(cam.position_m),
        "heading_deg": cam.heading_deg,
        "pitch_deg": cam.pitch_deg,
        "roll_deg": cam.roll_deg,
        "fov_deg": cam.fov_deg,
        "width_px": cam.width_px,
        "height_px": cam.height_px,
        "sun_direction_enu": list(meta.sun_direction_enu),
        "ring_centre_m": list(meta.ring_centre_m),
        "ring_radius_m": meta.ring_radius_m,
        "ring_quads_m": meta.ring_quads_m.tolist(),
        "ring_set": meta.ring_set,
        "fading": int(meta.fading),
        "ring_fade": meta.ring_fade,
        "ring_in_centre_m": list(meta.incoming_centre_m or (0.0, 0.0, 0.0)),
        "ring_in_radius_m": meta.incoming_radius_m,
        "ring_in_quads_m": (
            meta.incoming_quads_m if meta.incoming_quads_m is not None else no_quads
        ).tolist(),
        "shadow_version": 0 if meta.shadow is None else meta.shadow.version,
        "shadow_centre_m": list(meta.shadow.centre_m) if meta.shadow else [0.0] * 3,
        "shadow_size_m": meta.shadow.size_m if meta.shadow else 0.0,
        "shadow_sun_enu": list(meta.shadow.sun_direction_enu) if meta.shadow else [0.0] * 3,
    }


def pattern_fill(writer: FrameWriter, frame: int, base: npt.NDArray[np.uint32]) -> None:
    """The pattern `--pattern` checks: sizes and every pixel follow from the frame number."""
    for k, spec in enumerate(writer.layers):
        width, height = spec.max_width - frame % 7, spec.max_height - frame % 5
        seed = np.uint32((frame * PATTERN_FRAME + k * PATTERN_LAYER) & 0xFFFF_FFFF)
        buf = writer.layer_buffer(spec.name, width, height)
        np.frombuffer(buf, dtype=np.uint32)[:] = base[: width * height] + seed


def segment_bytes(name: str) -> bytes:
    fd = shm._shm_open(name, os.O_RDONLY)
    try:
        return os.pread(fd, os.fstat(fd).st_size, 0)
    finally:
        os.close(fd)


def write_segment(name: str, data: bytes) -> None:
    fd = shm._shm_open(name, os.O_CREAT | os.O_EXCL | os.O_RDWR)
    try:
        os.ftruncate(fd, len(data))
        os.pwrite(fd, data, 0)
    finally:
        os.close(fd)


# ---- header, record, pixels ----------------------------------------------------------------


def test_open_reports_the_header_and_layer_table_python_wrote(
    host_kit: Path,  # noqa: F811
    name: str,
) -> None:
    with FrameWriter.create(name, LAYERS, meta_capacity=2048) as writer:
        (header,) = run_json(host_kit, "open", name)
        layout = writer._layout
        assert header["size"] == writer.segment_size
        assert header["version"] == 1 and header["slot_count"] == 2
        assert header["header_size"] == layout.header_size
        assert header["slot_size"] == layout.slot_size
        assert header["meta_capacity"] == 2048
        assert header["writer_pid"] == os.getpid()
        assert (header["state"], header["publish_count"], header["latest_frame"]) == (1, 0, 0)
        assert header["layers"] == [
            {
                "name": spec.name,
                "max_width": spec.max_width,
                "max_height": spec.max_height,
                "capacity": spec.capacity,
                "format": 0,  # RGBA8: a version 1 segment has no other
                "bytes_per_pixel": 4,
                "index": k,
            }
            for k, spec in enumerate(LAYERS)
        ]
        writer.publish(41, make_record(41, False).pack())
        (header,) = run_json(host_kit, "open", name)
        assert (header["publish_count"], header["latest_frame"], header["active_slot"]) == (
            1,
            41,
            1,
        )


@pytest.mark.parametrize("fading", [False, True], ids=["steady", "fading"])
@pytest.mark.parametrize("mode", ["read", "view"])
def test_the_record_decoded_by_c_equals_what_python_wrote(
    host_kit: Path,  # noqa: F811
    name: str,
    mode: str,
    fading: bool,
) -> None:
    meta = make_record(7, fading)
    with FrameWriter.create(name, LAYERS) as writer:
        writer.publish(7, meta.pack())
        frame, summary = run_json(host_kit, mode, name)
    assert frame["meta_length"] == RECORD_SIZE == 1800
    assert frame["record_status"] == "WXSKY_OK", frame["record_error"]
    assert frame["record"] == expected_record(meta)
    assert frame["record"]["shadow_version"] == 19  # frame 7 has a map
    assert frame["consistent"], frame["inconsistency"]
    assert summary["summary"]["frames"] == 1


@pytest.mark.parametrize("mode", ["read", "view"])
def test_pixel_checksums_equal_pythons_for_every_layer(
    host_kit: Path,  # noqa: F811
    name: str,
    mode: str,
) -> None:
    rng = np.random.default_rng(13)

    def pixels(width: int, height: int) -> npt.NDArray[np.uint8]:
        return rng.integers(0, 256, size=(height, width, 4), dtype=np.uint8)

    # Two frames, one per slot: full size, smaller than capacity, odd sizes and absent layers.
    frames = [
        {"sky": pixels(48, 32), "near": pixels(40, 20), "ring_0": pixels(16, 16)},
        {"sky": pixels(17, 9), "near_front": pixels(1, 1), "ring_in_0": pixels(16, 3)},
    ]
    with FrameWriter.create(name, LAYERS) as writer, shm.FrameReader.open(name) as reader:
        for number, layers in enumerate(frames, start=1):
            for layer, data in layers.items():
                fill(writer, layer, data)
            writer.publish(number, make_record(number, number == 2).pack())
            frame, _ = run_json(host_kit, mode, name)
            python = reader.read()
            assert frame["frame_number"] == python.frame_number == number
            for got, spec in zip(frame["layers"], LAYERS, strict=True):
                want = layers.get(spec.name, np.zeros((0, 0, 4), np.uint8))
                assert got["name"] == spec.name
                assert (got["height"], got["width"]) == want.shape[:2]
                assert got["fnv"] == fnv1a64(want.tobytes())
                assert got["fnv"] == fnv1a64(python.layers[spec.name].tobytes())


# ---- bad segments ---------------------------------------------------------------------------

TEMPLATE_LAYERS = [LayerSpec("sky", 16, 8), LayerSpec("near", 16, 8), LayerSpec("ring_0", 8, 8)]


def template(name: str) -> tuple[bytes, dict[str, int]]:
    """A valid segment's bytes with one frame published, and where its fields lie."""
    with FrameWriter.create(name, TEMPLATE_LAYERS) as writer:
        fill(writer, "sky", np.full((8, 16, 4), 200, np.uint8))
        writer.publish(5, make_record(5, False).pack())
        data = segment_bytes(name)
        lay = writer._layout
    active = struct.unpack_from("<I", data, shm.HDR_ACTIVE_SLOT)[0]
    slot = lay.slot_base(active)
    where = {
        "size": len(data),
        "header_size": lay.header_size,
        "slot_size": lay.slot_size,
        "slot": slot,  # the active slot
        "other": lay.slot_base(1 - active),
        "meta": slot + lay.meta_offset,
        "pixels0": slot + lay.pixel_offsets[0],
    }
    return data, where


def patched(data: bytes, *edits: tuple[int, str, Any]) -> bytes:
    out = bytearray(data)
    for offset, fmt, value in edits:
        if fmt == "raw":
            out[offset : offset + len(value)] = value
        else:
            struct.pack_into(fmt, out, offset, value)
    return bytes(out)


def bad_segments(data: bytes, w: dict[str, int]) -> dict[str, tuple[bytes, dict[str, Any]]]:
    """case -> (bytes, the expected statuses and message fragments of probe's calls)."""
    size, hs, ss, slot, meta = w["size"], w["header_size"], w["slot_size"], w["slot"], w["meta"]
    desc1 = shm.HDR_LAYERS + shm.LAYER_DESC_SIZE
    entry0 = slot + shm.SLOT_LAYERS  # the active slot's layer table, layer 0
    entry2_other = w["other"] + shm.SLOT_LAYERS + 2 * shm.LAYER_ENTRY_SIZE

    def fails(status: str, fragment: str) -> dict[str, Any]:
        return {"open": (status, fragment)}

    def reads(call: str, status: str, fragment: str, **more: Any) -> dict[str, Any]:
        return {"open": ("WXSKY_OK", ""), call: (status, fragment), **more}

    return {
        "too_small": (data[:32], fails("WXSKY_EFORMAT", "is 32 bytes, less than the 64-byte")),
        "empty": (b"", fails("WXSKY_STARTING", "is empty: its writer is still creating it")),
        "bad_magic": (
            patched(data, (0, "raw", b"WXSKYSHX")),
            fails("WXSKY_EFORMAT", "is not a wxsky frame segment (magic 57 58 53 4b 59 53 48 58"),
        ),
        "magic_zero": (
            patched(data, (0, "raw", bytes(8))),
            fails("WXSKY_STARTING", "still creating it (no magic yet)"),
        ),
        "magic_half_written": (
            patched(data, (4, "raw", bytes(4))),
            fails("WXSKY_STARTING", "no magic yet"),
        ),
        "version_3": (
            patched(data, (shm.HDR_VERSION, "<I", 3)),
            fails(
                "WXSKY_EVERSION", "has layout version 3 (offset 8); this kit reads versions 1 to 2"
            ),
        ),
        "slot_count_3": (
            patched(data, (shm.HDR_SLOT_COUNT, "<I", 3)),
            fails("WXSKY_EFORMAT", "slot_count 3 (offset 16), expected 2"),
        ),
        "slots_past_the_end": (
            data[: hs + ss],
            fails("WXSKY_EFORMAT", f"header_size {hs} + 2 * slot_size {ss} exceeds the segment"),
        ),
        "slot_size_wraps": (
            patched(data, (shm.HDR_SLOT_SIZE, "<Q", 1 << 63)),
            fails("WXSKY_EFORMAT", f"2 * slot_size {1 << 63} exceeds the segment size {size}"),
        ),
        "header_size_unaligned": (
            patched(data, (shm.HDR_HEADER_SIZE, "<I", hs - 4)),
            fails("WXSKY_EFORMAT", "must be multiples of 8"),
        ),
        "layer_count_0": (
            patched(data, (shm.HDR_LAYER_COUNT, "<I", 0)),
            fails("WXSKY_EFORMAT", "layer_count 0 (offset 20), expected 1-64"),
        ),
        "layer_count_65": (
            patched(data, (shm.HDR_LAYER_COUNT, "<I", 65)),
            fails("WXSKY_EFORMAT", "layer_count 65 (offset 20), expected 1-64"),
        ),
        "descriptors_past_header": (
            patched(data, (shm.HDR_HEADER_SIZE, "<I", 64)),
            fails("WXSKY_EFORMAT", "header_size 64 leaves no room for 3 layer descriptors"),
        ),
        "name_control_char": (
            patched(data, (desc1 + 2, "raw", b"\x07")),
            fails("WXSKY_EFORMAT", "layer 1 name has byte 0x07 at position 2"),
        ),
        "name_space": (
            patched(data, (desc1, "raw", b"ne ar")),
            fails("WXSKY_EFORMAT", "layer 1 name has byte 0x20 at position 2"),
        ),
        "name_not_nul_padded": (
            patched(data, (desc1 + 6, "raw", b"x")),
            fails("WXSKY_EFORMAT", "layer 1 name has byte 0x78 at position 6"),
        ),
        "name_empty": (
            patched(data, (desc1, "raw", bytes(16))),
            fails("WXSKY_EFORMAT", "layer 1 has an empty name"),
        ),
        "names_twice": (
            patched(data, (desc1, "raw", b"sky\0")),
            fails("WXSKY_EFORMAT", "layers 0 and 1 are both named 'sky'"),
        ),
        "capacity_not_w_h_4": (
            patched(data, (shm.HDR_LAYERS + shm.LD_CAPACITY, "<Q", 16 * 8 * 4 + 4)),
            fails("WXSKY_EFORMAT", "layer 0 'sky' capacity 516 is not max_width 16 * max_height"),
        ),
        "capacity_wraps": (
            patched(
                data,
                (shm.HDR_LAYERS + shm.LD_MAX_WIDTH, "<I", 0xFFFF_FFFF),
                (shm.HDR_LAYERS + shm.LD_MAX_HEIGHT, "<I", 0xFFFF_FFFF),
                (shm.HDR_LAYERS + shm.LD_CAPACITY, "<Q", (0xFFFF_FFFF**2 * 4) & (2**64 - 1)),
            ),
            fails("WXSKY_EFORMAT", "layer 0 'sky' capacity"),
        ),
        "layer_offset_past_the_end": (
            patched(data, (entry2_other + shm.LE_OFFSET, "<Q", size - 4)),
            fails(
                "WXSKY_EFORMAT",
                f"layer 2 'ring_0' pixels at offset {size - 4} (256 bytes) run past the segment "
                f"end (size {size})",
            ),
        ),
        "layer_offset_huge": (
            patched(data, (entry2_other + shm.LE_OFFSET, "<Q", 2**64 - 8)),
            fails("WXSKY_EFORMAT", "run past the segment end"),
        ),
        "layer_offset_in_the_other_slot": (
            patched(data, (entry0 + shm.LE_OFFSET, "<Q", w["other"] + 1024)),
            fails("WXSKY_EFORMAT", "layer 0 'sky' pixels at offset"),
        ),
        "layer_offset_over_the_slot_header": (
            patched(data, (entry0 + shm.LE_OFFSET, "<Q", slot)),
            fails("WXSKY_EFORMAT", "lie outside the slot's data"),
        ),
        "meta_region_past_the_slot": (
            patched(data, (slot + shm.SLOT_META_OFFSET, "<I", ss - 100)),
            fails("WXSKY_EFORMAT", "metadata region at offset"),
        ),
        "state_closed": (
            patched(data, (shm.HDR_STATE, "<I", 2)),
            fails("WXSKY_ECLOSED", "has closed it (state 2)"),
        ),
        "state_initialising": (
            patched(data, (shm.HDR_STATE, "<I", 0)),
            fails("WXSKY_STARTING", "state 0"),
        ),
        "state_unknown": (
            patched(data, (shm.HDR_STATE, "<I", 9)),
            fails("WXSKY_EFORMAT", "state 9 (offset 44)"),
        ),
        "meta_length_over_capacity": (
            patched(data, (slot + shm.SLOT_META_LENGTH, "<I", 4097)),
            reads(
                "read",
                "WXSKY_EFORMAT",
                "meta_length 4097 exceeds meta_capacity 4096",
                view=("WXSKY_EFORMAT", "meta_length 4097"),
            ),
        ),
        "frame_wider_than_capacity": (
            patched(data, (entry0 + shm.LE_WIDTH, "<I", 17)),
            reads(
                "read",
                "WXSKY_EFORMAT",
                "layer 0 'sky' is 17x8, more than its capacity 16x8",
                view=("WXSKY_EFORMAT", "is 17x8"),
            ),
        ),
        "frame_pixels_moved_out": (
            patched(data, (entry0 + shm.LE_OFFSET, "<Q", size - 8)),
            fails("WXSKY_EFORMAT", "run past the segment end"),
        ),
        "active_slot_2": (
            patched(data, (shm.HDR_ACTIVE_SLOT, "<I", 2)),
            reads("read", "WXSKY_EFORMAT", "active_slot 2 (offset 40), expected 0 or 1"),
        ),
        "slot_being_written_forever": (
            patched(data, (slot + shm.SLOT_SEQ, "<Q", 3)),
            reads(
                "read",
                "WXSKY_ETIMEDOUT",
                "no consistent frame within 0 ms",
                view=("WXSKY_AGAIN", "writing or switching slots"),
            ),
        ),
        "no_frame_yet": (
            patched(data, (shm.HDR_PUBLISH_COUNT, "<Q", 0)),
            reads(
                "read",
                "WXSKY_AGAIN",
                "no frame published yet",
                view=("WXSKY_AGAIN", "no frame published yet"),
            ),
        ),
        "record_version_1": (
            patched(data, (meta, "<I", 1)),
            reads(
                "record",
                "WXSKY_EVERSION",
                "frame record version 1; this kit reads versions 2 and 3",
            ),
        ),
        "record_version_4": (
            patched(data, (meta, "<I", 4)),
            reads("record", "WXSKY_EVERSION", "frame record version 4;"),
        ),
        "record_v1_length": (
            patched(data, (meta, "<I", 1), (slot + shm.SLOT_META_LENGTH, "<I", 920)),
            reads("record", "WXSKY_EVERSION", "frame record version 1;"),
        ),
        "record_short": (
            patched(data, (slot + shm.SLOT_META_LENGTH, "<I", 1799)),
            reads("record", "WXSKY_EFORMAT", "frame record is 1799 bytes, expected 1800"),
        ),
        # A version 2 record (the daemon before the shadow map) still reads, at its length.
        "record_version_2": (
            patched(data, (meta, "<I", 2), (slot + shm.SLOT_META_LENGTH, "<I", 1736)),
            reads("record", "WXSKY_OK", ""),
        ),
        "record_version_2_short": (
            patched(data, (meta, "<I", 2), (slot + shm.SLOT_META_LENGTH, "<I", 1735)),
            reads("record", "WXSKY_EFORMAT", "1735 bytes, expected 1736 (version 2)"),
        ),
        "record_shadow_without_size": (
            patched(data, (meta + 1736, "<Q", 9), (meta + 1768, "<d", 0.0)),
            reads("record", "WXSKY_EFORMAT", "shadow_size_m is 0 at offset 1768"),
        ),
        "record_shadow_nan_sun": (
            patched(data, (meta + 1792, "<d", float("nan"))),
            reads("record", "WXSKY_EFORMAT", "shadow_sun_enu[2] at offset 1792 is not finite"),
        ),
        "record_nan": (
            patched(data, (meta + 928, "<d", float("nan"))),
            reads("record", "WXSKY_EFORMAT", "ring_fade at offset 928 is not finite (nan)"),
        ),
        "record_inf_in_a_quad": (
            patched(data, (meta + 152 + 8 * (12 * 2 + 3 * 1), "<d", float("-inf"))),
            reads("record", "WXSKY_EFORMAT", "ring_quads_m[2][1][0] at offset 368 is not finite"),
        ),
        "record_fading_7": (
            patched(data, (meta + 924, "<I", 7)),
            reads("record", "WXSKY_EFORMAT", "fading is 7 at offset 924, expected 0 or 1"),
        ),
        "record_ring_set_2": (
            patched(data, (meta + 920, "<I", 2)),
            reads("record", "WXSKY_EFORMAT", "ring_set is 2 at offset 920"),
        ),
    }


def test_bad_segments_give_the_right_status_and_message(
    build: tuple[Path, bool], names: Callable[[], str]
) -> None:
    folder, sanitized = build
    data, where = template(names())
    cases = bad_segments(data, where)
    segment = {case: names() for case in cases}
    for case, (raw, _) in cases.items():
        write_segment(segment[case], raw)
    missing = names()
    probes = [*segment.values(), missing, "bad/name", "x" * 201]
    results = run_json(folder, "probe", *probes, sanitized=sanitized)
    assert [r["name"] for r in results] == probes
    by_name = {r["name"]: r for r in results}
    for case, (_, expect) in cases.items():
        got = by_name[segment[case]]
        for call, (status, fragment) in expect.items():
            assert got.get(call) == status, (case, call, got)
            message = got[f"{call}_error"]
            assert fragment in message, (case, call, message)
            if call in ("open", "read", "view") and status != "WXSKY_OK":
                assert message.startswith(f"segment '{segment[case]}'"), (case, message)
        if "read" not in expect and got["open"] == "WXSKY_OK":
            assert got["read"] == "WXSKY_OK", (case, got)
    assert by_name[missing]["open"] == "WXSKY_ENOENT"
    assert "no shared-memory object of that name" in by_name[missing]["open_error"]
    assert by_name["bad/name"]["open"] == "WXSKY_EINVAL"
    assert "byte 0x2f at position 3" in by_name["bad/name"]["open_error"]
    assert "201 characters" in by_name["x" * 201]["open_error"]
    # The untouched template reads back whole.
    write_segment(good := names(), data)
    (result,) = run_json(folder, "probe", good, sanitized=sanitized)
    assert (result["open"], result["read"], result["record"], result["end"]) == ("WXSKY_OK",) * 4


def test_a_failing_command_exits_1_with_one_line_naming_the_status(
    host_kit: Path,  # noqa: F811
    names: Callable[[], str],
) -> None:
    proc = run(host_kit, "open", missing := names())
    assert proc.returncode == 1 and proc.stdout == ""
    assert proc.stderr == (
        f"wxsky_frames_check: WXSKY_ENOENT: segment '{missing}': no shared-memory object of "
        "that name (is the wxsky daemon running?)\n"
    )
    write_segment(bad := names(), b"NOTWXSKY" + bytes(4096))
    proc = run(host_kit, "read", bad)
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1
    assert proc.stderr.startswith(f"wxsky_frames_check: WXSKY_EFORMAT: segment '{bad}' is not")


def test_fuzzed_segments_never_crash_the_sanitized_build(
    host_kit_sanitized: Path,  # noqa: F811
    names: Callable[[], str],
) -> None:
    src = names()
    with FrameWriter.create(src, TEMPLATE_LAYERS) as writer:
        for number in (1, 2):  # both slots hold a frame
            fill(writer, "near", np.full((8, 16, 4), number, np.uint8))
            writer.publish(number, make_record(number, number == 2).pack())
        for seed in (1, 2):
            (tally,) = run_json(
                host_kit_sanitized,
                "fuzz",
                src,
                names(),
                "--seed",
                str(seed),
                "--iterations",
                "1000",
                sanitized=True,
            )
            assert tally["iterations"] == 1000
            opened = tally["open"]
            # The mutations reach every stage: refused at open, opened and read, decoded.
            assert opened.get("WXSKY_OK", 0) > 100 and opened.get("WXSKY_EFORMAT", 0) > 100, tally
            assert sum(tally["read"].values()) == opened["WXSKY_OK"]
            assert tally["read"].get("WXSKY_OK", 0) > 50, tally
            assert len(tally["record"]) >= 2, tally


# ---- the seqlock under a live writer --------------------------------------------------------


class PatternWriter(threading.Thread):
    """Publishes pattern frames as fast as it can until stopped, or in bursts of `burst`
    frames each followed by a pause."""

    def __init__(self, writer: FrameWriter, burst: int = 0, pause_s: float = 0.0) -> None:
        super().__init__(daemon=True)
        self.writer = writer
        self.burst = burst
        self.pause_s = pause_s
        self.stop = threading.Event()
        self.published = 0
        biggest = max(s.max_width * s.max_height for s in writer.layers)
        self.base = np.arange(biggest, dtype=np.uint32)
        record = make_record(0, True).pack()
        self.head, self.tail = record[:8], record[16:]

    def publish(self, frame: int) -> None:
        pattern_fill(self.writer, frame, self.base)
        self.writer.publish(frame, self.head + struct.pack("<Q", frame) + self.tail)

    def run(self) -> None:
        frame = 1
        while not self.stop.is_set():
            self.publish(frame)
            self.published = frame
            frame += 1
            if self.burst and frame % self.burst == 0:
                time.sleep(self.pause_s)


@pytest.mark.parametrize("mode", ["read", "view"])
def test_frames_read_under_a_racing_writer_are_whole_and_increasing(
    host_kit: Path,  # noqa: F811
    name: str,
    mode: str,
) -> None:
    """The copy-out read races a writer publishing flat out (thousands of frames a second,
    copies of 384 KiB). A view is checked in place (checksums and the pattern), which takes
    longer than two publishes at full speed, so for it the writer publishes in bursts of 4 with
    3 ms pauses: a view begun in a burst tears and is retried, one begun in a pause ends
    clean even on a machine several times slower. Every frame that ends clean must be whole."""
    layers = [LayerSpec("sky", 256, 256), LayerSpec("near", 256, 128)]
    with FrameWriter.create(name, layers) as writer:
        racer = PatternWriter(writer) if mode == "read" else PatternWriter(writer, 4, 0.003)
        racer.publish(0)
        racer.start()
        try:
            args = ("--frames", "200", "--pattern", "--timeout-ms", "60000")
            proc = run(host_kit, mode, name, *args)
        finally:
            racer.stop.set()
            racer.join()
    assert proc.returncode == 0, proc.stderr
    *frames, summary = (json.loads(line) for line in proc.stdout.splitlines())
    assert len(frames) == 200 and summary["summary"]["inconsistent"] == 0
    numbers = [f["frame_number"] for f in frames]
    assert all(a < b for a, b in itertools.pairwise(numbers)), numbers
    for frame in frames:
        assert frame["consistent"], frame["inconsistency"]
        assert frame["record"]["frame_number"] == frame["frame_number"]


@pytest.mark.parametrize(
    ("publishes", "status"), [(0, "OK"), (1, "OK"), (2, "ETORN"), (5, "ETORN")]
)
def test_a_view_held_until_the_writer_returns_to_its_slot_is_torn(
    host_kit: Path,  # noqa: F811
    name: str,
    publishes: int,
    status: str,
) -> None:
    with FrameWriter.create(name, [LayerSpec("sky", 32, 16)]) as writer:
        racer = PatternWriter(writer)
        racer.publish(1)
        with Repl(host_kit, name) as repl:
            assert repl("open")["status"] == "WXSKY_OK"
            begun = repl("begin")
            assert begun["status"] == "WXSKY_OK" and begun["frame_number"] == 1
            for frame in range(2, 2 + publishes):
                racer.publish(frame)
            ended = repl("end")
            assert ended["status"] == f"WXSKY_{status}", ended
            unchanged = ended["layers"] == begun["layers"]
            if status == "OK":
                assert unchanged  # the writer filled only the other slot
            else:
                assert not unchanged
                assert "overwrote slot" in ended["status_error"]
            # A new view is of the latest frame and ends clean.
            again = repl("begin")
            assert again["frame_number"] == 1 + publishes
            assert repl("end")["status"] == "WXSKY_OK"


def test_copy_out_waits_checks_buffers_and_can_skip_layers(
    build: tuple[Path, bool],
    name: str,
) -> None:
    folder, sanitized = build
    with (
        FrameWriter.create(name, LAYERS) as writer,
        Repl(folder, name, sanitized=sanitized) as repl,
    ):
        assert repl("open")["status"] == "WXSKY_OK"
        nothing = repl("read 60")
        assert nothing["status"] == "WXSKY_AGAIN", nothing
        assert "no frame published yet (waited 60 ms)" in nothing["status_error"]
        assert nothing["elapsed_ms"] >= 59
        assert repl("latest")["latest_frame"] == 0
        assert repl("begin")["status"] == "WXSKY_AGAIN"
        fill(writer, "near", np.full((20, 30, 4), 9, np.uint8))
        writer.publish(3, make_record(3, False).pack())
        assert repl("latest")["latest_frame"] == 3
        small = repl("read_small 1")
        assert small["status"] == "WXSKY_ENOSPC"
        cap = LAYERS[1].capacity
        assert small["status_error"] == (
            f"segment '{name}': the buffer for layer 1 'near' is {cap - 1} bytes, less than its "
            f"capacity {cap}"
        )
        bare = repl("read_nobuf")
        assert bare["status"] == "WXSKY_OK" and bare["frame_number"] == 3
        assert bare["sizes"] == [[0, 0], [30, 20], [0, 0], [0, 0], [0, 0]]
        assert bare["meta_length"] == RECORD_SIZE
        full = repl("read")
        assert full["status"] == "WXSKY_OK" and full["record_status"] == "WXSKY_OK"
        assert full["layers"][1]["fnv"] == fnv1a64(bytes([9]) * (20 * 30 * 4))
        assert repl("check")["status"] == "WXSKY_OK"
        assert repl("end")["status"] == "WXSKY_EINVAL"  # no view was begun


# ---- lifecycle: closed and replaced segments ------------------------------------------------


def test_a_closed_segment_is_reported_and_reopened_when_the_writer_returns(
    host_kit: Path,  # noqa: F811
    name: str,
) -> None:
    writer = FrameWriter.create(name, LAYERS)
    writer.publish(1, make_record(1, False).pack())
    with Repl(host_kit, name) as repl:
        assert repl("open")["status"] == "WXSKY_OK"
        assert repl("check")["status"] == "WXSKY_OK"
        writer.close()  # state 2, then unlinked
        for command in ("check", "read", "begin"):
            reply = repl(command)
            assert reply["status"] == "WXSKY_ECLOSED", reply
            assert "has closed it (state 2)" in reply["status_error"]
        assert repl("open")["status"] == "WXSKY_ENOENT"
        with FrameWriter.create(name, LAYERS[:2]) as again:
            again.publish(9, make_record(9, False).pack())
            reopened = repl("open")
            assert reopened["status"] == "WXSKY_OK"
            assert [layer["name"] for layer in reopened["header"]["layers"]] == ["sky", "near"]
            assert repl("read")["frame_number"] == 9
            assert repl("check")["status"] == "WXSKY_OK"


def test_a_segment_replaced_after_its_writer_died_is_reported_and_reopened(
    host_kit: Path,  # noqa: F811
    name: str,
) -> None:
    code = textwrap.dedent(
        """
        import sys, time
        from wxsky.output.shm import FrameWriter, LayerSpec
        writer = FrameWriter.create(sys.argv[1], [LayerSpec("sky", 8, 8)])
        writer.publish(1)
        print("ready", flush=True)
        time.sleep(60)
        """
    )
    dead = subprocess.Popen([sys.executable, "-c", code, name], stdout=subprocess.PIPE, text=True)
    try:
        assert dead.stdout is not None and dead.stdout.readline() == "ready\n"
        with Repl(host_kit, name) as repl:
            first = repl("open")
            assert first["status"] == "WXSKY_OK"
            assert first["header"]["writer_pid"] == dead.pid
            dead.send_signal(signal.SIGKILL)
            dead.wait(timeout=10)
            # A writer that died leaves its segment live-looking: only frames stop.
            assert repl("check")["status"] == "WXSKY_OK"
            with FrameWriter.create(name, [LayerSpec("sky", 16, 16)]) as successor:
                successor.publish(2, make_record(2, False).pack())
                replaced = repl("check")
                assert replaced["status"] == "WXSKY_ECLOSED"
                assert "now refers to another object" in replaced["status_error"]
                reopened = repl("open")
                assert reopened["status"] == "WXSKY_OK"
                assert reopened["header"]["writer_pid"] == os.getpid()
                assert reopened["header"]["layers"][0]["max_width"] == 16
                assert repl("read")["frame_number"] == 2
                assert repl("check")["status"] == "WXSKY_OK"
    finally:
        dead.kill()
        dead.wait(timeout=10)
        if dead.stdout is not None:
            dead.stdout.close()
