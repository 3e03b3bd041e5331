"""HTTP requests and the disk cache behind `wxsky.inputs.grib_sources`' URL source (issue 45).

`get` makes one blocking request and gives back whatever status came (the source decides
what a 304, a 404 or a 206 means), the body bounded; anything that is not an answer (refused,
timed out, cut off) is a GribError, one line naming the URL.

`DiskCache` keeps each URL's last bytes and their validators in one file under a folder, so
a daemon restarted while the network is down still has model data, and a restarted one with
the network up revalidates (a 304) instead of downloading again. Files are written to a
temporary name and renamed, so a reader never sees half of one; the folder is kept under a
byte budget by removing the least recently used entries.
"""

from __future__ import annotations

import contextlib
import hashlib
import http.client
import json
import logging
import os
import secrets
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from email.message import Message
from pathlib import Path

from wxsky import __version__
from wxsky.errors import GribError
from wxsky.logs import clip

__all__ = ["USER_AGENT", "Answer", "CacheEntry", "DiskCache", "Validators", "get"]

log = logging.getLogger("wxsky.inputs.grib")

USER_AGENT = f"wxsky/{__version__}"
CACHE_SUFFIX = ".grib-cache"
MAX_CACHE_HEADER_B = 64 * 1024  # the JSON line in front of the bytes
# A temporary file this old was left by a process that died while writing it.
STALE_TEMP_S = 3600.0


@dataclass(frozen=True)
class Validators:
    """What a server said identifies the version it sent, for the next conditional request."""

    url: str  # the URL they came with (the file, or its .idx): they mean nothing for another
    etag: str | None = None
    last_modified: str | None = None

    def headers_for(self, url: str) -> dict[str, str]:
        if url != self.url:
            return {}
        headers = {}
        if self.etag:
            headers["If-None-Match"] = self.etag
        if self.last_modified:
            headers["If-Modified-Since"] = self.last_modified
        return headers


@dataclass(frozen=True)
class Answer:
    status: int
    reason: str
    headers: Message
    body: bytes = field(repr=False)  # empty unless 2xx

    def validators(self, url: str) -> Validators:
        return Validators(url, self.headers.get("ETag"), self.headers.get("Last-Modified"))


def get(url: str, headers: dict[str, str], *, timeout_s: float, limit_b: int) -> Answer:
    """GET `url`. Every HTTP status comes back as an Answer; a body over `limit_b` bytes,
    as declared or as sent, and every failure to get an answer raise GribError."""
    request = urllib.request.Request(url, headers={"User-Agent": USER_AGENT, **headers})
    try:
        with urllib.request.urlopen(request, timeout=timeout_s) as response:
            length = (response.headers.get("Content-Length") or "").strip()
            if length.isascii() and length.isdigit() and int(length) > limit_b:
                raise GribError(f"{url}: Content-Length {length}, over the {limit_b}-byte limit")
            body = response.read(limit_b + 1)
            answer = Answer(response.status, str(response.reason), response.headers, body)
    except urllib.error.HTTPError as exc:  # 304 and every 4xx and 5xx
        exc.close()  # its body (an error page) is not read: the connection goes now
        return Answer(exc.code, str(exc.reason), exc.headers, b"")
    except urllib.error.URLError as exc:
        raise GribError(f"{url}: {clip(exc.reason, 200)}") from None
    # OSError: refused, reset, timed out; HTTPException: a cut-off body, a garbled answer;
    # ValueError: a URL urllib cannot even send.
    except (OSError, http.client.HTTPException, ValueError) as exc:
        raise GribError(f"{url}: {clip(exc or type(exc).__name__, 200)}") from None
    if len(answer.body) > limit_b:
        raise GribError(f"{url}: the body is over the {limit_b}-byte limit")
    return answer


