"""Run a real wxsky daemon for N minutes under every fault of issue 14 and report how it held.

    .venv/bin/python tools/soak/soak.py --minutes 60 --out soak-out        # the figures
    .venv/bin/python tools/soak/soak.py --seconds 20 --cycle-s 5 --out DIR   # a smoke run
    .venv/bin/python tools/soak/soak.py --minutes 60 --attacks --out DIR     # issue 40's run

The daemon runs on a private socket, segment and config (640x360, METAR polled every 0.5 s)
with a METAR feed file, an NMEA line on a pty and a CANaerospace bus on an slcan adapter (a
second pty; `--can udp_multicast` uses a multicast bus instead, `--can none` none). The first
part of the N minutes is the undisturbed baseline (no input, no faults: only the checking
reader and the monitor); the rest is the soak, in cycles of `--cycle-s` (10 s) in which
separate threads, each bounded in count and time:

* rewrite the METAR feed (tools/soak/soak_feed.py: valid, garbage, truncated, gzip, a gzip that
  is cut short, a small gzip bomb, half-written, stale/far/impossible reports, removed);
* unplug the serial line and the CAN bus for 2 s and plug them in again, waiting for the
  daemon to reopen each (tools/soak/soak_links.py);
* send one new valid wind (serial) and temperature (CAN) every `--cockpit-period-s`, each
  after the bad input of tools/soak/cockpit_faults.py;
* misbehave on the control channel once a second (tools/soak/soak_control.py: connect and drop,
  slow readers, floods, bytes that are not the protocol, commands that must be refused,
  bursts of connections);
* apply a preset and release it;
* fork shared-memory readers and SIGKILL them mid-read (tools/soak/soak_shm.py farm);
* with `--attacks [NAME,...]`: one of issue 40's seven attacks a cycle, in turn
  (tools/soak/attacks.py: a year-9999 clock from control, CIGI and FlightGear, a forged Zenoh
  tick and state, a health flood and a channel SIGKILLed, CIGI conditions requests, a CIGI
  regions flood, the segment truncated). For them the daemon also listens for a CIGI host and
  a FlightGear pose (its clock following FlightGear's) on loopback ports and is a sky master
  on a loopback Zenoh endpoint with one small display channel joined (restarted when an
  attack kills it). Each attack's result (the daemon it aimed at alive, publishing, `status`
  answering, its own checks) is in the report, with a target of its own: all survived;

while a checking reader (tools/soak/soak_shm.py check) reads every frame, a client follows the
`target` notifications, and a sampler records the daemon's RSS, descriptors, threads, frame
number and log size every second. Then everything is plugged back, the daemon is stopped
with SIGTERM and the report is written to --out: report.json, soak.png (RSS, descriptors and
threads, frame rate over time) and daemon.log.

Targets (exit 1 when one is missed; 0 when all hold):

* crashes 0: the daemon ran to the end, stopped with status 0 within 15 s of SIGTERM, and
  its log has no traceback;
* torn frames 0: seen by the checking reader (frame numbers going back count too);
* valid inputs applied / sent, all: winds (serial), temperatures (CAN), METAR writes, presets
  applied and released;
* invalid inputs reaching the weather 0: bad cockpit values in the target, METAR marker
  values, bad control commands the daemon accepted;
* frame rate during the soak / during the baseline (medians of 1 s samples of the segment's
  frame number) >= 0.8;
* RSS at the end / after warm-up (10 % of the soak in, or 10 cycles where that is at most
  half of it; at most 5 min): growth < 5 %, between medians of 2-minute windows
  (`rss_windows`), both under the faults;
* descriptors and threads at the end / at the end of the baseline: at most 2 more;
* log volume during the soak: at most 120 lines and 32 KiB a minute, no line over 2,000
  characters;
* with `--attacks`: every attack survived (a channel's death counts here; the master's is a
  crash above).

The log budget is this tool's, not the issue's: a log a person can read (rate-limited
warnings, a status line every 5 s, a line per link state change).
"""

from __future__ import annotations

import argparse
import bisect
import contextlib
import itertools
import json
import logging
import os
import random
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from wxsky.errors import WxskyError
from wxsky.host.client import ControlClient
from wxsky.output.shm import FrameReader
from wxsky.settings.presets import load_preset

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the checkout, for `tools.*`
from tools.soak.attacks import (
    ATTACKS,
    AttackError,
    AttackResult,
    Daemon,
    Target,
    channel_config,
    free_tcp_port,
    latest_frame,
    run_attack,
    start_daemon,
    wait_channel,
)
from tools.soak.cockpit_faults import (
    FOREIGN_CAN_ID,
    bad_can_frames,
    bad_nmea,
    can_frame,
    look,
    temperature_frame,
    valid_temperature_c,
    valid_wind,
    wind_sentence,
)
from tools.soak.rss_parts import PARTS, rss_parts
from tools.soak.soak_control import ControlFaults
from tools.soak.soak_feed import FeedWrite, FeedWriter
from tools.soak.soak_links import MulticastCan, PtyDevice

log = logging.getLogger("soak")

TOOLS = Path(__file__).resolve().parent
SERIAL_NAME = "panel"
CAN_NAME = "canbus"
BUILTIN_PRESETS = (
    "overcast-stratus",
    "clear",
    "thunderstorm",
    "high-cirrus",
    "broken-stratocumulus",
)
# The soak's own presets: the start-up weather (fair-cumulus, same clouds and seed, no time of
# its own) with other visibilities, winds and pressures, so that applying one changes the
# weather but not what a frame costs to draw, and the frame rate stays comparable with the
# baseline's. (--builtin-presets applies the shipped ones: overcast and thunderstorm take two
# to three times as long to draw on llvmpipe, clear a seventh.)
SOAK_PRESETS = {
    f"soak-{i}": {"visibility_m": 12000.0 + 3000.0 * i, "qnh_hpa": 1000.0 + 4 * i} for i in range(5)
}
UNPLUG_S = 2.0
REOPEN_TIMEOUT_S = 15.0
START_TIMEOUT_S = 90.0
STOP_TIMEOUT_S = 15.0
SETTLE_S = 4.0
PARTS_EVERY_S = 5.0  # reading smaps walks every mapping: a few ms
RSS_WINDOW_S = 120.0  # the windows RSS growth is judged between (_report)
FAULTS = ("feed", "links", "cockpit", "presets", "kills", "control", "attacks")
DEFAULT_FAULTS = FAULTS[:-1]  # the attacks need a CIGI port, a pose port and a channel: opt in

