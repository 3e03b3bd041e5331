"""A private wxsky daemon wired to cockpit links the calling tool drives: NMEA on a pty whose
master the tool writes, and CANaerospace on a udp_multicast bus (None where the host has no
multicast). Shared by the cockpit latency benchmark and the soak test; `private_daemon`, the
daemon alone, also by the CIGI latency benchmark.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import can

from wxsky.host.client import ControlClient, DaemonUnavailable


@dataclass
class CockpitDaemon:
    proc: subprocess.Popen[bytes]
    client: ControlClient  # subscribed to nothing yet
    master: int  # write NMEA here: the daemon reads the pty's other end
    bus: can.BusABC | None  # send CANaerospace here; None without multicast

    def alive(self) -> bool:
        return self.proc.poll() is None


@contextlib.contextmanager
def cockpit_daemon(group: str, config_toml: str = "") -> Iterator[CockpitDaemon]:
    """Start the daemon (its shared memory and socket private to this run), connect, yield;
    on the way out stop it with SIGTERM and release the pty and the bus."""
    master, slave = os.openpty()
    bus = multicast_bus(group)
    args = ["--serial", os.ttyname(slave)]
    if bus is not None:
        args += ["--can", f"udp_multicast:{group}"]
    try:
        with private_daemon(config_toml, args) as (proc, client):
            yield CockpitDaemon(proc, client, master, bus)
    finally:
        if bus is not None:
            bus.shutdown()
        os.close(master)
        os.close(slave)


@contextlib.contextmanager
def private_daemon(
    config_toml: str = "", args: Sequence[str] = ()
) -> Iterator[tuple[subprocess.Popen[bytes], ControlClient]]:
    """`wxsky run` with `config_toml` and `args`, its shared memory and control socket private
    to this run, and a client connected to it; stopped with SIGTERM on the way out."""
    with tempfile.TemporaryDirectory() as tmp:
        sock = Path(tmp) / "wx.sock"
        cfg = Path(tmp) / "wxsky.toml"
        shm = f'shm_name = "wxsky-tool-{uuid.uuid4().hex[:8]}"\n'
        # TOML allows a table once: the name joins the caller's [output] where there is one.
        if "[output]\n" in config_toml:
            cfg.write_text(config_toml.replace("[output]\n", "[output]\n" + shm, 1))
        else:
            cfg.write_text(f"{config_toml}\n[output]\n{shm}")
        cmd = [sys.executable, "-m", "wxsky", "run", "--config", str(cfg)]
        cmd += ["--control", f"unix:{sock}", *args]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        client: ControlClient | None = None
        try:
            client = _connect(sock, proc)
            yield proc, client
        finally:
            if client is not None:
                client.close()
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()


def multicast_bus(group: str) -> can.BusABC | None:
    """A udp_multicast bus that has sent one frame, or None where multicast does not work."""
    try:
        bus = can.Bus(interface="udp_multicast", channel=group)
        bus.send(can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False))
    except (can.CanError, OSError):
        return None
    return bus


def _connect(sock: Path, proc: subprocess.Popen[bytes]) -> ControlClient:
    deadline = time.monotonic() + 60.0
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit("daemon exited early")
        if sock.exists():
            # Bound a moment before it listens: refused meanwhile.
            with contextlib.suppress(OSError, DaemonUnavailable):
                return ControlClient.connect(f"unix:{sock}")
        time.sleep(0.1)
    raise SystemExit("daemon did not start")
