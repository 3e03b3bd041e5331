"""The physical atmosphere's tables kept on disk, so a process need not make them again.

A set of tables (`wxsky.scene.atmosphere.build_luts`) costs 0.3 to 0.8 s of numpy and depends
only on its quantised key and the code that made it. A daemon starting, every `wxsky snapshot`
and every sun step of a restarted daemon would make the same sets again: here they are read
back instead (a few milliseconds), exactly as made (`.npz`, float64).

Where: `$WXSKY_CACHE_DIR/atmosphere/`, else `$XDG_CACHE_HOME/wxsky/atmosphere/`, else
`~/.cache/wxsky/atmosphere/`; `WXSKY_CACHE_DIR=` (empty) turns the cache off. A file is named
by its key and a digest of the code that made it (`CODE_FILES` and numpy's version), so a
changed atmosphere never reads an old table. At most `MAX_BYTES` are kept: the least recently
used files go first. A file that cannot be read (cut short, another version's layout) is made
anew and written over, with one log line; a folder that cannot be written turns the cache off
for the process, with one log line. Writes go to a temporary name and are renamed into place,
so processes sharing the folder never read half a file.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import logging
import os
import threading
from pathlib import Path

from wxsky.scene import atmosphere as atm

log = logging.getLogger(__name__)

CACHE_ENV = "WXSKY_CACHE_DIR"
MAX_BYTES = 128 * 2**20  # some 135 sets of 0.94 MiB
# The sources the tables' values come from (relative to the package): the digest of these
# names the files. tests/test_lut_cache.py checks that it lists every wxsky module the
# atmosphere imports.
CODE_FILES = ("scene/atmosphere.py", "schema/kinds.py")

_lock = threading.Lock()
_off = False  # set when the folder cannot be written: one log line, then no more tries
_digest: str | None = None


def cache_dir() -> Path | None:
    """The folder the tables are kept in, or None where the cache is off."""
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return Path(chosen) / "atmosphere" if chosen else None
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "wxsky" / "atmosphere"


def code_digest() -> str:
    """16 hex digits naming the code that makes the tables."""
    global _digest
    if _digest is None:
        h = hashlib.sha256(importlib.metadata.version("numpy").encode())
        package = Path(atm.__file__).resolve().parents[1]
        for rel in CODE_FILES:
            h.update(rel.encode())
            h.update((package / rel).read_bytes())
        _digest = h.hexdigest()[:16]
    return _digest


def file_for(folder: Path, key: atm.AtmosphereKey) -> Path:
    return folder / (
        f"{code_digest()}-s{key.sun_elevation_q}-v{key.visibility_q}-h{key.humidity_q}"
        f"-e{key.eye_alt_m:.3f}.npz"
    )


def cached_luts(key: atm.AtmosphereKey) -> atm.AtmosphereLuts:
    """The tables for `key`: read back when kept, else made (`build_luts`) and kept."""
    folder = None if _off else cache_dir()
    if folder is None:
        return atm.build_luts(key)
    path = file_for(folder, key)
    try:
        luts = atm.luts_from_bytes(key, path.read_bytes())
    except (FileNotFoundError, NotADirectoryError):
        pass  # not kept yet (the write below says why where the folder is no folder)
    except (OSError, ValueError) as exc:
        log.warning("atmosphere cache: %s unreadable (%s); making it anew", path, exc)
    else:
        with contextlib.suppress(OSError):
            os.utime(path)  # recently used: the last to be dropped
        return luts
    luts = atm.build_luts(key)
    _keep(folder, path, luts)
    return luts


def _keep(folder: Path, path: Path, luts: atm.AtmosphereLuts) -> None:
    global _off
    part = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.part")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        part.write_bytes(atm.luts_to_bytes(luts))
        os.replace(part, path)
    except OSError as exc:
        with _lock:
            if not _off:
                log.warning("atmosphere cache off for this process: %s: %s", folder, exc)
            _off = True
        with contextlib.suppress(OSError):
            part.unlink()
        return
    _trim(folder)


def _trim(folder: Path, max_bytes: int = MAX_BYTES) -> None:
    """Drop the least recently used files until the folder holds at most max_bytes."""
    try:
        files = []
        for entry in os.scandir(folder):
            if entry.name.endswith(".npz"):
                st = entry.stat()
                files.append((st.st_mtime, st.st_size, entry.path))
    except OSError:
        return
    total = sum(size for _, size, _ in files)
    for _, size, name in sorted(files):
        if total <= max_bytes:
            break
        try:
            os.unlink(name)
        except OSError:
            continue  # another process dropped it first
        total -= size
