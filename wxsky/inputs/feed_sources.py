"""Where METAR feed bytes come from: a file (re-read when it changes), a stream such as
stdin (one report per line, as it arrives), or an HTTP(S) URL polled with conditional
requests and exponential back-off. A source only fetches bytes; parsing is the feeds
module's job.
"""

from __future__ import annotations

import asyncio
import contextlib
import email.utils
import gzip
import os
import threading
import urllib.error
import urllib.request
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import BinaryIO, Protocol

from wxsky import __version__
from wxsky.errors import FeedError, FeedUnavailable

MAX_FEED_BYTES = 64 * 1024 * 1024  # a whole-world AWC cache is ~1 MB; more is not a feed
GZIP_MAGIC = b"\x1f\x8b"


@dataclass(frozen=True)
class Fetched:
    data: bytes
    reference_utc: datetime  # when the feed says it was written (mtime, HTTP Date, arrival)
    format: str = "auto"  # a source that knows its format says so ("lines" for streams)


class FeedSource(Protocol):
    name: str

    async def fetch(self) -> Fetched | None:
        """New data, or None when nothing changed. Raises FeedError on failure."""
        ...

    def close(self) -> None: ...


def gunzip_if_needed(data: bytes, name: str) -> bytes:
    if not data.startswith(GZIP_MAGIC):
        return data
    try:
        return gzip.decompress(data)
    except (OSError, EOFError) as exc:
        raise FeedError(f"{name}: broken gzip data ({exc})") from None


def open_source(spec: str, *, timeout_s: float = 10.0) -> FeedSource:
    """A source for a config/CLI feed spec: "-" (stdin), an http(s):// URL, or a path."""
    if spec == "-":
        return StreamSource("stdin", _stdin())
    if spec.startswith(("http://", "https://")):
        return HttpSource(spec, timeout_s=timeout_s)
    if "://" in spec:
        raise FeedError(f"feed {spec!r}: only files, '-' (stdin) and http(s) URLs are supported")
    return FileSource(Path(spec))


def _stdin() -> BinaryIO:
    import sys

    return sys.stdin.buffer


class FileSource:
    """A file, read again whenever its size, mtime or inode changes (tools usually replace
    feed files by renaming a new one over the old, which changes the inode)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = str(path)
        self._seen: tuple[int, int, int] | None = None

    async def fetch(self) -> Fetched | None:
        return await asyncio.to_thread(self.fetch_now)

    def fetch_now(self) -> Fetched | None:
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            raise FeedUnavailable(f"{self.name}: no such file") from None
        except OSError as exc:
            raise FeedUnavailable(f"{self.name}: cannot stat: {exc.strerror or exc}") from None
        key = (st.st_mtime_ns, st.st_size, st.st_ino)
        if key == self._seen:
            return None
        if st.st_size > MAX_FEED_BYTES:
            raise FeedError(f"{self.name}: {st.st_size} bytes is too large for a METAR feed")
        try:
            data = self.path.read_bytes()
        except OSError as exc:
            raise FeedUnavailable(f"{self.name}: cannot read: {exc.strerror or exc}") from None
        self._seen = key
        mtime = datetime.fromtimestamp(st.st_mtime, tz=UTC)
        return Fetched(gunzip_if_needed(data, self.name), mtime)

    def close(self) -> None:
        pass


class StreamSource:
    """Lines from a binary stream (stdin, a pipe), read by a daemon thread so the event loop
    never blocks; each fetch returns the lines that arrived since the last one."""

    def __init__(self, name: str, stream: BinaryIO, max_line_bytes: int = 4096) -> None:
        self.name = name
        self._stream = stream
        self._max_line = max_line_bytes
        self._lines: list[bytes] = []
        self._lock = threading.Lock()
        self._eof = False
        self._thread = threading.Thread(target=self._read, name=f"wxsky-{name}", daemon=True)
        self._thread.start()

    @property
    def eof(self) -> bool:
        return self._eof and not self._lines

    def _read(self) -> None:
        with contextlib.suppress(OSError, ValueError):
            skipping = False  # inside an over-long line, whose rest is dropped
            for chunk in iter(lambda: self._stream.readline(self._max_line + 1), b""):
                ended = chunk.endswith(b"\n")
                if not skipping:
                    line = chunk if ended else chunk[: self._max_line] + b"\n"
                    with self._lock:
                        self._lines.append(line)
                skipping = not ended
        self._eof = True

    async def fetch(self) -> Fetched | None:
        with self._lock:
            lines, self._lines = self._lines, []
        if not lines:
            if self._eof:
                raise FeedUnavailable(f"{self.name}: end of input; keeping the last weather")
            return None
        return Fetched(b"".join(lines), datetime.now(UTC), format="lines")

    def close(self) -> None:
        pass  # the reader thread is a daemon thread blocked in readline; it dies with us


class HttpSource:
    """A URL polled with If-None-Match / If-Modified-Since, so an unchanged feed costs a
    304 and no parsing. Failures raise FeedError; the caller backs off."""

    def __init__(self, url: str, timeout_s: float = 10.0) -> None:
        self.url = url
        self.name = url
        self.timeout_s = timeout_s
        self._etag: str | None = None
        self._last_modified: str | None = None

    async def fetch(self) -> Fetched | None:
        return await asyncio.to_thread(self.fetch_now)

    def fetch_now(self) -> Fetched | None:
        headers = {"User-Agent": f"wxsky/{__version__}", "Accept-Encoding": "gzip"}
        if self._etag:
            headers["If-None-Match"] = self._etag
        if self._last_modified:
            headers["If-Modified-Since"] = self._last_modified
        request = urllib.request.Request(self.url, headers=headers)
        try:
            with urllib.request.urlopen(request, timeout=self.timeout_s) as response:
                data = response.read(MAX_FEED_BYTES + 1)
                etag = response.headers.get("ETag")
                modified = response.headers.get("Last-Modified")
                date = response.headers.get("Date")
        except urllib.error.HTTPError as exc:
            if exc.code == 304:
                return None
            raise FeedUnavailable(f"{self.url}: HTTP {exc.code} {exc.reason}") from None
        except urllib.error.URLError as exc:
            raise FeedUnavailable(f"{self.url}: {exc.reason}") from None
        except (TimeoutError, OSError) as exc:
            raise FeedUnavailable(f"{self.url}: {exc or type(exc).__name__}") from None
        if len(data) > MAX_FEED_BYTES:
            raise FeedError(f"{self.url}: more than {MAX_FEED_BYTES} bytes; not a METAR feed")
        self._etag, self._last_modified = etag, modified
        return Fetched(gunzip_if_needed(data, self.url), _http_date(date) or datetime.now(UTC))

    def close(self) -> None:
        pass


def _http_date(text: str | None) -> datetime | None:
    if not text:
        return None
    try:
        return email.utils.parsedate_to_datetime(text).astimezone(UTC)
    except (TypeError, ValueError):
        return None
