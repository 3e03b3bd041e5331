"""The trace: one JSON object per line per event (`--trace FILE` on `run` and `bench`), so the
ring's rebuild policy can be checked from outside the daemon.

Every line has `frame` (the published frame number), `event` and `camera_m` ([x, y, z] in the
ring's world frame: east, north, up metres around the observer); the ring schedule's events
(`ring_rebuild_start` with `reason` and `centre_m`, `impostor_rendered` with `index`,
`ring_rebuild_done`, `crossfade_start` with `fade_s`, `crossfade_done`, `ring_rebuild_failed`
with `error`, `ring_rebuild_cancelled` at shutdown) add their own fields. Lines are flushed per
frame, so a reader sees them while the daemon runs.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from wxsky.engine.ring_schedule import RingEvent
from wxsky.errors import ConfigError


class TraceWriter:
    def __init__(self, path: Path) -> None:
        try:
            self._file: IO[str] | None = path.open("w", encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"--trace {path}: cannot write it ({exc.strerror})") from None
        self.path = path
        self.lines = 0

    def write(self, frame: int, event: str, camera_m: Iterable[float], **fields: Any) -> None:
        if self._file is None:
            return
        record = {"frame": frame, "event": event, "camera_m": [float(v) for v in camera_m]}
        record.update(fields)
        self._file.write(json.dumps(record, separators=(",", ":")) + "\n")
        self.lines += 1

    def write_events(
        self, frame: int, camera_m: Iterable[float], events: Iterable[RingEvent]
    ) -> None:
        """A frame's ring events, then one flush."""
        camera = list(camera_m)
        wrote = False
        for e in events:
            self.write(frame, e.event, camera, **e.fields)
            wrote = True
        if wrote and self._file is not None:
            self._file.flush()

    def close(self) -> None:
        """Idempotent."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> TraceWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
