"""Where METAR feed bytes come from: a file (re-read when it changes), a stream such as
stdin (one report per line, as it arrives), or an HTTP(S) URL polled with conditional
requests and exponential back-off. A source only fetches bytes; parsing is the feeds
module's job.

Nothing is read past `MAX_FEED_BYTES`, as sent or as unpacked: gzip data (a `.gz` file, an
HTTP body with `Content-Encoding: gzip` or gzip magic) goes through the one bounded gunzip of
`weather.feeds`, and data over the limit is refused with `FeedTooLarge`. A file caught while
it is being written is not read but held back for `SETTLE_S` (`FeedChanging`).
"""

from __future__ import annotations

import asyncio
import contextlib
import email.utils
import os
import stat
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import BinaryIO, Protocol

from wxsky import __version__
from wxsky.errors import FeedChanging, FeedError, FeedTooLarge, FeedUnavailable
from wxsky.logs import clip
from wxsky.weather.feeds import GZIP_MAGIC, MAX_FEED_BYTES, gunzip, unfinished_last_line

__all__ = [
    "GZIP_MAGIC",
    "MAX_FEED_BYTES",
    "DirSource",
    "FeedSource",
    "Fetched",
    "FileSource",
    "HttpSource",
    "StreamSource",
    "gunzip_if_needed",
    "open_source",
]

# A file modified less than this long ago may be half-written (rewritten in place, a writer
# that paused between two writes): it is read once it has stood unchanged this long.
SETTLE_S = 0.5
# A file that never stands still (appended to all the time) is read anyway after this.
MAX_SETTLE_S = 5.0


@dataclass(frozen=True)
class Fetched:
    data: bytes
    reference_utc: datetime  # when the feed says it was written (mtime, HTTP Date, arrival)
    format: str = "auto"  # a source that knows its format says so ("lines" for streams)
    # Why a last line was left out (cut off mid-group and never finished), for the input to
    # warn about; None when the data is whole.
    dropped: str | None = None
    # A directory's files, each (name, bytes), parsed one by one (formats with a header, as
    # AWC's CSV, cannot be run together); `data` is then empty.
    files: tuple[tuple[str, bytes], ...] = ()


class FeedSource(Protocol):
    name: str

    async def fetch(self) -> Fetched | None:
        """New data, or None when nothing changed. Raises FeedError on failure."""
        ...

    def forget(self) -> None:
        """Forget what was fetched, so the next fetch returns the data even if unchanged
        (after the input failed while handling it)."""
        ...

    def close(self) -> None: ...


def gunzip_if_needed(data: bytes, name: str) -> bytes:
    """`data` unpacked if it is gzip, bounded by MAX_FEED_BYTES (FeedTooLarge past it); a
    damaged or cut-off stream is refused whole, so a half-downloaded feed is never taken."""
    if not data.startswith(GZIP_MAGIC):
        return data
    out, trouble = gunzip(data, name=name)
    if trouble is not None:
        raise FeedError(f"{name}: broken gzip data ({trouble})")
    return out


def open_source(spec: str, *, timeout_s: float = 10.0, settle_s: float = SETTLE_S) -> FeedSource:
    """A source for a config/CLI feed spec: "-" (stdin), an http(s):// URL, or a path.
    `settle_s` 0 reads a file at once however recently it was written (a one-shot command)."""
    if spec == "-":
        return StreamSource("stdin", _stdin())
    if spec.startswith(("http://", "https://")):
        return HttpSource(spec, timeout_s=timeout_s)
    if "://" in spec:
        raise FeedError(
            f"feed {spec!r}: only files, directories, '-' (stdin) and http(s) URLs are supported"
        )
    if Path(spec).is_dir():
        return DirSource(Path(spec))
    return FileSource(Path(spec), settle_s=settle_s)


def _stdin() -> BinaryIO:
    import sys

    return sys.stdin.buffer