TARGETS = {
    "fps_ratio_min": 0.8,
    "rss_growth_max": 0.05,
    "fd_growth_max": 2,
    "thread_growth_max": 2,
    "log_lines_per_min_max": 120.0,
    "log_kib_per_min_max": 32.0,
    "log_line_chars_max": 2000,
}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    length = p.add_mutually_exclusive_group()
    length.add_argument("--minutes", type=float, help="baseline + soak length (default 60)")
    length.add_argument("--seconds", type=float, help="the same in seconds, for short runs")
    p.add_argument("--out", type=Path, default=Path("soak-out"), help="report folder")
    p.add_argument("--cycle-s", type=float, default=10.0, help="fault cycle (default 10 s)")
    p.add_argument("--baseline-s", type=float, help="undisturbed part (default: 15 %%, <= 60 s)")
    p.add_argument("--size", default="640x360", help="camera and segment size, WxH")
    p.add_argument("--can", choices=("slcan", "udp_multicast", "none"), default="slcan")
    p.add_argument("--group", default="239.74.163.79", help="udp_multicast group")
    p.add_argument("--cockpit-period-s", type=float, default=0.5)
    p.add_argument("--control-period-s", type=float, default=1.0)
    p.add_argument(
        "--builtin-presets",
        action="store_true",
        help="apply the shipped presets (their clouds cost more or less to draw)",
    )
    p.add_argument("--bomb-mib", type=int, default=65, help="gzip bomb's size inflated; 0: none")
    p.add_argument("--burst", type=int, default=100, help="connections in a burst")
    p.add_argument(
        "--faults",
        type=lambda text: set(text.split(",")),
        default=set(DEFAULT_FAULTS),
        help=f"which to run, comma-separated (default: {','.join(DEFAULT_FAULTS)})",
    )
    p.add_argument(
        "--attacks",
        nargs="?",
        const="all",
        metavar="NAME,...",
        help="add issue 40's attacks to the faults, one a cycle in turn (default: all seven "
        f"cases: {','.join(ATTACKS)})",
    )
    p.add_argument(
        "--tracemalloc",
        action="store_true",
        help="run the daemon with PYTHONTRACEMALLOC=1 and have it log where Python memory grew "
        "(SIGUSR2) after the warm-up and at the end: for hunting a leak (slows the daemon)",
    )
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("-v", "--verbose", action="store_true", help="log each fault action")
    p.add_argument(
        "--rejudge",
        type=Path,
        metavar="REPORT",
        help="run nothing: print the RSS growth of a saved report.json as runs are judged now",
    )
    args = p.parse_args()
    if args.rejudge is not None:
        print(json.dumps(rejudge_rss(args.rejudge)))
        return 0
    if args.faults - set(FAULTS):
        p.error(f"--faults: unknown {', '.join(sorted(args.faults - set(FAULTS)))}")
    if args.attacks is not None:
        args.faults.add("attacks")
    if "attacks" in args.faults:
        names = args.attacks.split(",") if args.attacks not in (None, "all") else list(ATTACKS)
        unknown = [n for n in names if n not in ATTACKS]
        if unknown:
            p.error(f"--attacks: unknown {', '.join(unknown)} (known: {', '.join(ATTACKS)})")
        args.attack_names = names
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(asctime)s soak: %(message)s",
        datefmt="%H:%M:%S",
    )
    total_s = args.seconds if args.seconds is not None else 60.0 * (args.minutes or 60.0)
    if total_s < 10.0:
        p.error("run for at least 10 s")
    width, _, height = args.size.partition("x")
    plan = Plan.make(total_s, args.baseline_s, args.cycle_s, (int(width), int(height)))
    # SIGTERM as Ctrl-C: the same clean-up.
    signal.signal(signal.SIGTERM, lambda signum, frame: _interrupt())
    soak = Soak(args, plan)
    try:
        report = soak.run()
    except KeyboardInterrupt:
        log.info("interrupted; cleaning up")
        return 130
    except SoakError as exc:
        log.error("%s", exc)
        return 2
    finally:
        soak.cleanup()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "report.json").write_text(json.dumps(report, indent=1) + "\n")
    _chart(report, args.out / "soak.png")
    ok = _print_summary(report)
    return 0 if ok else 1


class SoakError(Exception):
    """The soak could not be run (the daemon did not start): no figures, exit status 2."""


def _interrupt() -> None:
    raise KeyboardInterrupt


@dataclass(frozen=True)
class Plan:
    total_s: float
    baseline_s: float
    soak_s: float
    warmup_s: float  # into the soak: where RSS growth is measured from
    cycle_s: float
    size: tuple[int, int]

    @classmethod
    def make(
        cls, total_s: float, baseline_s: float | None, cycle_s: float, size: tuple[int, int]
    ) -> Plan:
        baseline = baseline_s if baseline_s is not None else min(60.0, max(5.0, 0.15 * total_s))
        soak = total_s - baseline
        # Warm-up: a tenth of the soak, but at least every fault's rotation once (10 cycles)
        # where the soak is long enough, and never more than 5 minutes.
        warmup = min(300.0, max(0.1 * soak, min(0.5 * soak, 10 * cycle_s)))
        return cls(total_s, baseline, soak, warmup, cycle_s, size)

    def offset(self, fraction_of_10s: float) -> float:
        """A moment in the cycle, given as where it falls in a 10 s cycle."""
        return self.cycle_s * fraction_of_10s / 10.0


@dataclass
class Sample:
    t: float  # s since the daemon started
    rss_kib: int
    fds: int
    threads: int
    frame: int
    log_bytes: int
    status_fps: float | None
    clients: int | None
    block_cache_kib: int | None  # the daemon's generated cloud blocks (status block_cache)
    # What RSS is made of (status memory): glibc heap in use (live C and Python memory) and
    # Python's live blocks. Flat while RSS climbs: the allocator keeping freed pages.
    heap_in_use_kib: int | None = None
    python_blocks: int | None = None
    heap_free_kib: int | None = None  # free inside glibc's arenas, resident or not
    # RSS by kind of mapping (rss_parts.PARTS), every PARTS_EVERY_S: where a climb is.
    main_heap_kib: int | None = None
    arenas_kib: int | None = None
    jit_kib: int | None = None
    anon_kib: int | None = None
    files_kib: int | None = None


@dataclass
class TargetRecord:
    t: float
    visibility_m: float
    visibility_src: str
    qnh_hpa: float
    qnh_src: str


@dataclass
class LinkStats:
    name: str
    unplugs: int = 0
    noticed: int = 0  # the daemon's status left "open" while unplugged
    reopened: int = 0  # the daemon reported it open again, with one more reopen
    reopen_s: list[float] = field(default_factory=list)
    sent: list[tuple[float, Any]] = field(default_factory=list)  # valid values, when sent
    unplugged_at: list[float] = field(default_factory=list)
    unplugged_unseen: int = 0  # unplugs with the last value sent not yet seen 1 s later
    stalled: int = 0  # writes the device did not take in time (not counted as sent)
    # The daemon's count of this link's updates replaced by a newer one of the same field
    # before it applied them (status `superseded`): a value so replaced never shows.
    superseded: int = 0


