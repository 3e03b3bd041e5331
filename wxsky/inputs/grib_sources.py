"""Where GRIB2 model data comes from (issue 45): a file (read again when it changes), a
directory of files, one per forecast step, or an http(s) URL of one file, polled with
conditional requests, taking only the messages wxsky reads by byte range where the server
publishes a `.idx` inventory beside the file.

A source only fetches bytes; `wxsky.inputs.grib_decode` decodes them. Fetches block (the
daemon calls them on a worker thread) and raise GribError, one line naming the file or URL.
Nothing is read past MAX_GRIB_BYTES for one file or URL.
"""

from __future__ import annotations

import hashlib
import logging
import os
import stat
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from wxsky.errors import GribError
from wxsky.inputs.grib_decode import IDX_WANTED, IDX_WIND, MIN_LEVEL_HPA
from wxsky.inputs.grib_http import Answer, CacheEntry, DiskCache, Validators, get
from wxsky.weather.grib_idx import (
    ByteRange,
    IdxEntry,
    fewer_ranges,
    parse_ecmwf_index,
    parse_idx,
    wanted_ranges,
)

__all__ = [
    "MAX_GRIB_BYTES",
    "MAX_GRIB_DIR_BYTES",
    "DirGribSource",
    "FileGribSource",
    "GribBlob",
    "GribSource",
    "HttpGribSource",
    "open_grib_source",
]

log = logging.getLogger("wxsky.inputs.grib")

MAX_GRIB_BYTES = 1024**3  # one file or URL: a whole 0.25 degree GFS step is about 0.5 GB
MAX_GRIB_DIR_BYTES = 4 * 1024**3  # a directory's files together, all held at once
MAX_IDX_BYTES = 16 * 1024**2  # a GFS 0.25 degree inventory is about 60 kB
# Requests for one file's messages: the nearest are joined until no more than this are left.
MAX_RANGE_REQUESTS = 64
IndexParser = Callable[[str, str], list[IdxEntry]]
# Left out of a directory: inventories, hidden files, and files still being written.
_NOT_GRIB_SUFFIXES = (".idx", ".part", ".tmp")

_Key = tuple[int, int, int]  # (mtime_ns, size, inode): any of them changing is a new file


@dataclass(frozen=True)
class GribBlob:
    name: str  # the path or URL it came from
    data: bytes = field(repr=False)
    digest: str  # sha256 hex of data: the decoder's cache key

    @classmethod
    def of(cls, name: str, data: bytes) -> GribBlob:
        return cls(name, data, hashlib.sha256(data).hexdigest())

    @property
    def held(self) -> bool:
        """Unchanged since the caller last had its data, which is not sent again (`data`
        empty; `digest` says which): a directory of 0.25 degree steps is gigabytes, and the
        caller keeps what it decoded, not the bytes."""
        return not self.data

    def without_data(self) -> GribBlob:
        return GribBlob(self.name, b"", self.digest)


class GribSource(Protocol):
    name: str

    def fetch(self) -> list[GribBlob] | None:
        """The data, or None when nothing changed since the last fetch. Raises GribError."""
        ...

    def forget(self) -> None:
        """The next fetch returns the data even if unchanged (after the caller failed while
        handling it)."""
        ...

    def close(self) -> None:
        """Idempotent."""
        ...


def open_grib_source(
    spec: str,
    *,
    cache_dir: Path | None = None,
    cache_max_bytes: int = 2 * 1024**3,
    timeout_s: float = 30.0,
    byte_ranges: bool = True,
    fields: str = "all",
) -> GribSource:
    """A source for a config/CLI spec: an http(s):// URL of one GRIB2 file, a directory (one
    file per forecast step) or a file. `cache_dir` keeps a URL's last data on disk (bounded by
    `cache_max_bytes`); `byte_ranges` False always fetches a URL's whole file; `fields` which
    messages a URL's byte ranges take ("all" wxsky reads, or "wind": the wind and temperature
    profile alone)."""
    if spec.startswith(("http://", "https://")):
        cache = DiskCache(cache_dir, cache_max_bytes) if cache_dir is not None else None
        wanted = IDX_WIND if fields == "wind" else IDX_WANTED
        return HttpGribSource(
            spec, wanted=wanted, timeout_s=timeout_s, byte_ranges=byte_ranges, cache=cache
        )
    if "://" in spec:
        raise GribError(f"GRIB source {spec!r}: only files, directories and http(s) URLs")
    if not spec:
        raise GribError("GRIB source: an empty path")
    path = Path(spec)
    if spec.endswith("/") or path.is_dir():
        return DirGribSource(path)
    return FileGribSource(path)