class FileSource:
    """A file, read again whenever its size, mtime or inode changes (tools usually replace
    feed files by renaming a new one over the old, which changes the inode).

    Content it refuses (too large, a gzip bomb, broken gzip) counts as seen: it is not read
    again until it changes, and the input keeps saying it is bad. A file modified within
    `settle_s`, or that changes while it is read, is not marked seen but held back
    (`FeedChanging`), so half a file is never taken for the feed.
    """

    def __init__(
        self, path: Path, settle_s: float = SETTLE_S, max_settle_s: float = MAX_SETTLE_S
    ) -> None:
        self.path = path
        self.name = str(path)
        self.settle_s = settle_s
        self.max_settle_s = max_settle_s
        self._seen: tuple[int, int, int] | None = None
        self._held: tuple[int, int, int] | None = None  # the change last held back
        self._held_since: float | None = None  # monotonic time of the first hold

    async def fetch(self) -> Fetched | None:
        return await asyncio.to_thread(self.fetch_now)

    def fetch_now(self) -> Fetched | None:
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            self._seen = None  # the same file back again is news
            raise FeedUnavailable(f"{self.name}: no such file") from None
        except OSError as exc:
            self._seen = None
            raise FeedUnavailable(f"{self.name}: cannot stat: {exc.strerror or exc}") from None
        key = (st.st_mtime_ns, st.st_size, st.st_ino)
        if key == self._seen:
            return None
        if st.st_size > MAX_FEED_BYTES:
            self._seen = key
            raise FeedTooLarge(
                f"{self.name}: {st.st_size} bytes, over the {MAX_FEED_BYTES}-byte limit "
                "for a METAR feed"
            )
        self._hold_if_recent(st.st_mtime_ns, key)
        data = self._read(key)
        self._hold_if_unfinished(data, key)
        self._seen = key
        self._held = self._held_since = None
        mtime = datetime.fromtimestamp(st.st_mtime, tz=UTC)
        data, dropped = self._drop_cut_line(gunzip_if_needed(data, self.name))
        return Fetched(data, mtime, dropped=dropped)

    def _drop_cut_line(self, data: bytes) -> tuple[bytes, str | None]:
        """Held for `max_settle_s` and its last line still has no end: a line that is cut off
        in the middle of a group (`... 9999 OVC0`) is a report being written, never taken for
        one (it would read as a different report); the lines before it are. A last line that
        ends with a whole group is taken (a file written without a final newline)."""
        if self.settle_s <= 0 or data.endswith(b"\n"):
            return data, None
        cut = unfinished_last_line(data.decode("utf-8", "replace"))
        if cut is None:
            return data, None
        station, why = cut
        kept = data[: data.rfind(b"\n") + 1]
        message = (
            f"{self.name}: {station}: the last line ends mid-group ({clip(why, 80)}) and no "
            f"newline came for {self.max_settle_s:g} s; left out"
        )
        if not kept.strip():
            # Nothing else in the file: refused (as seen) with the reason, until it changes.
            raise FeedError(message)
        return kept, message

    def _hold_if_unfinished(self, data: bytes, key: tuple[int, int, int]) -> None:
        """Text whose last line has no end is held back for up to `max_settle_s` (a writer
        pausing longer than `settle_s` mid-file), then taken as it is: every feed format ends
        its lines with a newline, and half a line can read as a shorter report. A cut-off gzip
        stream needs no wait: it is refused, never misread, and read again once it changes."""
        if self.settle_s <= 0 or data.startswith(GZIP_MAGIC) or data.endswith(b"\n"):
            return
        why = "empty" if not data else "its last line has no end"
        self._hold(key, f"{self.name}: {why}, maybe not finished; reading it again shortly")

    def _hold(self, key: tuple[int, int, int], message: str) -> None:
        """Hold this change back (FeedChanging), unless it has been held `max_settle_s`."""
        now = time.monotonic()
        if self._held_since is None:
            self._held_since = now
        elif now - self._held_since >= self.max_settle_s:
            return
        self._held = key
        raise FeedChanging(message, self.settle_s)

    def _hold_if_recent(self, mtime_ns: int, key: tuple[int, int, int]) -> None:
        age_s = (time.time_ns() - mtime_ns) / 1e9
        # A change already held back once and unchanged since has stood still long enough,
        # even where the clock and the file system disagree about how recent it is.
        if not 0.0 <= age_s < self.settle_s or key == self._held:
            return
        self._hold(
            key, f"{self.name}: written {age_s:.2f} s ago, maybe not finished; reading it shortly"
        )

    def _read(self, key: tuple[int, int, int]) -> bytes:
        try:
            with open(self.path, "rb") as f:
                data = f.read(MAX_FEED_BYTES + 1)
                after = os.fstat(f.fileno())
        except FileNotFoundError:
            self._seen = None
            raise FeedUnavailable(f"{self.name}: no such file") from None
        except OSError as exc:
            self._seen = None
            raise FeedUnavailable(f"{self.name}: cannot read: {exc.strerror or exc}") from None
        if (after.st_mtime_ns, after.st_size, after.st_ino) != key or len(data) != key[1]:
            raise FeedChanging(
                f"{self.name}: changed while it was read; reading it again shortly",
                max(self.settle_s, 0.05),
            )
        return data

    def forget(self) -> None:
        self._seen = self._held = self._held_since = None

    def close(self) -> None:
        pass