class Soak:
    def __init__(self, args: argparse.Namespace, plan: Plan) -> None:
        self.args = args
        self.plan = plan
        self.rng = random.Random(args.seed)
        self.tmp = Path(tempfile.mkdtemp(prefix="wxsky-soak-"))
        self.sock = self.tmp / "wx.sock"
        self.log_path = self.tmp / "daemon.log"
        self.trace_path = self.tmp / "trace.jsonl"
        self.shm_name = f"wxsky-soak-{uuid.uuid4().hex[:8]}"
        self.feed = FeedWriter(self.tmp / "metar.txt", random.Random(args.seed + 1), args.bomb_mib)
        self.serial = PtyDevice(self.tmp / "ttyPANEL")
        self.can: PtyDevice | MulticastCan | None = None
        if args.can == "slcan":
            self.can = PtyDevice(self.tmp / "ttyCAN")
        elif args.can == "udp_multicast":
            self.can = MulticastCan(args.group)
        self.proc: subprocess.Popen[bytes] | None = None
        self.checker: subprocess.Popen[bytes] | None = None
        self.farm: subprocess.Popen[str] | None = None
        self.checker_stats: list[Path] = []  # one per checker run (an attack may kill one)
        self.t0 = 0.0
        self.quit = threading.Event()  # monitors
        self.stop = threading.Event()  # fault threads
        self.threads: list[threading.Thread] = []
        self.samples: list[Sample] = []
        self.targets: list[TargetRecord] = []
        self.cockpit_seen: dict[Any, list[float]] = {}
        self.cockpit_invalid: list[str] = []
        self.watcher_reconnects = 0
        self.watcher_lost_at: list[float] = []  # when the target watcher lost its connection
        self.links = {"serial": LinkStats(SERIAL_NAME), "can": LinkStats(CAN_NAME)}
        self.ready = {"serial": False, "can": False}  # the cockpit loop may send on it
        self.sending = {"serial": threading.Lock(), "can": threading.Lock()}
        self.presets: list[dict[str, Any]] = []
        self.preset_dir = self.tmp / "presets"
        self.preset_names = BUILTIN_PRESETS if args.builtin_presets else tuple(SOAK_PRESETS)
        self.kills: Counter[str] = Counter()
        self.control = ControlFaults(self.sock, random.Random(args.seed + 2), args.burst)
        self.marks: dict[str, float] = {}
        self.died_at: float | None = None
        self.exit: dict[str, Any] = {}
        self.attacking = "attacks" in args.faults
        self.endpoint = f"tcp/127.0.0.1:{free_tcp_port()}" if self.attacking else ""
        self.channels: list[Daemon] = []  # every channel started, for the clean-up
        self.master: Daemon | None = None  # the soak's daemon, as the attacks see it
        self.attack_results: list[tuple[float, AttackResult]] = []

    def now(self) -> float:
        return time.monotonic() - self.t0

    # -- the run ------------------------------------------------------------------------

    def run(self) -> dict[str, Any]:
        _write_presets(self.preset_dir)
        self.feed.write("lines")
        self.serial.plug()
        if self.can is not None:
            self.can.plug()
        self._start_daemon()
        self._wait_started()
        if self.attacking:
            self._attack_target()  # reads the CIGI and pose ports while status answers
            self._start_channel()
        self._start_readers()
        self._spawn(self._watch_target, "soak-target")
        self._spawn(self._sample, "soak-sampler")
        plan = self.plan
        log.info(
            "baseline %.0f s, soak %.0f s in %.0f s cycles", plan.baseline_s, plan.soak_s,
            plan.cycle_s,
        )  # fmt: skip
        self.marks["baseline_start"] = self.now()
        self._wait(plan.baseline_s)
        self.marks["soak_start"] = self.now()
        on = self.args.faults
        streams: list[tuple[str, Callable[[], None], str]] = [
            ("feed", self._feed_loop, "soak-feed"),
            ("links", lambda: self._link_loop("serial", self.serial, 2.0), "soak-serial"),
            ("cockpit", self._cockpit_loop, "soak-cockpit"),
            ("presets", self._preset_loop, "soak-presets"),
            ("kills", self._kill_loop, "soak-kills"),
            ("control", lambda: self.control.run(self.stop, self.args.control_period_s), "ctl"),
            ("attacks", self._attack_loop, "soak-attacks"),
        ]
        if self.can is not None:
            can_dev = self.can
            streams.append(("links", lambda: self._link_loop("can", can_dev, 6.0), "soak-can"))
        faults = [self._spawn(run, name) for kind, run, name in streams if kind in on]
        if self.args.tracemalloc:  # the daemon's first snapshot after the warm-up
            self._wait(min(plan.warmup_s, plan.soak_s))
            self._memory_report()
            self._wait(max(0.0, plan.soak_s - plan.warmup_s))
            self._memory_report()
        else:
            self._wait(plan.soak_s)
        self.marks["soak_end"] = self.now()
        self.stop.set()
        for thread in faults:
            thread.join(timeout=REOPEN_TIMEOUT_S + 20.0)
            if thread.is_alive():
                log.warning("%s did not finish", thread.name)
        log.info("soak over; settling")
        self._wait(min(SETTLE_S, max(2.0, plan.cycle_s / 2)), require_alive=False)
        self.marks["end"] = self.now()
        self.quit.set()
        for thread in self.threads:
            thread.join(timeout=5.0)
        checker = self._stop_readers()
        self._stop_daemon()
        return self._report(checker)

    def _wait(self, seconds: float, require_alive: bool = True) -> None:
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            time.sleep(min(left, 0.5))
            if self.proc is not None and self.proc.poll() is not None and self.died_at is None:
                self.died_at = self.now()
                log.error("the daemon exited with %s during the run", self.proc.returncode)
                if require_alive:
                    return

    def _spawn(self, target: Callable[[], None], name: str) -> threading.Thread:
        def guarded() -> None:
            try:
                target()
            except Exception:
                log.exception("%s failed", name)

        thread = threading.Thread(target=guarded, name=name, daemon=True)
        thread.start()
        if name in ("soak-target", "soak-sampler"):
            self.threads.append(thread)
        return thread

    # -- the daemon ---------------------------------------------------------------------

    def _config(self) -> str:
        w, h = self.plan.size
        text = f"""
[daemon]
status_interval_s = 5.0
log_level = "INFO"
[camera]
width = {w}
height = {h}
[output]
shm_name = "{self.shm_name}"
max_width = {w}
max_height = {h}
[presets]
dirs = ["{self.preset_dir}"]
[metar]
feeds = ["{self.feed.path}"]
poll_interval_s = 0.5
max_backoff_s = 2.0
[[serial]]
url = "{self.serial.path}"
name = "{SERIAL_NAME}"
"""
        if isinstance(self.can, PtyDevice):
            text += f'[[can]]\ninterface = "slcan"\nchannel = "{self.can.path}@115200"\n'
        elif isinstance(self.can, MulticastCan):
            text += f'[[can]]\ninterface = "udp_multicast"\nchannel = "{self.can.group}"\n'
        if self.can is not None:
            text += f'name = "{CAN_NAME}"\n'
        if self.attacking:
            text += '[cigi]\nlisten = ["udp:127.0.0.1:0"]\n'
            text += '[flightgear]\npose = "udp:127.0.0.1:0"\nclock = "flightgear"\n'
        return text

    def _start_daemon(self) -> None:
        cfg = self.tmp / "wxsky.toml"
        cfg.write_text(self._config())
        cmd = [sys.executable, "-m", "wxsky", "run", "--config", str(cfg)]
        cmd += ["--control", f"unix:{self.sock}", "--trace", str(self.trace_path)]
        if self.attacking:
            cmd += ["--share", f"zenoh:{self.endpoint}"]
        env = dict(os.environ)
        if self.args.tracemalloc:
            env["PYTHONTRACEMALLOC"] = "1"
        with open(self.log_path, "wb") as out:
            self.proc = subprocess.Popen(
                cmd, stdout=out, stderr=subprocess.STDOUT, start_new_session=True, env=env
            )
        self.t0 = time.monotonic()
        log.info("daemon pid %d; files in %s", self.proc.pid, self.tmp)

    def _memory_report(self) -> None:
        """Has the daemon log its tracemalloc growth (memory.TraceReport)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGUSR2)

    def _wait_started(self) -> None:
        """Until the daemon publishes frames, both links are open and the feed's first
        report is in the target."""
        assert self.proc is not None
        deadline = time.monotonic() + START_TIMEOUT_S
        first = self.feed.writes[0].expected
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise SoakError(f"the daemon exited early:\n{self._log_tail()}")
            with contextlib.suppress(WxskyError, OSError), self._client(1.0) as client:
                status = client.call("status")
                states = {i["name"]: i.get("state") for i in status["inputs"]}
                target = status["target"]
                if (
                    status["frames_published"] > 0
                    and states.get(SERIAL_NAME) == "open"
                    and (self.can is None or states.get(CAN_NAME) == "open")
                    and first is not None
                    and target["visibility_m"] == first[0]
                ):
                    self.ready = {"serial": True, "can": self.can is not None}
                    log.info("daemon up after %.1f s", self.now())
                    return
            time.sleep(0.2)
        raise SoakError(f"the daemon did not start in {START_TIMEOUT_S:.0f} s:\n{self._log_tail()}")

    def _client(self, timeout_s: float = 2.0) -> ControlClient:
        return ControlClient.connect(f"unix:{self.sock}", timeout_s=timeout_s)

    def _stop_daemon(self) -> None:
        proc = self.proc
        if proc is None:
            return
        if proc.poll() is not None:
            self.exit = {"code": proc.returncode, "stop_s": None, "killed": False}
            return
        start = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        try:
            code = proc.wait(timeout=STOP_TIMEOUT_S)
            self.exit = {"code": code, "stop_s": time.monotonic() - start, "killed": False}
        except subprocess.TimeoutExpired:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
            self.exit = {"code": proc.returncode, "stop_s": None, "killed": True}
        log.info("daemon stopped: %s", self.exit)

    def _log_tail(self) -> str:
        with contextlib.suppress(OSError):
            return self.log_path.read_text(errors="replace")[-4000:]
        return ""

    # -- shared-memory readers ----------------------------------------------------------

    def _start_readers(self) -> None:
        self._start_checker()
        self._start_farm()
        time.sleep(1.0)

    def _start_checker(self) -> None:
        stats = self.tmp / f"checker-{len(self.checker_stats)}.json"
        self.checker_stats.append(stats)
        self.checker = subprocess.Popen(
            [sys.executable, str(TOOLS / "soak_shm.py"), "check", self.shm_name, str(stats)],
            start_new_session=True,
        )

    def _start_farm(self) -> None:
        script = str(TOOLS / "soak_shm.py")
        self.farm = subprocess.Popen(
            [sys.executable, script, "farm", self.shm_name, "--seed", str(self.args.seed)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )

    def _stop_readers(self) -> dict[str, Any]:
        procs: list[subprocess.Popen[Any]] = [p for p in (self.checker, self.farm) if p]
        for proc in procs:
            if proc.poll() is not None:
                continue
            if proc is self.farm and proc.stdin is not None:
                proc.stdin.close()
            else:
                proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5.0)
        return _merged_checker_stats(self.checker_stats)

    def _kill_loop(self) -> None:
        for _ in self._cycles(1.0):
            farm = self.farm  # the attack loop starts another when an attack killed it
            assert farm is not None and farm.stdin is not None and farm.stdout is not None
            try:
                farm.stdin.write(f"kill 3 {min(2.0, self.plan.cycle_s / 4):.2f}\n")
                farm.stdin.flush()
                answer = json.loads(farm.stdout.readline() or "{}")
            except (OSError, ValueError):
                continue  # the farm died (a truncated segment faults its readers too)
            self.kills.update({k: v for k, v in answer.items() if isinstance(v, int)})

    # -- monitors -----------------------------------------------------------------------

    def _watch_target(self) -> None:
        while not self.quit.is_set():
            try:
                with self._client() as client:
                    self._note_target(client.call("status")["target"])
                    client.subscribe(["target"])
                    while not self.quit.is_set():
                        note = client.next_notification(timeout_s=0.5)
                        if note is not None and note.method == "target":
                            self._note_target(note.params)
            except (WxskyError, OSError) as exc:
                if self.quit.is_set():
                    return
                self.watcher_reconnects += 1
                self.watcher_lost_at.append(self.now())
                log.debug("target watcher: %s; reconnecting", exc)
                time.sleep(0.2)

    def _note_target(self, target: dict[str, Any]) -> None:
        t = self.now()
        seen: set[Any] = set()
        look(target, seen, self.cockpit_invalid)
        for value in seen:
            self.cockpit_seen.setdefault(value, []).append(t)
        src = target["sources"]
        self.targets.append(
            TargetRecord(
                t, target["visibility_m"], src["visibility_m"], target["qnh_hpa"], src["qnh_hpa"]
            )
        )

    def _sample(self) -> None:
        assert self.proc is not None
        pid = self.proc.pid
        reader: FrameReader | None = None
        client: ControlClient | None = None
        next_t = next_parts = time.monotonic()
        while not self.quit.is_set():
            next_t += 1.0
            try:
                rss, threads = _proc_status(pid)
                fds = len(os.listdir(f"/proc/{pid}/fd"))
            except (OSError, ValueError):
                return  # the daemon is gone
            if self.attacking:  # a segment an attack truncates would fault a mapping here
                latest = latest_frame(self.shm_name)
                frame = -1 if latest is None else latest
            else:
                try:
                    if reader is None or not reader.is_current():
                        if reader is not None:
                            reader.close()
                        reader = FrameReader.open(self.shm_name)
                    frame = reader.frame_number
                except WxskyError:
                    reader, frame = None, -1
            fps = clients = cache_kib = heap_kib = blocks = free_kib = None
            parts: dict[str, int | None] = dict.fromkeys(PARTS)
            if time.monotonic() >= next_parts:
                next_parts = time.monotonic() + PARTS_EVERY_S
                with contextlib.suppress(OSError, ValueError):
                    parts.update(rss_parts(pid))
            try:
                client = client or self._client()
                status = client.call("status", timeout_s=2.0)
                fps, clients = status["fps"], status["clients"]
                cache_kib = status["block_cache"]["bytes"] // 1024
                memory = status.get("memory") or {}
                heap_kib = (memory.get("heap") or {}).get("in_use_kib")
                blocks = memory.get("python_blocks")
                free_kib = (memory.get("heap") or {}).get("free_kib")
            except (WxskyError, OSError):
                if client is not None:
                    client.close()
                client = None
            log_bytes = self.log_path.stat().st_size
            self.samples.append(
                Sample(
                    self.now(),
                    rss,
                    fds,
                    threads,
                    frame,
                    log_bytes,
                    fps,
                    clients,
                    cache_kib,
                    heap_kib,
                    blocks,
                    free_kib,
                    *(parts[name] for name in PARTS),
                )
            )
            time.sleep(max(0.0, next_t - time.monotonic()))
        if reader is not None:
            reader.close()
        if client is not None:
            client.close()

    # -- faults -------------------------------------------------------------------------

    def _cycles(self, at_10s: float) -> Any:
        """Yields once a cycle at `at_10s` (in 10 s cycle units) until the soak ends."""
        start = time.monotonic()
        k = 0
        while True:
            when = start + k * self.plan.cycle_s + self.plan.offset(at_10s)
            if self.stop.wait(max(0.0, when - time.monotonic())):
                return
            yield k
            k += 1

    def _feed_loop(self) -> None:
        for _ in self._cycles(0.0):
            write = self.feed.write_next()
            log.debug("feed: %s %s", write.kind, write.expected)

    def _link_loop(self, kind: str, device: PtyDevice | MulticastCan, at_10s: float) -> None:
        stats = self.links[kind]
        probe = StatusProbe(f"unix:{self.sock}", SERIAL_NAME if kind == "serial" else CAN_NAME)
        try:
            for _ in self._cycles(at_10s):
                with self.sending[kind]:  # no value is half way to the device after this
                    self.ready[kind] = False
                # The cable is pulled between values, not with one on the wire: a value the
                # daemon could not have read is not one it lost.
                if not _until(lambda: self._last_value_seen(kind), 1.0):
                    stats.unplugged_unseen += 1  # a value may be lost with the cable; it counts
                reopens = probe().get("reopens", 0)
                device.unplug()
                stats.unplugs += 1
                stats.unplugged_at.append(self.now())
                if device.observable and _until(lambda: probe().get("state") != "open", UNPLUG_S):
                    stats.noticed += 1
                time.sleep(UNPLUG_S)  # and not a moment less, even at the end
                self._replug(kind, device, probe, reopens)
                stats.superseded = max(stats.superseded, probe().get("superseded", 0))
            if not device.plugged:
                self._replug(kind, device, probe, probe().get("reopens", 0))
            stats.superseded = max(stats.superseded, probe().get("superseded", 0))
        finally:
            probe.close()

    def _last_value_seen(self, kind: str) -> bool:
        sent = self.links[kind].sent
        return not sent or _seen_after(self.cockpit_seen.get(sent[-1][1]), sent[-1][0])

    def _replug(
        self, kind: str, device: PtyDevice | MulticastCan, probe: StatusProbe, reopens: int
    ) -> None:
        stats = self.links[kind]
        device.plug()
        start = time.monotonic()
        if device.observable:

            def reopened() -> bool:
                i = probe()
                return i.get("state") == "open" and i.get("reopens", 0) > reopens

            if not _until(reopened, REOPEN_TIMEOUT_S):
                log.warning(
                    "%s: not reopened %.0f s after the replug", probe.name, REOPEN_TIMEOUT_S
                )
                return
        stats.reopened += 1
        stats.reopen_s.append(time.monotonic() - start)
        self.ready[kind] = True

    def _cockpit_loop(self) -> None:
        period = self.args.cockpit_period_s
        i = 0
        next_t = time.monotonic()
        while not self.stop.wait(max(0.0, next_t - time.monotonic())):
            next_t += period
            i += 1
            with self.sending["serial"]:
                if self.ready["serial"]:
                    wind, t = valid_wind(i), self.now()  # the time before: it may show at once
                    if self.serial.write(bad_nmea(self.rng) + wind_sentence(wind)):
                        self.links["serial"].sent.append((t, wind))
                    else:
                        self.links["serial"].stalled += 1
            with self.sending["can"]:
                if self.can is not None and self.ready["can"]:
                    temperature, t = valid_temperature_c(i), self.now()
                    frames = [*bad_can_frames(), can_frame(FOREIGN_CAN_ID, bytes(8))]
                    if self.can.send_can([*frames, temperature_frame(temperature)]):
                        self.links["can"].sent.append((t, temperature))
                    else:
                        self.links["can"].stalled += 1

    def _preset_loop(self) -> None:
        client: ControlClient | None = None

        def call(method: str, params: dict[str, Any]) -> None:
            """The call, once again on a new connection if the first one fails: the daemon
            closes the longest idle client to make room in a burst of connections (the
            control faults make them) and says to connect again."""
            nonlocal client
            for attempt in (1, 2):
                try:
                    client = client or self._client()
                    client.call(method, params)
                    return
                except (WxskyError, OSError):
                    if client is not None:
                        client.close()
                    client = None
                    if attempt == 2:
                        raise

        try:
            for k in self._cycles(3.0):
                name = self.preset_names[k % len(self.preset_names)]
                record: dict[str, Any] = {"name": name, "applied_at": self.now()}
                try:
                    call("apply_preset", {"name": name})
                    record["apply_ok"] = True
                except (WxskyError, OSError) as exc:
                    record["apply_ok"] = False
                    record["error"] = f"apply: {exc}"
                self.stop.wait(self.plan.offset(4.0))  # released even when the soak ends
                record["released_at"] = self.now()
                try:
                    call("release", {})
                    record["release_ok"] = True
                except (WxskyError, OSError) as exc:
                    record["release_ok"] = False
                    record["error"] = f"{record.get('error', '')} release: {exc}".strip()
                self.presets.append(record)
        finally:
            if client is not None:
                client.close()

    # -- issue 40's attacks -------------------------------------------------------------

    def _start_channel(self) -> Daemon:
        """A small display channel joined to the soak's daemon (the Zenoh attacks' target)."""
        tag = uuid.uuid4().hex[:8]
        d = start_daemon(
            self.tmp / f"channel-{tag}",
            "channel",
            channel_config(f"wxsky-soak-ch-{tag}"),
            ("--join", f"zenoh:{self.endpoint}", "--channel", "left"),
        )
        self.channels.append(d)
        try:
            wait_channel(d)
        except AttackError as exc:
            log.warning("%s", exc)
        return d

    def _attack_target(self) -> Target:
        assert self.proc is not None
        if self.master is None:  # one for the run: it keeps the ports it read
            self.master = Daemon("master", self.proc, self.sock, self.shm_name, self.log_path)
            self.master.cigi_port()
            self.master.pose_port()
        master = self.master
        channel = self.channels[-1] if self.channels else None
        return Target(
            master,
            channel,
            endpoint=self.endpoint,
            respawn_channel=self._respawn_channel,
            weather_is_ours=False,  # the preset loop changes it every cycle
        )

    def _respawn_channel(self) -> Daemon:
        return self._start_channel()

    def _attack_loop(self) -> None:
        names: list[str] = self.args.attack_names
        for k in self._cycles(5.0):
            if self.proc is None or self.proc.poll() is not None:
                return
            if self.channels and not self.channels[-1].alive():
                self._start_channel()  # an attack before killed it
            name = names[k % len(names)]
            at = self.now()
            result = run_attack(name, self._attack_target())
            # The shared-memory readers map the segment: an attack on it can kill them too.
            if self.checker is not None and self.checker.poll() is not None:
                result.counters["checker_died"] = self.checker.returncode
                self._start_checker()
            if self.farm is not None and self.farm.poll() is not None:
                result.counters["farm_died"] = self.farm.returncode
                self._start_farm()
            self.attack_results.append((at, result))
            log.info("attack at %.0f s: %s", at, result.line())

    def _attacks_report(self) -> dict[str, Any]:
        ran = [(t, r) for t, r in self.attack_results if not r.skipped]
        return {
            "names": list(self.args.attack_names),
            "ran": len(ran),
            "survived": sum(r.survived for _, r in ran),
            "failed": [f"{t:.0f} s {r.name}: {r.what}" for t, r in ran if not r.survived][:20],
            "results": [{"t": t} | r.as_dict() for t, r in self.attack_results],
        }

    # -- clean-up -----------------------------------------------------------------------

    def cleanup(self) -> None:
        self.stop.set()
        self.quit.set()
        for channel in self.channels:
            channel.stop()
        for proc in (self.checker, self.farm, self.proc):
            if proc is not None and proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(timeout=10)
        self.serial.unplug()
        if self.can is not None:
            self.can.unplug()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(f"/dev/shm/{self.shm_name}")
        out = self.args.out
        with contextlib.suppress(OSError):
            out.mkdir(parents=True, exist_ok=True)
            _copy_log(self.log_path, out / "daemon.log")
        shutil.rmtree(self.tmp, ignore_errors=True)

    # -- the report ---------------------------------------------------------------------

    def _report(self, checker: dict[str, Any]) -> dict[str, Any]:
        m = self.marks
        baseline = [s for s in self.samples if m["baseline_start"] + 2 <= s.t <= m["soak_start"]]
        soak = [s for s in self.samples if m["soak_start"] <= s.t <= m["soak_end"]]
        settle = [s for s in self.samples if m["soak_end"] < s.t]
        warm_t = m["soak_start"] + self.plan.warmup_s
        warm, end_samples = rss_windows(soak, warm_t, m["soak_end"])
        # The baseline's last seconds, once the daemon has settled; on a machine so busy that
        # they hold fewer than two samples (the sampler's status call waited), all of it.
        fps_base = _fps(self.samples, m["baseline_start"] + 2, m["soak_start"])
        if fps_base is None:
            fps_base = _fps(self.samples, m["baseline_start"], m["soak_start"])
        fps_soak = _fps(self.samples, m["soak_start"], m["soak_end"])
        rss_warm = statistics.median(s.rss_kib for s in warm) if warm else 0
        rss_end = statistics.median(s.rss_kib for s in end_samples) if end_samples else 0
        quiet_start = baseline[-1] if baseline else self.samples[0]
        quiet_end = (settle or end_samples or self.samples)[-1]
        logs = _log_figures(self.log_path, soak, (m["soak_end"] - m["soak_start"]) / 60.0)
        tracebacks = logs.pop("tracebacks")
        crashes = []
        if self.died_at is not None:
            crashes.append(f"exited during the run at {self.died_at:.0f} s")
        if self.exit.get("killed"):
            crashes.append(f"did not stop within {STOP_TIMEOUT_S:.0f} s of SIGTERM")
        elif self.exit.get("code") not in (0, None) or not self.exit:
            crashes.append(f"exit status {self.exit.get('code')}")
        valid = self._valid_applied()
        invalid = self._invalid_reaching()
        report: dict[str, Any] = {
            "plan": {
                "total_s": self.plan.total_s,
                "baseline_s": self.plan.baseline_s,
                "soak_s": self.plan.soak_s,
                "warmup_s": self.plan.warmup_s,
                "cycle_s": self.plan.cycle_s,
                "size": list(self.plan.size),
                "can": self.args.can,
                "cpus": os.cpu_count(),
                "loadavg_end": os.getloadavg(),
                "faults": sorted(self.args.faults),
                "presets": list(self.preset_names),
                "shm_name": self.shm_name,
                "tmp": str(self.tmp),
            },
            "marks": m,
            "crashes": {"count": len(crashes), "what": crashes, "tracebacks": tracebacks},
            "exit": self.exit,
            "frames": {
                "torn": checker.get("torn"),
                "order_errors": checker.get("order_errors"),
                "read": checker.get("frames"),
                "double_reads": checker.get("double_reads"),
                "skipped": checker.get("skipped"),
                "read_errors": checker.get("read_errors"),
                "published": (quiet_end.frame - self.samples[0].frame) if self.samples else 0,
                "problems": checker.get("problems", []),
            },
            "valid": valid,
            "invalid": invalid,
            "fps": {
                "baseline": fps_base,
                "soak": fps_soak,
                "ratio": (fps_soak / fps_base) if fps_base and fps_soak is not None else None,
                "soak_p10": _fps_quantile(self.samples, m["soak_start"], m["soak_end"], 0.1),
            },
            "rss_kib": {
                "warm": rss_warm,
                "end": rss_end,
                "peak": max(s.rss_kib for s in self.samples),
                "growth": (rss_end / rss_warm - 1.0) if rss_warm else None,
                # Bounded by bytes (status block_cache limit_bytes): growth that is the cache
                # filling, not a leak.
                "block_cache_warm": _median_of(warm, "block_cache_kib"),
                "block_cache_end": _median_of(end_samples, "block_cache_kib"),
                "heap_in_use_warm": _median_of(warm, "heap_in_use_kib"),
                "heap_in_use_end": _median_of(end_samples, "heap_in_use_kib"),
                "python_blocks_warm": _median_of(warm, "python_blocks"),
                "python_blocks_end": _median_of(end_samples, "python_blocks"),
                "heap_free_warm": _median_of(warm, "heap_free_kib"),
                "heap_free_end": _median_of(end_samples, "heap_free_kib"),
                # RSS by kind of mapping (tools/soak/rss_parts.py), after warm-up and at the end
                "parts_warm": {k: _median_of(warm, f"{k}_kib") for k in PARTS},
                "parts_end": {k: _median_of(end_samples, f"{k}_kib") for k in PARTS},
            },
            "fds": {
                "start": quiet_start.fds,
                "end": quiet_end.fds,
                "max": max(s.fds for s in self.samples),
            },
            "threads": {
                "start": quiet_start.threads,
                "end": quiet_end.threads,
                "max": max(s.threads for s in self.samples),
            },
            "clients": {"start": quiet_start.clients, "end": quiet_end.clients},
            "log": logs,
            # What the frame rate pays for: each rebuild is a sprite build beside the render
            # thread and 8 impostors drawn.
            "ring_rebuilds": _ring_rebuilds(self.trace_path, self.samples, m),
            "links": {
                k: {
                    "unplugs": v.unplugs,
                    "noticed": v.noticed,
                    "reopened": v.reopened,
                    "reopen_s_max": max(v.reopen_s, default=None),
                    "stalled_writes": v.stalled,
                    "unplugged_unseen": v.unplugged_unseen,
                }
                for k, v in self.links.items()
            },
            "feed_writes": dict(Counter(w.kind for w in self.feed.writes)),
            "control": self.control.summary(),
            "reader_kills": dict(self.kills),
            "watcher_reconnects": self.watcher_reconnects,
            "samples": [list(vars(s).values()) for s in self.samples],
            "sample_fields": list(Sample.__dataclass_fields__),
        }
        if self.attacking:
            report["attacks"] = self._attacks_report()
        report["targets"] = _judge(report)
        return report

    def _valid_applied(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for kind, stats in self.links.items():
            if kind == "can" and self.can is None:
                continue
            missed = [(t, v) for t, v in stats.sent if not _seen_after(self.cockpit_seen.get(v), t)]
            out[kind] = {
                "sent": len(stats.sent),
                "applied": len(stats.sent) - len(missed),
                # Missed values the daemon replaced by a newer one of the same field (its loop
                # was busy for longer than the send period): not lost, latest wins.
                "superseded": stats.superseded,
            }
            # When each was sent, and how far the nearest unplug and watcher reconnect were:
            # what tells a value lost by the daemon from one the harness could not have seen.
            out[kind]["missed"] = [
                f"{v!r} sent at {t:.1f} s (unplug {_nearest(stats.unplugged_at, t)}, "
                f"watcher lost {_nearest(self.watcher_lost_at, t)})"
                for t, v in missed[:10]
            ]
        metar_seen = {r.visibility_m for r in self.targets if r.visibility_src == "metar"}
        expected = [w for w in self.feed.writes if w.expected is not None]
        missed_w = [w for w in expected if w.expected and w.expected[0] not in metar_seen]
        out["metar"] = {
            "sent": len(expected),
            "applied": len(expected) - len(missed_w),
            "missed": [f"{w.kind} {w.expected}" for w in missed_w[:10]],
        }
        applied = released = 0
        for p in self.presets:
            vis = load_preset(p["name"], (self.preset_dir,)).visibility_m
            during = [r for r in self.targets if p["applied_at"] <= r.t <= p["released_at"] + 1]
            after = [r for r in self.targets if p["released_at"] <= r.t <= p["released_at"] + 3]
            applied += any(r.visibility_src == "control" and r.visibility_m == vis for r in during)
            released += any(r.visibility_src != "control" for r in after)
        n = len(self.presets)
        out["presets"] = {"sent": 2 * n, "applied": applied + released}
        out["presets"]["detail"] = {"applied": applied, "released": released, "of": n}
        out["presets"]["errors"] = [
            f"{p['name']} at {p['applied_at']:.0f} s: {p['error']}"[:300]
            for p in self.presets
            if p.get("error")
        ][:10]
        return out

    def _invalid_reaching(self) -> dict[str, Any]:
        writes: list[FeedWrite] = self.feed.writes
        allowed_vis = {v for w in writes for v, _ in w.allowed}
        allowed_qnh = {q for w in writes for _, q in w.allowed}
        forbidden_vis = {v for w in writes for v in w.forbidden_visibility}
        forbidden_qnh = {q for w in writes for q in w.forbidden_qnh}
        metar: list[str] = []
        for r in self.targets:
            if r.visibility_src == "metar" and (
                r.visibility_m in forbidden_vis or r.visibility_m not in allowed_vis
            ):
                metar.append(f"{r.t:.1f} s: visibility {r.visibility_m}")
            if r.qnh_src == "metar" and (
                r.qnh_hpa in forbidden_qnh or r.qnh_hpa not in allowed_qnh
            ):
                metar.append(f"{r.t:.1f} s: qnh {r.qnh_hpa}")
        control = self.control.accepted_bad
        cockpit = sorted(set(self.cockpit_invalid))
        return {
            "count": len(cockpit) + len(set(metar)) + len(control),
            "cockpit": cockpit[:10],
            "metar": sorted(set(metar))[:10],
            "control_accepted": control[:10],
        }


# -- helpers ------------------------------------------------------------------------------


def _write_presets(folder: Path) -> None:
    base = (resources.files("wxsky.settings") / "presets" / "fair-cumulus.toml").read_text()
    base = re.sub(r"(?m)^time_utc = .*\n", "", base)  # applying one must not move the clock
    folder.mkdir(exist_ok=True)
    for i, (name, values) in enumerate(SOAK_PRESETS.items()):
        text = re.sub(r"(?m)^description = .*$", f'description = "soak preset {i}"', base)
        for key, value in values.items():
            text = re.sub(rf"(?m)^{key} = .*$", f"{key} = {value}", text)
        text = text.replace("speed_mps = 4.0", f"speed_mps = {3.0 + i}")
        (folder / f"{name}.toml").write_text(text)


class StatusProbe:
    """One input's status entry on request, over a connection made again when it is lost."""

    def __init__(self, address: str, name: str) -> None:
        self.address = address
        self.name = name
        self._client: ControlClient | None = None

    def __call__(self) -> dict[str, Any]:
        try:
            self._client = self._client or ControlClient.connect(self.address)
            status = self._client.call("status", timeout_s=2.0)
        except (WxskyError, OSError):
            self.close()
            return {}
        return next((i for i in status["inputs"] if i["name"] == self.name), {})

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
        self._client = None


