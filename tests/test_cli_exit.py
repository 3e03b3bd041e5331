"""How the `wxsky` command line behaves as a program: exit statuses (0 success, 1 runtime
failure or internal error, 2 usage error), bare commands, help with defaults, the logging and
verbosity options on every command, and option limits taken from the settings' own kinds."""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import sys
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from daemon_harness import write_config

import wxsky.app.snapshot
import wxsky.scene.camera
import wxsky.scene.ephemeris
import wxsky.settings.config
import wxsky.settings.presets
from wxsky.cli import build_parser, exit_status, main
from wxsky.cli.common import (
    EXIT_FAILURE,
    EXIT_INTERRUPTED,
    EXIT_USAGE,
    NumberArg,
    UsageError,
    log_level,
)
from wxsky.cli.metar_cmd import FORMAT_CHOICES
from wxsky.errors import FeedError, FeedUnavailable, PresetError, RenderError
from wxsky.host.client import DaemonUnavailable, RemoteError
from wxsky.png import read_png
from wxsky.scene.camera import FOV_DEG, PITCH_DEG, VIEWPORT_PX
from wxsky.schema import Number, fmt_number
from wxsky.settings.config import BLEND_STATIONS
from wxsky.weather.feeds import FORMATS
from wxsky.weather.state import ALT_M, LAT_DEG, LON_DEG, SEED, WeatherState

REPO = Path(__file__).resolve().parents[1]
FEED = REPO / "tests" / "data" / "metar" / "noaa_cycle_2025-07-26_okay_weather_HEAD1500.txt.gz"
SUN = ("sun", "--lat", "47.46", "--lon", "8.55", "--time", "2026-06-21T12:00:00Z")


def run_wxsky(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "wxsky", *args], capture_output=True, text=True, timeout=120
    )