class DirSource:
    """A directory of feed files, an archive to replay (NOAA's hourly cycle files `00Z.TXT`
    .. `23Z.TXT`, a day of AWC caches): every regular, non-hidden file in it, read again when
    any is added, changed or removed, each parsed on its own. Files ending `.part` or `.tmp`
    are being written and left out. The whole is bounded by `MAX_FEED_BYTES`, as one file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = str(path)
        self._seen: tuple[tuple[str, int, int], ...] | None = None

    async def fetch(self) -> Fetched | None:
        return await asyncio.to_thread(self.fetch_now)

    def _listing(self) -> list[tuple[Path, os.stat_result]]:
        try:
            names = sorted(os.listdir(self.path))
        except OSError as exc:
            self._seen = None
            raise FeedUnavailable(f"{self.name}: cannot list: {exc.strerror or exc}") from None
        out = []
        for name in names:
            if name.startswith(".") or name.endswith((".part", ".tmp")):
                continue
            with contextlib.suppress(OSError):
                st = os.stat(self.path / name)
                if stat.S_ISREG(st.st_mode):
                    out.append((self.path / name, st))
        return out

    def fetch_now(self) -> Fetched | None:
        listing = self._listing()
        key = tuple((p.name, st.st_mtime_ns, st.st_size) for p, st in listing)
        if key == self._seen:
            return None
        if not listing:
            self._seen = key
            raise FeedError(f"{self.name}: no feed files in the directory")
        total = sum(st.st_size for _, st in listing)
        if total > MAX_FEED_BYTES:
            self._seen = key
            raise FeedTooLarge(
                f"{self.name}: {total} bytes in {len(listing)} files, over the "
                f"{MAX_FEED_BYTES}-byte limit for a METAR feed"
            )
        files = []
        for path, _ in listing:
            try:
                data = path.read_bytes()
            except OSError as exc:
                raise FeedUnavailable(f"{path}: cannot read: {exc.strerror or exc}") from None
            files.append((str(path), gunzip_if_needed(data, str(path))))
        self._seen = key
        newest = max(st.st_mtime for _, st in listing)
        return Fetched(b"", datetime.fromtimestamp(newest, tz=UTC), files=tuple(files))

    def forget(self) -> None:
        self._seen = None

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
        self._pending_bytes = 0
        self._drained = threading.Condition()
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
                    with self._drained:
                        # A writer far ahead of the polls (a whole file piped in, gzip data)
                        # waits in the pipe rather than in our memory.
                        while self._pending_bytes >= MAX_FEED_BYTES:
                            self._drained.wait()
                        self._lines.append(line)
                        self._pending_bytes += len(line)
                skipping = not ended
        self._eof = True

    async def fetch(self) -> Fetched | None:
        with self._drained:
            lines, self._lines = self._lines, []
            self._pending_bytes = 0
            self._drained.notify()
        if not lines:
            if self._eof:
                raise FeedUnavailable(f"{self.name}: end of input; keeping the last weather")
            return None
        return Fetched(b"".join(lines), datetime.now(UTC), format="lines")

    def forget(self) -> None:
        pass  # lines once fetched are gone; the next ones still come

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
                length = (response.headers.get("Content-Length") or "").strip()
                if length.isdigit() and int(length) > MAX_FEED_BYTES:
                    raise self._too_large(f"Content-Length {length}")
                data = response.read(MAX_FEED_BYTES + 1)
                encoding = (response.headers.get("Content-Encoding") or "identity").strip()
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
            raise self._too_large("the body")
        encoding = encoding.lower()
        if encoding in ("gzip", "x-gzip"):
            if not data.startswith(GZIP_MAGIC):
                raise FeedError(f"{self.url}: Content-Encoding gzip, but the body is not gzip")
        elif encoding != "identity":
            raise FeedError(
                f"{self.url}: Content-Encoding {clip(encoding, 40)!r} is not supported "
                "(wxsky asks for gzip only)"
            )
        # Unpacked before the validators are kept, so refused content is fetched whole again.
        unpacked = gunzip_if_needed(data, self.url)
        self._etag, self._last_modified = etag, modified
        return Fetched(unpacked, _http_date(date) or datetime.now(UTC))

    def _too_large(self, what: str) -> FeedTooLarge:
        return FeedTooLarge(
            f"{self.url}: {what} over the {MAX_FEED_BYTES}-byte limit; not a METAR feed"
        )

    def forget(self) -> None:
        self._etag = self._last_modified = None

    def close(self) -> None:
        pass


def _http_date(text: str | None) -> datetime | None:
    if not text:
        return None
    try:
        return email.utils.parsedate_to_datetime(text).astimezone(UTC)
    except (TypeError, ValueError, OverflowError):  # OverflowError: year 1 east of UTC
        return None