def _merged_checker_stats(paths: list[Path]) -> dict[str, Any]:
    """The checking readers' stats, summed over every run of the checker (one an attack
    killed is followed by another)."""
    runs = []
    for path in paths:
        with contextlib.suppress(OSError, ValueError):
            runs.append(dict(json.loads(path.read_text())))
    if not runs:
        return {}
    out: dict[str, Any] = dict(runs[0])
    for run in runs[1:]:
        for key, value in run.items():
            if isinstance(value, list):
                out[key] = list(out.get(key) or []) + value
            elif key == "first_frame":
                continue
            elif key == "last_frame" or not isinstance(value, int):
                out[key] = value
            else:
                out[key] = (out.get(key) or 0) + value
    out["runs"] = len(runs)
    return out


def _until(predicate: Callable[[], bool], timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.1)
    return predicate()


def rss_windows(soak: list[Any], warm_t: float, end_t: float) -> tuple[list[Any], list[Any]]:
    """The samples RSS growth is judged between: RSS swings by tens of MiB from one second
    to the next while the faults run (a table build's temporaries, a flood's queue), so two
    windows of RSS_WINDOW_S under the same faults, one from the warm-up mark and one ending
    with the soak (a third of what lies between them when that is shorter). Until 2026-12-05
    they were 10 s about the mark under the faults and the last 3 s after them, which moved
    the figure by up to 9 points from run to run."""
    window = min(RSS_WINDOW_S, max(end_t - warm_t, 0.0) / 3.0)
    warm = [s for s in soak if warm_t <= s.t <= warm_t + window] or soak[:1]
    end = [s for s in soak if end_t - window <= s.t <= end_t] or soak[-3:]
    return warm, end