@dataclass(frozen=True)
class CacheEntry:
    data: bytes = field(repr=False)
    validators: Validators | None
    # What of the file the bytes are (the whole file, or which messages by range): validators
    # of a different selection do not vouch for these bytes.
    selection: str
    saved_utc_s: float = 0.0  # when it was written (seconds since the epoch), for the log


class DiskCache:
    """One file per URL under `folder`, named by a hash of the URL: a JSON line (the URL, the
    data's sha256, validators, selection), then the data. Bounded to `max_bytes` in all."""

    def __init__(self, folder: Path, max_bytes: int) -> None:
        self.folder = folder
        self.max_bytes = max_bytes

    def path_for(self, url: str) -> Path:
        return self.folder / (hashlib.sha256(url.encode()).hexdigest()[:32] + CACHE_SUFFIX)

    def load(self, url: str, limit_b: int) -> CacheEntry | None:
        """The entry for `url`, or None when there is none or it is damaged (then it is as if
        there were none: the next download replaces it). Loading counts as a use."""
        path = self.path_for(url)
        try:
            with open(path, "rb") as f:
                header = json.loads(f.readline(MAX_CACHE_HEADER_B))
                data = f.read(limit_b + 1)
            os.utime(path)  # used: the last to be evicted
            ok = header["url"] == url and hashlib.sha256(data).hexdigest() == header["sha256"]
            v = header["validators"]
            validators = None if v is None else Validators(v[0], _text(v[1]), _text(v[2]))
            entry = CacheEntry(data, validators, str(header["selection"]), float(header["saved"]))
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
            log.warning("%s: cached copy %s unreadable, ignored: %s", url, path, clip(exc, 120))
            return None
        if not ok:
            log.warning("%s: cached copy %s is damaged, ignored", url, path)
            return None
        return entry

    def store(self, url: str, entry: CacheEntry) -> None:
        """Write `url`'s entry (atomically), then evict. A failure is logged, never raised: the
        data is good whether or not it could be kept."""
        path = self.path_for(url)
        v = entry.validators
        header = {
            "url": url,
            "sha256": hashlib.sha256(entry.data).hexdigest(),
            "validators": None if v is None else [v.url, v.etag, v.last_modified],
            "selection": entry.selection,
            "saved": time.time(),
        }
        temp = self.folder / f".{path.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            with open(temp, "wb") as f:
                f.write(json.dumps(header).encode() + b"\n")
                f.write(entry.data)
            os.replace(temp, path)
        except OSError as exc:
            with contextlib.suppress(OSError):
                temp.unlink()
            log.warning("%s: could not cache it in %s: %s", url, self.folder, clip(exc, 120))
            return
        self.evict(keep=path)

    def evict(self, keep: Path) -> None:
        """Remove the least recently used entries (never `keep`) until the folder's entries
        total at most `max_bytes`; and temporary files a dead writer left behind."""
        entries: list[tuple[int, int, Path]] = []  # (mtime_ns, size, path)
        now_s = time.time()
        try:
            names = list(os.scandir(self.folder))
        except OSError:
            return
        for item in names:
            with contextlib.suppress(OSError):  # gone meanwhile: another process evicted it
                st = item.stat(follow_symlinks=False)
                if item.name.endswith(".tmp") and now_s - st.st_mtime > STALE_TEMP_S:
                    os.unlink(item.path)
                elif item.name.endswith(CACHE_SUFFIX) and item.is_file(follow_symlinks=False):
                    entries.append((st.st_mtime_ns, st.st_size, Path(item.path)))
        total_b = sum(size for _, size, _ in entries)
        for _, size, path in sorted(entries):
            if total_b <= self.max_bytes:
                break
            if path == keep:
                continue
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
                log.info("evicted %s from the GRIB cache (%d bytes)", path.name, size)
            total_b -= size


def _text(value: object) -> str | None:
    """A validator read back from a cache file: a string or nothing (TypeError otherwise)."""
    if value is None or isinstance(value, str):
        return value
    raise TypeError(f"a validator of type {type(value).__name__}")