def in_process(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


def raising(exc: BaseException) -> Any:
    def fail(*args: Any, **kwargs: Any) -> Any:
        raise exc

    return fail


# -- bare commands and --help -------------------------------------------------------------------


def test_bare_wxsky_prints_help_and_exits_0() -> None:
    proc = run_wxsky()
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage: wxsky ")
    assert "snapshot" in proc.stdout and "Exit status" in proc.stdout
    assert proc.stderr == ""


def test_version_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _ = in_process(capsys, "--version")
    assert code == 0 and out.startswith("wxsky ")


@pytest.mark.parametrize("group", ["metar", "preset"])
def test_a_bare_command_group_prints_its_help(
    capsys: pytest.CaptureFixture[str], group: str
) -> None:
    code, out, err = in_process(capsys, group)
    assert (code, err) == (0, "")
    assert out.startswith(f"usage: wxsky {group} ")


def _commands(
    parser: argparse.ArgumentParser, path: tuple[str, ...] = ()
) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """Every parser of the command line with the words that reach it: (), ("run",), ..."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _commands(sub, (*path, name))


COMMANDS = [path for path, _ in _commands(build_parser())]


def test_the_command_table_is_complete() -> None:
    assert {
        ("run",),
        ("status",),
        ("snapshot",),
        ("bench",),
        ("sun",),
        ("metar", "decode"),
        ("metar", "fetch"),
        ("preset", "list"),
        ("preset", "diff"),
    } <= set(COMMANDS)


@pytest.mark.parametrize("command", COMMANDS, ids=lambda c: " ".join(c) or "wxsky")
def test_every_help_shows_defaults_without_noise(
    capsys: pytest.CaptureFixture[str], command: tuple[str, ...]
) -> None:
    code, out, err = in_process(capsys, *command, "--help")
    assert (code, err) == (0, "")
    flat = " ".join(out.split())  # argparse wraps lines anywhere
    assert "default: None" not in flat and "default: False" not in flat
    assert "default: []" not in flat
    for option in ("--log-level LEVEL", "-v, --verbose", "--debug"):
        assert option in flat


def test_every_option_says_what_it_is() -> None:
    for path, parser in _commands(build_parser()):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue
            assert action.help, (path, action.option_strings or action.dest)


@pytest.mark.parametrize(
    ("command", "needles"),
    [
        (
            ("snapshot",),
            [
                "--size WxH picture size in pixels, width and height 16..8192 (default: 960x540)",
                "--fov-deg DEG horizontal field of view, 1..170 (default: 60)",
                "--pitch-deg DEG positive = up, -90..90 (default: 10)",
                "--heading-deg DEG 0 = north, clockwise (default: 0)",
                "--mode {ring,direct}",
                "(default: ring)",
                "--preset NAME the weather of this preset",
                "--metar REPORT the weather this METAR report states",
                "--config FILE daemon config",
            ],
        ),
        (("bench",), ["(default: 120)", "(default: 1280x720)", "(default: broken-stratocumulus)"]),
        (("metar", "fetch"), ["blend the nearest N stations, 1..10 (default: the config's"]),
        (("sun",), ["--alt-m M observer height MSL, -500..30000 (default: 0)"]),
        (("metar", "decode"), ["--month M for REPORT, 1..12 (default: "]),
    ],
)
def test_help_shows_limits_and_defaults(
    capsys: pytest.CaptureFixture[str], command: tuple[str, ...], needles: list[str]
) -> None:
    code, out, _ = in_process(capsys, *command, "--help")
    assert code == 0
    flat = " ".join(out.split())
    for needle in needles:
        assert needle in flat, needle


# -- exit statuses ------------------------------------------------------------------------------


def test_status_without_a_daemon_is_a_runtime_failure(tmp_path: Path) -> None:
    proc = run_wxsky("status", "--control", "unix:/nonexistent/x.sock")
    assert proc.returncode == 1, proc.stderr
    line = one_line(proc.stderr)
    assert line.startswith("wxsky: error: cannot connect to the wxsky daemon at unix:/nonexistent")
    assert proc.stdout == ""


def test_snapshot_size_out_of_range_names_the_dimension_and_the_range(tmp_path: Path) -> None:
    out = tmp_path / "x.png"
    proc = run_wxsky("snapshot", "--preset", "clear", "--size", "100000x100000", "--out", str(out))
    assert proc.returncode == 2, proc.stderr
    lo, hi = fmt_number(VIEWPORT_PX.lo or 0), fmt_number(VIEWPORT_PX.hi or 0)
    assert one_line(proc.stderr) == (
        f"wxsky: error: --size 100000x100000: width must be {lo}..{hi} px, got 100000"
    )
    assert not out.exists()


@pytest.mark.parametrize(
    ("size", "needle"),
    [
        ("64x9000", "--size 64x9000: height must be 16..8192 px, got 9000"),
        ("8x64", "--size 8x64: width must be 16..8192 px, got 8"),
        ("big", "--size 'big': expected WIDTHxHEIGHT"),
    ],
)
def test_size_errors(capsys: pytest.CaptureFixture[str], size: str, needle: str) -> None:
    code, _, err = in_process(capsys, "bench", "--size", size)
    assert code == EXIT_USAGE
    assert one_line(err).startswith(f"wxsky: error: {needle}")


def test_the_size_limit_is_the_cameras(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(wxsky.scene.camera, "VIEWPORT_PX", Number(16, 500, integer=True))
    code, _, err = in_process(capsys, "bench", "--size", "640x360")
    assert code == EXIT_USAGE
    assert "width must be 16..500 px, got 640" in one_line(err)


def test_an_unknown_preset_is_a_usage_error(tmp_path: Path) -> None:
    proc = run_wxsky("snapshot", "--preset", "no-such-sky", "--out", str(tmp_path / "x.png"))
    assert proc.returncode == 2, proc.stderr
    assert "unknown preset 'no-such-sky'" in one_line(proc.stderr)


@pytest.mark.parametrize(
    "args",
    [
        ("preset", "show", "no-such-sky"),
        ("bench", "--preset", "no-such-sky"),
        ("snapshot", "--preset", "clear", "--transition-to", "no-such-sky", "--out", "x.png"),
        ("run", "--preset", "no-such-sky"),
    ],
)
def test_unknown_presets_everywhere(capsys: pytest.CaptureFixture[str], args: list[str]) -> None:
    code, _, err = in_process(capsys, *args)
    assert code == EXIT_USAGE
    assert "no-such-sky" in one_line(err)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("snapshot", "--out", "x.png"), "one of the arguments --preset --metar is required"),
        (("snapshot", "--preset", "clear"), "the following arguments are required: --out"),
        (("no-such-command",), "invalid choice: 'no-such-command'"),
        (("status", "--no-such-option"), "unrecognized arguments: --no-such-option"),
        (("sun", "--lat", "north", "--lon", "0"), "--lat north is not a number"),
        (("metar", "decode", "x", "--month", "0"), "--month 0 is outside 1..12"),
        (("metar", "decode", "x", "--year", "2026.5"), "--year 2026.5 is not an integer"),
        (("bench", "--frames", "0"), "--frames 0 is outside 1..100000"),
        (("bench", "--fps", "inf"), "--fps inf is not a finite number"),
        (("bench", "--turn", "--camera-path", "p.csv"), "--turn and --camera-path"),
        (("status", "--log-level", "LOUD"), "--log-level LOUD is not a log level"),
        (("run", "--can", "can0"), "--can 'can0': expected INTERFACE:CHANNEL"),
        (("snapshot", "--preset", "clear", "--lat", "1", "--out", "x.png"), "go together"),
        (("snapshot", "--metar", "x", "--time", "noon", "--out", "x.png"), "ISO 8601"),
        (("metar", "decode"), "give a REPORT or --file PATH"),
    ],
)
def test_usage_errors_are_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], args: tuple[str, ...], needle: str
) -> None:
    code, out, err = in_process(capsys, *args)
    assert code == EXIT_USAGE, err
    line = one_line(err)
    assert line.startswith("wxsky: error: ") and needle in line, line
    assert out == ""


def test_a_feed_that_cannot_be_read_is_a_runtime_failure(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    code, _, err = in_process(capsys, "metar", "fetch", str(tmp_path / "gone.txt"))
    assert code == EXIT_FAILURE
    assert "gone.txt: no such file" in one_line(err)
    code, _, err = in_process(capsys, "metar", "decode", "--file", str(tmp_path / "gone.txt"))
    assert code == EXIT_FAILURE
    assert "gone.txt: cannot read" in one_line(err)
    # A feed that is read but is no METAR feed is the user's: a bad file.
    junk = tmp_path / "junk.txt"
    junk.write_text("hello\n")
    code, _, err = in_process(capsys, "metar", "fetch", str(junk))
    assert code == EXIT_USAGE
    assert "not a METAR feed" in one_line(err)


def test_exit_status_by_error_class() -> None:
    assert exit_status(DaemonUnavailable("no daemon")) == EXIT_FAILURE
    assert exit_status(FeedUnavailable("HTTP 503")) == EXIT_FAILURE
    assert exit_status(RenderError("no EGL")) == EXIT_FAILURE
    assert exit_status(FeedError("not a METAR feed")) == EXIT_USAGE
    assert exit_status(PresetError("unknown preset")) == EXIT_USAGE
    # The daemon refused the request: the user's; the daemon failed (protocol §2.5): runtime.
    assert exit_status(RemoteError("unknown preset 'x'")) == EXIT_USAGE
    assert exit_status(RemoteError("internal error: KeyError: 'x'")) == EXIT_FAILURE


def test_an_output_file_that_cannot_be_written_is_a_usage_error(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, fake_render: list[Any]
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    code, _, err = in_process(
        capsys, "snapshot", "--preset", "clear", "--out", str(blocker / "x.png")
    )
    assert code == EXIT_USAGE
    assert one_line(err) == f"wxsky: error: --out {blocker / 'x.png'}: {blocker} is not a directory"
    # A directory that exists but cannot be written: refused before any work too.
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o500)
    if os.access(locked, os.W_OK):
        pytest.skip("running as a user that writes anywhere (root)")
    code, _, err = in_process(
        capsys, "snapshot", "--preset", "clear", "--out", str(locked / "x.png")
    )
    assert code == EXIT_USAGE
    assert one_line(err) == (
        f"wxsky: error: --out {locked / 'x.png'}: directory {locked} is not writable"
    )


# -- internal errors and -v ---------------------------------------------------------------------


@pytest.mark.parametrize("exc", [RuntimeError("boom"), ValueError("boom")], ids=repr)
def test_an_internal_error_is_one_line_without_v(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, exc: Exception
) -> None:
    # A ValueError from inside wxsky is a bug too, not something the user typed wrong.
    monkeypatch.setattr(wxsky.scene.ephemeris, "sun_and_moon", raising(exc))
    code, _, err = in_process(capsys, *SUN)
    assert code == EXIT_FAILURE
    line = one_line(err)
    assert line.startswith(f"wxsky: internal error: {type(exc).__name__}: boom")
    assert "rerun with -v" in line
    assert "Traceback" not in err


@pytest.mark.parametrize(
    "args",
    [("-v", *SUN), (*SUN, "-v"), (*SUN, "--verbose"), ("--debug", *SUN), (*SUN, "--debug")],
    ids=" ".join,
)
def test_v_shows_the_traceback_of_an_internal_error(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, args: tuple[str, ...]
) -> None:
    monkeypatch.setattr(wxsky.scene.ephemeris, "sun_and_moon", raising(RuntimeError("boom")))
    code, _, err = in_process(capsys, *args)
    assert code == EXIT_FAILURE
    assert err.startswith("Traceback (most recent call last):")
    assert "in _cmd_sun" in err and "RuntimeError: boom" in err
    assert err.rstrip().endswith("wxsky: internal error: RuntimeError: boom")


def test_debug_shows_where_a_user_error_came_from(capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = in_process(capsys, "--debug", "preset", "show", "no-such-sky")
    assert code == EXIT_USAGE
    assert err.startswith("Traceback") and "PresetError" in err
    code, _, err = in_process(capsys, "-v", "preset", "show", "no-such-sky")
    assert code == EXIT_USAGE and "Traceback" not in err  # -v alone: user errors stay one line


def test_ctrl_c_exits_130(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(wxsky.scene.ephemeris, "sun_and_moon", raising(KeyboardInterrupt()))
    code, _, err = in_process(capsys, *SUN)
    assert code == EXIT_INTERRUPTED == 130
    assert one_line(err) == "wxsky: interrupted"


def test_a_reader_that_goes_away_is_not_a_failure() -> None:
    """`wxsky metar decode --file F --json | head -1`: far more output than a pipe holds."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "wxsky", "metar", "decode", "--file", str(FEED), "--json"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    assert proc.stdout is not None and proc.stderr is not None
    assert proc.stdout.readline().startswith(b"{")
    proc.stdout.close()
    err = proc.stderr.read().decode()
    # Not an internal error (a BrokenPipeError is an OSError), and nothing said about it.
    assert (proc.wait(timeout=60), err) == (0, "")


@pytest.mark.parametrize(
    ("args", "level"),
    [
        ((), logging.WARNING),
        (("-v",), logging.DEBUG),
        (("--log-level", "info"), logging.INFO),
        (("--log-level", "ERROR", "-v"), logging.ERROR),  # an explicit level wins over -v
    ],
)
@pytest.mark.parametrize("where", ["before", "after"])
def test_log_level_and_v_on_either_side_of_the_command(
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
    args: tuple[str, ...],
    level: int,
    where: str,
) -> None:
    seen: list[int] = []

    def record(*a: Any, **k: Any) -> Any:
        seen.append(logging.getLogger().getEffectiveLevel())
        raise KeyboardInterrupt

    monkeypatch.setattr(wxsky.scene.ephemeris, "sun_and_moon", record)
    before = logging.getLogger().level
    argv = (*args, *SUN) if where == "before" else (*SUN, *args)
    assert in_process(capsys, *argv)[0] == EXIT_INTERRUPTED
    assert seen == [level]
    assert logging.getLogger().level == before  # main leaves logging as it found it


def test_the_daemon_logs_at_its_configs_level_unless_told() -> None:
    """`run` passes its config's [daemon] log_level as the default to this."""

    def args(**given: Any) -> argparse.Namespace:
        return argparse.Namespace(**{"log_level": None, "verbose": 0, "debug": False, **given})

    assert log_level(args(), "ERROR") == "ERROR"
    assert log_level(args(verbose=1), "ERROR") == "DEBUG"
    assert log_level(args(debug=True), "ERROR") == "DEBUG"
    assert log_level(args(log_level="WARNING", verbose=2), "ERROR") == "WARNING"


def test_every_command_takes_the_logging_options() -> None:
    for path, parser in _commands(build_parser()):
        options = {o for action in parser._actions for o in action.option_strings}
        assert {"--log-level", "-v", "--verbose", "--debug"} <= options, path


# -- option limits from one source --------------------------------------------------------------

LIMITS = [
    (("snapshot", "--preset", "clear", "--out", "x.png"), "--fov-deg", FOV_DEG),
    (("snapshot", "--preset", "clear", "--out", "x.png"), "--pitch-deg", PITCH_DEG),
    (("snapshot", "--preset", "clear", "--out", "x.png"), "--alt-m", ALT_M),
    (("snapshot", "--preset", "clear", "--out", "x.png"), "--seed", SEED),
    (("snapshot", "--preset", "clear", "--out", "x.png", "--lon", "0"), "--lat", LAT_DEG),
    (("snapshot", "--preset", "clear", "--out", "x.png", "--lat", "0"), "--lon", LON_DEG),
    (("bench",), "--fov-deg", FOV_DEG),
    (("metar", "fetch", "feed.txt"), "--blend", BLEND_STATIONS),
    (("metar", "fetch", "feed.txt", "--lon", "0"), "--lat", LAT_DEG),
    (("metar", "fetch", "feed.txt", "--lat", "0"), "--lon", LON_DEG),
    (("sun", "--lon", "0"), "--lat", LAT_DEG),
    (("sun", "--lat", "0", "--lon", "0"), "--alt-m", ALT_M),
]


@pytest.mark.parametrize(
    ("base", "option", "kind"), LIMITS, ids=[f"{b[0]} {o}" for b, o, _ in LIMITS]
)
def test_option_limits_are_the_settings_limits(
    base: tuple[str, ...], option: str, kind: Number
) -> None:
    assert kind.lo is not None and kind.hi is not None
    parser = build_parser()
    for bound in (kind.lo, kind.hi):
        text = str(int(bound)) if kind.integer else repr(float(bound))
        args = parser.parse_args([*base, option, text])
        assert getattr(args, option.lstrip("-").replace("-", "_")) == bound
    step = 1 if kind.integer else 0.5
    for outside in (kind.lo - step, kind.hi + step):
        text = str(int(outside)) if kind.integer else repr(float(outside))
        with pytest.raises(UsageError, match=f"^{option} {text} is outside"):
            parser.parse_args([*base, option, text])


def test_blend_follows_the_config_kind(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    # Read when the option is used, not copied: a change of the config's limit is the CLI's.
    monkeypatch.setattr(wxsky.settings.config, "BLEND_STATIONS", Number(1, 3, integer=True))
    code, _, err = in_process(capsys, "metar", "fetch", "feed.txt", "--blend", "4")
    assert code == EXIT_USAGE
    assert one_line(err) == "wxsky: error: --blend 4 is outside 1..3"


def test_every_ranged_option_names_a_kind_that_exists() -> None:
    for path, parser in _commands(build_parser()):
        for action in parser._actions:
            if isinstance(action.type, NumberArg):
                assert isinstance(action.type.kind, Number), (path, action.option_strings)


def test_feed_format_choices_are_the_feed_readers() -> None:
    assert ("auto", *FORMATS) == FORMAT_CHOICES


# -- snapshot: the camera stands where the config puts it ---------------------------------------


@pytest.fixture
def fake_render(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """`take_snapshot` without GL: records the cameras asked for, returns a tiny picture."""
    cameras: list[Any] = []

    def take(state: WeatherState, camera: Any, *args: Any, **kwargs: Any) -> Any:
        cameras.append(camera)
        image = np.zeros((camera.height_px, camera.width_px, 4), np.uint8)
        return wxsky.app.snapshot.Snapshot(image, {}, np.zeros((8, 4, 3)), state)

    monkeypatch.setattr(wxsky.app.snapshot, "take_snapshot", take)
    return cameras


def test_snapshot_camera_height_is_the_configs(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, fake_render: list[Any]
) -> None:
    config = tmp_path / "wxsky.toml"
    config.write_text("[camera]\nalt_agl_m = 350.0\n")
    observer = wxsky.settings.presets.load_preset("clear").observer
    assert observer is not None
    out = tmp_path / "x.png"
    args = ("snapshot", "--preset", "clear", "--size", "32x16", "--out", str(out))
    assert in_process(capsys, *args, "--config", str(config))[0] == 0
    assert in_process(capsys, *args)[0] == 0
    assert in_process(capsys, *args, "--config", str(config), "--alt-m", "1234")[0] == 0
    heights = [camera.position_m[2] for camera in fake_render]
    assert heights == pytest.approx([observer.alt_m + 350.0, observer.alt_m + 2.0, 1234.0])
    assert read_png(out).shape == (16, 32, 4)


@pytest.mark.gl
def test_snapshot_renders_from_the_configured_height(tmp_path: Path) -> None:
    """The real renderer: a config's alt_agl_m gives the same picture as that --alt-m."""
    observer = wxsky.settings.presets.load_preset("overcast-stratus").observer
    assert observer is not None
    config = tmp_path / "wxsky.toml"
    config.write_text("[camera]\nalt_agl_m = 900.0\n")
    common = ("snapshot", "--preset", "overcast-stratus", "--size", "96x54", "--pitch-deg", "20")
    runs = {
        "config": ("--config", str(config)),
        "alt": ("--alt-m", repr(observer.alt_m + 900.0)),
        "ground": (),
    }
    for name, extra in runs.items():
        proc = run_wxsky(*common, *extra, "--out", str(tmp_path / f"{name}.png"))
        assert proc.returncode == 0, proc.stderr
    config_png, alt_png, ground_png = (read_png(tmp_path / f"{n}.png") for n in runs)
    assert np.array_equal(config_png, alt_png)
    assert not np.array_equal(config_png, ground_png)


@pytest.mark.gl
def test_a_daemon_that_cannot_listen_is_a_runtime_failure(tmp_path: Path) -> None:
    # The environment is in the way (a file where the socket should go), not the command.
    blocker = tmp_path / "not-a-socket"
    blocker.write_text("x", encoding="utf-8")
    # A segment of its own: the default one may be another daemon's (or test's) on this machine.
    config = write_config(tmp_path / "wxsky.toml", f"wxsky-test-{uuid.uuid4().hex[:10]}")
    proc = run_wxsky("run", "--config", str(config), "--control", f"unix:{blocker}")
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == (
        f"wxsky: error: {blocker} exists and is not a socket; refusing to replace it: remove "
        "it, or give this daemon another with --control ADDR or [output] control"
    )