def rejudge_rss(report_path: Path) -> dict[str, float]:
    """RSS growth of a saved report's samples by `rss_windows` (a run from before the
    windows changed, judged as runs are now)."""
    r = json.loads(report_path.read_text())
    rows = [SimpleNamespace(**dict(zip(r["sample_fields"], s, strict=True))) for s in r["samples"]]
    m = r["marks"]
    soak = [s for s in rows if m["soak_start"] <= s.t <= m["soak_end"]]
    warm, end = rss_windows(soak, m["soak_start"] + r["plan"]["warmup_s"], m["soak_end"])
    w = statistics.median(s.rss_kib for s in warm)
    e = statistics.median(s.rss_kib for s in end)
    return {"warm_mib": w / 1024, "end_mib": e / 1024, "growth": e / w - 1.0}


def _median_of(samples: list[Sample], name: str) -> float | None:
    values = [v for s in samples if (v := getattr(s, name)) is not None]
    return statistics.median(values) if values else None


def _nearest(times: list[float], t: float) -> str:
    """The signed distance from `t` to the nearest of `times`, as text."""
    if not times:
        return "never"
    d = min((x - t for x in times), key=abs)
    return f"{d:+.1f} s"


def _seen_after(times: list[float] | None, t: float) -> bool:
    if not times:
        return False
    return bisect.bisect_left(times, t - 0.05) < len(times)