# --- files and directories -----------------------------------------------------------------


def _stat(path: Path, name: str) -> os.stat_result:
    try:
        return os.stat(path)
    except FileNotFoundError:
        raise GribError(f"{name}: no such file") from None
    except OSError as exc:
        raise GribError(f"{name}: cannot stat: {exc.strerror or exc}") from None


def _key(st: os.stat_result) -> _Key:
    return (st.st_mtime_ns, st.st_size, st.st_ino)


def _read(path: Path, name: str, key: _Key) -> bytes:
    """The file's bytes, bounded; GribError when it changed while it was read (a writer
    rewriting it in place): it is read again at the next fetch."""
    if key[1] > MAX_GRIB_BYTES:
        raise GribError(
            f"{name}: {key[1]} bytes, over the {MAX_GRIB_BYTES}-byte limit for a GRIB file"
        )
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_GRIB_BYTES + 1)
            after = os.fstat(f.fileno())
    except FileNotFoundError:
        raise GribError(f"{name}: no such file") from None
    except OSError as exc:
        raise GribError(f"{name}: cannot read: {exc.strerror or exc}") from None
    if _key(after) != key or len(data) != key[1]:
        raise GribError(f"{name}: changed while it was read; it is read again next time")
    return data


class FileGribSource:
    """One file, read again whenever its mtime, size or inode changes (a tool that renames a
    new file over the old changes the inode even where mtime and size stay)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = str(path)
        self._seen: _Key | None = None

    def fetch(self) -> list[GribBlob] | None:
        st = _stat(self.path, self.name)
        key = _key(st)
        if key == self._seen:
            return None
        if not stat.S_ISREG(st.st_mode):
            raise GribError(f"{self.name}: not a regular file")
        data = _read(self.path, self.name, key)
        self._seen = key
        return [GribBlob.of(self.name, data)]

    def forget(self) -> None:
        self._seen = None

    def close(self) -> None:
        pass


class DirGribSource:
    """Every regular, non-hidden file of a directory but `.idx` inventories and `*.part` /
    `*.tmp` files (still being written), whatever their names: the messages' own dates say
    which forecast step each is. Only files that changed are read again; a fetch returns
    every file's blob, sorted by name, whenever one was added, changed or removed, those
    unchanged since the last fetch `held` (no data: the source keeps no file's bytes).
    After `forget`, every file is read again."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.name = str(path)
        self._files: dict[str, tuple[_Key, GribBlob]] = {}  # blobs without their data
        self._owed = True  # a fetch owes the caller the data (none handed out, or forgotten)

    def fetch(self) -> list[GribBlob] | None:
        try:
            items = sorted(os.scandir(self.path), key=lambda item: item.name)
        except FileNotFoundError:
            raise GribError(f"{self.name}: no such directory") from None
        except OSError as exc:
            raise GribError(f"{self.name}: cannot list: {exc.strerror or exc}") from None
        files: dict[str, tuple[_Key, GribBlob]] = {}
        out: list[GribBlob] = []
        changed = self._owed
        total_b = 0
        for item in items:
            if item.name.startswith(".") or item.name.lower().endswith(_NOT_GRIB_SUFFIXES):
                continue
            try:
                st = item.stat()  # a link to a file counts as the file
            except FileNotFoundError:
                continue  # renamed or removed since the listing: as if it were not there
            except OSError as exc:
                raise GribError(f"{item.path}: cannot stat: {exc.strerror or exc}") from None
            if not stat.S_ISREG(st.st_mode):
                continue
            key = _key(st)
            total_b += key[1]
            if total_b > MAX_GRIB_DIR_BYTES:
                raise GribError(
                    f"{self.name}: its files pass the {MAX_GRIB_DIR_BYTES}-byte limit for a "
                    f"GRIB directory at {item.name}"
                )
            old = self._files.get(item.path)
            if old is not None and old[0] == key and not self._owed:
                files[item.path] = old
                out.append(old[1])
                continue
            blob = GribBlob.of(item.path, _read(Path(item.path), item.path, key))
            files[item.path] = (key, blob.without_data())
            out.append(blob)
            changed = True
        if not files:
            self._files = {}
            raise GribError(
                f"{self.name}: no GRIB files in the directory (.idx, hidden, .part and .tmp "
                "files are left out)"
            )
        changed = changed or files.keys() != self._files.keys()
        self._files, self._owed = files, False
        return out if changed else None

    def forget(self) -> None:
        self._owed = True

    def close(self) -> None:
        pass


# --- http(s) ---------------------------------------------------------------------------------


class HttpGribSource:
    """One GRIB2 file at a URL. Where `URL.idx` answers, only the messages holding `wanted`
    fields are fetched, one Range request per run of neighbouring messages, and the polls ask
    for the .idx conditionally; otherwise the whole file is, conditionally. A poll that finds
    nothing changed costs one 304.

    With a `cache`, each download is kept on disk with its validators: a new source (a
    restarted daemon) revalidates the kept copy rather than downloading it again, and where
    its first fetch fails (the network is down) it returns the kept copy."""

    def __init__(
        self,
        url: str,
        *,
        wanted: tuple[tuple[str, str], ...],
        timeout_s: float = 30.0,
        byte_ranges: bool = True,
        cache: DiskCache | None = None,
    ) -> None:
        self.url = url
        self.name = url
        self.idx_url = url + ".idx"
        self._index_found: tuple[str, IndexParser] | None = None  # the index that answered
        self.wanted = wanted
        self.timeout_s = timeout_s
        self.byte_ranges = byte_ranges
        self.cache = cache
        # What of the file a download holds: a cached copy of another selection (the whole
        # file, or other fields) is not what a 304 to these validators vouches for.
        wanted_text = repr(sorted(wanted)).encode()
        self.selection = "ranges " + hashlib.sha256(wanted_text).hexdigest()[:16]
        if not byte_ranges:
            self.selection = "whole"
        self._validators: Validators | None = None  # sent with the next poll
        self._last_digest: str | None = None  # of the data last handed out
        self._first = True

    def fetch(self) -> list[GribBlob] | None:
        first, self._first = self._first, False
        kept = self._kept() if self._last_digest is None else None
        if kept is not None and self._validators is None and kept.selection == self.selection:
            self._validators = kept.validators
        try:
            got = self._download()
            if got is None:  # 304: unchanged since the data behind our validators
                if self._last_digest is not None:
                    return None
                if kept is not None and kept.validators == self._validators:
                    return self._hand_out(kept.data)
                self._validators = None  # that copy is gone (evicted): the data, whole
                got = self._download()
                if got is None:
                    raise GribError(f"{self.url}: HTTP 304 to a request that was not conditional")
        except GribError as exc:
            if not (first and kept is not None):
                raise
            age_h = (time.time() - kept.saved_utc_s) / 3600.0
            log.warning("%s; using the copy cached %.1f hours ago", exc, age_h)
            return self._hand_out(kept.data)
        data, validators = got
        self._validators = validators
        if self.cache is not None:
            self.cache.store(self.url, CacheEntry(data, validators, self.selection, time.time()))
        blob = GribBlob.of(self.url, data)
        if blob.digest == self._last_digest:
            return None  # a server without validators sent the same bytes again
        self._last_digest = blob.digest
        return [blob]

    def _kept(self) -> CacheEntry | None:
        return self.cache.load(self.url, MAX_GRIB_BYTES) if self.cache is not None else None

    def _hand_out(self, data: bytes) -> list[GribBlob]:
        blob = GribBlob.of(self.url, data)
        self._last_digest = blob.digest
        return [blob]

    def _download(self) -> tuple[bytes, Validators] | None:
        """The data and its validators, or None on a 304."""
        if self.byte_ranges:
            for index_url, parse in self._indexes():
                idx = self._get(index_url, self._conditional(index_url), MAX_IDX_BYTES)
                if idx.status == 304:
                    return None
                if idx.status == 200:
                    self._index_found = (index_url, parse)
                    text = idx.body.decode("utf-8", "replace")
                    entries = parse(text, index_url)
                    ranges = wanted_ranges(entries, self.wanted, min_hpa=MIN_LEVEL_HPA)
                    ranges = fewer_ranges(ranges, MAX_RANGE_REQUESTS)
                    if not ranges:
                        raise GribError(f"{index_url}: lists none of the fields wxsky reads")
                    return self._ranges(ranges), idx.validators(index_url)
                if not 400 <= idx.status < 500:  # a server in trouble, not a missing index
                    raise _failed(index_url, idx)
                log.debug("%s: HTTP %d", index_url, idx.status)
            log.debug("%s: no index; fetching the whole file", self.url)
        whole = self._get(self.url, self._conditional(self.url), MAX_GRIB_BYTES)
        if whole.status == 304:
            return None
        if whole.status != 200:
            raise _failed(self.url, whole)
        return whole.body, whole.validators(self.url)

    def _indexes(self) -> list[tuple[str, IndexParser]]:
        """Where the file's index may be, in the order to try: NOAA's `URL.idx` (wgrib2's
        inventory), then for a `.grib2` URL ECMWF open data's `.index` beside it (JSON
        lines); once one has answered, that one alone."""
        if self._index_found is not None:
            return [self._index_found]
        out: list[tuple[str, IndexParser]] = [(self.idx_url, parse_idx)]
        if self.url.endswith(".grib2"):
            out.append((self.url.removesuffix(".grib2") + ".index", parse_ecmwf_index))
        return out

    def _ranges(self, ranges: list[ByteRange]) -> bytes:
        parts: list[bytes] = []
        total_b = 0
        for first_b, last_b in ranges:
            spec = f"bytes={first_b}-{'' if last_b is None else last_b}"
            answer = self._get(self.url, {"Range": spec}, MAX_GRIB_BYTES)
            if answer.status == 200:
                return answer.body  # a server that ignores Range sends the whole file
            if answer.status != 206:
                raise _failed(self.url, answer)
            where = f"{self.url}: {spec}"
            _check_range(where, answer, first_b, last_b)
            # The .idx's offsets point at message starts: anything else is an inventory of
            # another version of the file (replaced between the two requests).
            if not answer.body.startswith(b"GRIB"):
                raise GribError(
                    f"{where}: not the start of a GRIB message; the file and its "
                    ".idx disagree (replaced meanwhile?)"
                )
            total_b += len(answer.body)
            if total_b > MAX_GRIB_BYTES:
                raise GribError(f"{self.url}: the ranges pass the {MAX_GRIB_BYTES}-byte limit")
            parts.append(answer.body)
        return b"".join(parts)

    def _get(self, url: str, headers: dict[str, str], limit_b: int) -> Answer:
        return get(url, headers, timeout_s=self.timeout_s, limit_b=limit_b)

    def _conditional(self, url: str) -> dict[str, str]:
        return self._validators.headers_for(url) if self._validators is not None else {}

    def forget(self) -> None:
        self._last_digest = None
        if self.cache is None:
            self._validators = None  # nothing kept to answer a 304 with: download again

    def close(self) -> None:
        pass


def _check_range(where: str, answer: Answer, first_b: int, last_b: int | None) -> None:
    """A 206 must be the range asked for, and whole: a short one is the file ending early
    (an inventory of a longer file) or the answer cut off."""
    content_range = (answer.headers.get("Content-Range") or "").strip()
    unit, _, rest = content_range.partition(" ")
    span, _, size = rest.partition("/")
    start, _, end = span.partition("-")
    if unit != "bytes" or not (_digits(start) and _digits(end)):
        raise GribError(f"{where}: 206 with Content-Range {content_range[:60]!r}")
    got_first, got_last = int(start), int(end)
    whole_to_end = last_b is None and (not _digits(size) or got_last == int(size) - 1)
    if got_first != first_b or not (got_last == last_b or whole_to_end):
        raise GribError(
            f"{where}: the server sent bytes {got_first}-{got_last}/{size or '*'} instead "
            "(a file shorter than its .idx says?)"
        )
    if len(answer.body) != got_last - got_first + 1:
        raise GribError(
            f"{where}: {len(answer.body)} bytes for a range of {got_last - got_first + 1}"
        )


def _failed(url: str, answer: Answer) -> GribError:
    return GribError(f"{url}: HTTP {answer.status} {answer.reason[:80]}")


def _digits(text: str) -> bool:
    return text.isascii() and text.isdigit()