def _proc_status(pid: int) -> tuple[int, int]:
    rss = threads = 0
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1])
            elif line.startswith("Threads:"):
                threads = int(line.split()[1])
    return rss, threads


def _rates(samples: list[Sample], start: float, end: float) -> list[float]:
    window = [s for s in samples if start <= s.t <= end and s.frame >= 0]
    return [(b.frame - a.frame) / (b.t - a.t) for a, b in itertools.pairwise(window) if b.t > a.t]


def _fps(samples: list[Sample], start: float, end: float) -> float | None:
    rates = _rates(samples, start, end)
    return statistics.median(rates) if rates else None


def _fps_quantile(samples: list[Sample], start: float, end: float, q: float) -> float | None:
    rates = sorted(_rates(samples, start, end))
    return rates[int(q * (len(rates) - 1))] if rates else None


_NUMBERS = re.compile(r"\d+(\.\d+)?")


def _ring_rebuilds(path: Path, samples: list[Sample], marks: dict[str, float]) -> dict[str, Any]:
    """Ring rebuilds started in the baseline and in the soak, by reason, from the trace (its
    lines carry frame numbers; the samples say when each frame was published)."""
    frames = [s.frame for s in samples]
    times = [s.t for s in samples]

    def when(frame: int) -> float:
        i = bisect.bisect_left(frames, frame)
        return times[min(i, len(times) - 1)] if times else 0.0

    out: dict[str, Counter[str]] = {"baseline": Counter(), "soak": Counter()}
    with contextlib.suppress(OSError), path.open(encoding="utf-8", errors="replace") as f:
        for line in f:
            if '"ring_rebuild_start"' not in line:
                continue
            with contextlib.suppress(ValueError):
                event = json.loads(line)
                t = when(int(event["frame"]))
                if marks["baseline_start"] <= t < marks["soak_start"]:
                    out["baseline"][event.get("reason", "?")] += 1
                elif marks["soak_start"] <= t <= marks["soak_end"]:
                    out["soak"][event.get("reason", "?")] += 1
    soak_min = max(1e-9, (marks["soak_end"] - marks["soak_start"]) / 60.0)
    return {
        "baseline": dict(out["baseline"]),
        "soak": dict(out["soak"]),
        "soak_per_min": sum(out["soak"].values()) / soak_min,
    }


def _log_figures(path: Path, soak: list[Sample], soak_min: float) -> dict[str, Any]:
    data = path.read_bytes() if path.exists() else b""
    lines = data.decode(errors="replace").splitlines()
    start = soak[0].log_bytes if soak else 0
    end = soak[-1].log_bytes if soak else 0
    soak_lines = data[start:end].count(b"\n")
    kinds = Counter(
        _NUMBERS.sub("N", line[9:])[:100]
        for line in lines
        if " WARNING " in line or " ERROR " in line
    )
    return {
        "bytes": len(data),
        "lines": len(lines),
        "soak_bytes": end - start,
        "soak_lines": soak_lines,
        "lines_per_min": soak_lines / soak_min if soak_min else None,
        "kib_per_min": (end - start) / 1024 / soak_min if soak_min else None,
        "longest_line": max((len(line) for line in lines), default=0),
        "warnings": sum(" WARNING " in line for line in lines),
        "errors": sum(" ERROR " in line or " CRITICAL " in line for line in lines),
        "tracebacks": sum(line.startswith("Traceback") for line in lines),
        "top_warnings": kinds.most_common(8),
    }


def _copy_log(src: Path, dst: Path, limit: int = 32 << 20) -> None:
    """The daemon's log into the report folder; a huge one as its head and tail."""
    if not src.exists():
        return
    size = src.stat().st_size
    if size <= limit:
        shutil.copyfile(src, dst)
        return
    with open(src, "rb") as f, open(dst, "wb") as out:
        out.write(f.read(limit // 2))
        out.write(f"\n[... {size - limit} bytes left out ...]\n".encode())
        f.seek(size - limit // 2)
        out.write(f.read())


def _judge(r: dict[str, Any]) -> dict[str, dict[str, Any]]:
    T = TARGETS
    fps_ratio = r["fps"]["ratio"]
    growth = r["rss_kib"]["growth"]
    log = r["log"]
    judged = {
        "crashes": (r["crashes"]["count"] + r["crashes"]["tracebacks"], "0"),
        "torn_frames": ((r["frames"]["torn"] or 0) + (r["frames"]["order_errors"] or 0), "0"),
        "valid_applied": (
            {
                k: f"{v['applied']}/{v['sent']}"
                + (f" ({v['superseded']} superseded)" if v.get("superseded") else "")
                for k, v in r["valid"].items()
            },
            "all",
        ),
        "invalid_reaching": (r["invalid"]["count"], "0"),
        "fps_ratio": (fps_ratio, f">= {T['fps_ratio_min']}"),
        "rss_growth": (growth, f"< {T['rss_growth_max']}"),
        "fd_growth": (r["fds"]["end"] - r["fds"]["start"], f"<= {T['fd_growth_max']}"),
        "thread_growth": (
            r["threads"]["end"] - r["threads"]["start"],
            f"<= {T['thread_growth_max']}",
        ),
        "log_volume": (
            {
                "lines_per_min": log["lines_per_min"],
                "kib_per_min": log["kib_per_min"],
                "longest_line": log["longest_line"],
            },
            f"<= {T['log_lines_per_min_max']:.0f} lines and {T['log_kib_per_min_max']:.0f} KiB "
            f"a minute, lines <= {T['log_line_chars_max']}",
        ),
    }
    oks = {
        "crashes": judged["crashes"][0] == 0,
        "torn_frames": judged["torn_frames"][0] == 0 and r["frames"]["read"],
        # A value the daemon counted as replaced by a newer one of its field before it could
        # apply it (latest wins) is not a lost one.
        "valid_applied": all(
            v["sent"] - v["applied"] <= v.get("superseded", 0) for v in r["valid"].values()
        ),
        "invalid_reaching": judged["invalid_reaching"][0] == 0,
        "fps_ratio": fps_ratio is not None and fps_ratio >= T["fps_ratio_min"],
        "rss_growth": growth is not None and growth < T["rss_growth_max"],
        "fd_growth": judged["fd_growth"][0] <= T["fd_growth_max"],
        "thread_growth": judged["thread_growth"][0] <= T["thread_growth_max"],
        "log_volume": (log["lines_per_min"] or 0) <= T["log_lines_per_min_max"]
        and (log["kib_per_min"] or 0) <= T["log_kib_per_min_max"]
        and log["longest_line"] <= T["log_line_chars_max"],
    }
    attacks = r.get("attacks")
    if attacks is not None:  # only in a soak with --attacks
        judged["attacks_survived"] = (f"{attacks['survived']}/{attacks['ran']}", "all")
        oks["attacks_survived"] = attacks["ran"] > 0 and attacks["survived"] == attacks["ran"]
    return {k: {"value": v, "target": t, "ok": bool(oks[k])} for k, (v, t) in judged.items()}


def _print_summary(r: dict[str, Any]) -> bool:
    plan = r["plan"]
    print(
        f"soak: {plan['total_s'] / 60:.1f} min ({plan['baseline_s']:.0f} s baseline), "
        f"{plan['cpus']} cpus, {plan['size'][0]}x{plan['size'][1]}, CAN {plan['can']}"
    )
    for name, t in r["targets"].items():
        print(
            f"  {'ok  ' if t['ok'] else 'MISS'} {name}: {_fmt(t['value'])} (target {t['target']})"
        )
    f, fps, rss = r["frames"], r["fps"], r["rss_kib"]
    print(
        f"  frames: {f['read']} read and checked ({f['double_reads']} twice), {f['skipped']} "
        f"skipped, {f['read_errors']} read errors, of {f['published']} published"
    )
    print(
        f"  fps: baseline {_fmt(fps['baseline'])}, soak {_fmt(fps['soak'])}, "
        f"soak p10 {_fmt(fps['soak_p10'])}"
    )
    print(
        f"  rss: after warm-up {rss['warm'] / 1024:.1f} MiB, end {rss['end'] / 1024:.1f} MiB, "
        f"peak {rss['peak'] / 1024:.1f} MiB; fds {r['fds']}; threads {r['threads']}"
    )
    if rss.get("block_cache_end") is not None:
        print(
            f"  block cache: after warm-up {_fmt_kib(rss['block_cache_warm'])}, "
            f"end {_fmt_kib(rss['block_cache_end'])}"
        )
    if rss.get("heap_in_use_end") is not None:
        print(
            f"  heap in use: after warm-up {_fmt_kib(rss['heap_in_use_warm'])}, "
            f"end {_fmt_kib(rss['heap_in_use_end'])}; python blocks "
            f"{_fmt(rss['python_blocks_warm'])} -> {_fmt(rss['python_blocks_end'])}"
        )
    if rss.get("parts_end"):
        print(
            "  rss by mapping (warm-up -> end): "
            + ", ".join(
                f"{k} {_fmt_kib(rss['parts_warm'][k])} -> {_fmt_kib(rss['parts_end'][k])}"
                for k in PARTS
            )
        )
    rb = r.get("ring_rebuilds")
    if rb:
        print(
            f"  ring rebuilds: baseline {rb['baseline']}, soak {rb['soak']} "
            f"({rb['soak_per_min']:.1f}/min)"
        )
    lg = r["log"]
    print(
        f"  log: {lg['bytes']} bytes, {lg['lines']} lines ({lg['soak_lines']} in the soak), "
        f"{lg['warnings']} warnings, {lg['errors']} errors"
    )
    for what in r["crashes"]["what"]:
        print(f"  crash: {what}")
    for kind in ("cockpit", "metar", "control_accepted"):
        for what in r["invalid"][kind]:
            print(f"  invalid reached ({kind}): {what}")
    for kind, v in r["valid"].items():
        if isinstance(v, dict) and v.get("missed"):
            print(f"  valid missed ({kind}): {', '.join(v['missed'][:5])}")
    for what in r["valid"]["presets"].get("errors", [])[:5]:
        print(f"  preset error: {what}")
    for problem in f["problems"][:5]:
        print(f"  frames: {problem}")
    print(f"  links: {r['links']}")
    print(f"  feed writes: {r['feed_writes']}; reader kills: {r['reader_kills']}")
    print(f"  control: {r['control']['actions']}")
    attacks = r.get("attacks")
    if attacks is not None:
        print(f"  attacks: {attacks['survived']} of {attacks['ran']} survived")
        for what in attacks["failed"][:10]:
            print(f"  attack failed: {what}")
    for problem in r["control"]["problems"][:5]:
        print(f"  control problem: {problem}")
    ok = all(t["ok"] for t in r["targets"].values())
    print(f"verdict: {'PASS' if ok else 'FAIL'}")
    return ok


def _fmt_kib(kib: float | None) -> str:
    return "n/a" if kib is None else f"{kib / 1024:.1f} MiB"


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    if isinstance(value, dict):
        return ", ".join(f"{k} {_fmt(v)}" for k, v in value.items())
    return str(value)


def _chart(r: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = r["sample_fields"]
    rows = [dict(zip(names, s, strict=True)) for s in r["samples"]]
    if len(rows) < 2:
        return
    t = [row["t"] / 60.0 for row in rows]
    # A sample whose frame could not be read (-1: the segment being restored) has no rate.
    fps = [0.0] + [
        (b["frame"] - a["frame"]) / (b["t"] - a["t"])
        if b["t"] > a["t"] and a["frame"] >= 0 and b["frame"] >= 0
        else float("nan")
        for a, b in itertools.pairwise(rows)
    ]
    m = r["marks"]
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    axes[0].plot(t, [row["rss_kib"] / 1024 for row in rows], color="tab:blue", label="RSS")
    cache = [row.get("block_cache_kib") for row in rows]
    if any(c is not None for c in cache):
        axes[0].plot(
            t,
            [float("nan") if c is None else c / 1024 for c in cache],
            color="tab:purple",
            label="block cache",
        )
    heap = [row.get("heap_in_use_kib") for row in rows]
    if any(h is not None for h in heap):
        axes[0].plot(
            t,
            [float("nan") if h is None else h / 1024 for h in heap],
            color="tab:cyan",
            linewidth=0.6,
            label="heap in use",
        )
    colours = ("tab:olive", "tab:brown", "tab:red", "tab:pink", "tab:gray")
    for name, colour in zip(PARTS, colours, strict=True):
        xs = [x for x, row in zip(t, rows, strict=True) if row.get(f"{name}_kib") is not None]
        ys = [row[f"{name}_kib"] / 1024 for row in rows if row.get(f"{name}_kib") is not None]
        if xs:
            axes[0].plot(xs, ys, color=colour, linewidth=0.6, linestyle="--", label=name)
    axes[0].set_ylabel("MiB")
    axes[0].legend(loc="center right")
    axes[1].plot(t, [row["fds"] for row in rows], label="open fds", color="tab:orange")
    axes[1].plot(t, [row["threads"] for row in rows], label="threads", color="tab:green")
    axes[1].set_ylabel("count")
    axes[1].legend(loc="upper left")
    axes[2].plot(t, fps, color="tab:gray", linewidth=0.6, label="1 s")
    axes[2].axhline(r["fps"]["baseline"] or 0, color="tab:blue", linestyle="--", label="baseline")
    axes[2].axhline(
        (r["fps"]["baseline"] or 0) * TARGETS["fps_ratio_min"],
        color="tab:red",
        linestyle=":",
        label="0.8 x baseline",
    )
    axes[2].set_ylabel("frames/s")
    # A frame counter that jumps (a segment written again whole) would set the scale.
    axes[2].set_ylim(0.0, 2.0 * max(r["fps"]["baseline"] or 30.0, 1.0))
    axes[2].set_xlabel("minutes since the daemon started")
    axes[2].legend(loc="lower left")
    for ax in axes:
        ax.axvspan(m["baseline_start"] / 60, m["soak_start"] / 60, color="tab:green", alpha=0.08)
        ax.axvline((m["soak_start"] + r["plan"]["warmup_s"]) / 60, color="k", linewidth=0.5)
        ax.axvline(m["soak_end"] / 60, color="k", linewidth=0.5)
        ax.grid(alpha=0.3)
    ok = all(v["ok"] for v in r["targets"].values())
    fig.suptitle(
        f"wxsky soak: {r['plan']['total_s'] / 60:.1f} min, baseline shaded, warm-up and end "
        f"marked: {'PASS' if ok else 'FAIL'}"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


if __name__ == "__main__":
    raise SystemExit(main())
