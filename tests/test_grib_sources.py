"""GRIB2 sources (issue 45): the real GFS file served over real HTTP on loopback, with an
`.idx` inventory, Range requests and ETags, by a server that counts what it sends; files and
directories on disk; the .idx parser and range selection. No mocks: what a fetch returns is
decoded by the real decoder and compared with the whole file's fields."""

from __future__ import annotations

import contextlib
import hashlib
import http.server
import itertools
import os
import re
import shutil
import socket
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from wxsky.errors import GribError
from wxsky.inputs.grib_decode import IDX_WANTED, MIN_LEVEL_HPA, Window, decode, inventory
from wxsky.inputs.grib_sources import (
    MAX_GRIB_BYTES,
    MAX_RANGE_REQUESTS,
    DirGribSource,
    FileGribSource,
    GribBlob,
    HttpGribSource,
    open_grib_source,
)
from wxsky.weather.grib_idx import (
    IdxEntry,
    fewer_ranges,
    parse_ecmwf_index,
    parse_idx,
    wanted_ranges,
)
from wxsky.weather.model_fields import ModelField, merge_steps
from wxsky.weather.model_profile import profile_at

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "data" / "grib" / "gfs.t12z.pgrbf120.2p5deg.grib2"  # ../shared's, copied
WINDOW = Window(21.3, -157.9)  # Honolulu: a small window keeps the decodes fast
TIMEOUT_S = 5.0  # only so a hang fails instead of waiting forever
# u and v on 10..1000 hPa (the fixture's README), of which wxsky reads 1000..100 hPa
PRESSURE_LEVELS_READ = 21
VALID = datetime(2011, 1, 15, 12, tzinfo=UTC)  # the fixture's one step


@pytest.fixture(scope="module")
def grib() -> bytes:
    if not FIXTURE.exists():  # ../shared is absent in a fresh clone
        pytest.skip(f"no GRIB fixture at {FIXTURE}")
    return FIXTURE.read_bytes()


@pytest.fixture(scope="module")
def whole_fields(grib: bytes) -> list[ModelField]:
    return decode(grib, "whole", WINDOW)


def _by_key(fields: list[ModelField]) -> dict[tuple[object, ...], ModelField]:
    out: dict[tuple[object, ...], ModelField] = {
        (f.name, f.level_type, f.level, f.valid_utc): f for f in fields
    }
    assert len(out) == len(fields), "a field decoded twice"
    return out


def assert_same_fields(got: list[ModelField], want: list[ModelField]) -> None:
    g, w = _by_key(got), _by_key(want)
    assert g.keys() == w.keys(), sorted(map(str, g.keys() ^ w.keys()))
    for key, f in w.items():
        assert np.array_equal(g[key].values, f.values, equal_nan=True), key
        assert np.array_equal(g[key].grid.lats_deg, f.grid.lats_deg), key
        assert np.array_equal(g[key].grid.lons_deg, f.grid.lons_deg), key


def decoded(blobs: list[GribBlob] | None) -> list[ModelField]:
    assert blobs is not None
    out: list[ModelField] = []
    for b in blobs:
        assert b.digest == hashlib.sha256(b.data).hexdigest()
        out += decode(b.data, b.name, WINDOW)
    return out


def one_line_error(excinfo: pytest.ExceptionInfo[GribError], *names: str) -> str:
    text = str(excinfo.value)
    assert "\n" not in text and "\r" not in text, text
    for name in names:
        assert name in text, text
    return text


# --- a real HTTP server on loopback ------------------------------------------------------------


@dataclass
class Served:
    """What the server publishes (path -> bytes) and what it saw and sent."""

    files: dict[str, bytes] = field(default_factory=dict)
    honour_range: bool = True
    requests: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    bytes_sent: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def publish(self, path: str, data: bytes, idx: bool = True) -> None:
        self.files[path] = data
        if idx:
            self.files[path + ".idx"] = inventory(data).encode()
        else:
            self.files.pop(path + ".idx", None)

    def reset_counts(self) -> None:
        with self.lock:
            self.requests.clear()
            self.bytes_sent = 0

    def paths(self) -> list[str]:
        return [p for p, _ in self.requests]


NOT_FOUND = b"no such file\n"
_RANGE = re.compile(r"bytes=(\d+)-(\d*)")


def _handler(served: Served) -> type[http.server.BaseHTTPRequestHandler]:
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self) -> None:
            with served.lock:
                served.requests.append((self.path, dict(self.headers)))
            body = served.files.get(self.path)
            if body is None:
                self._answer(404, NOT_FOUND)
                return
            etag = f'"{hashlib.sha256(body).hexdigest()[:16]}"'
            if self.headers.get("If-None-Match") == etag:
                self._answer(304, b"", etag=etag)
                return
            m = _RANGE.fullmatch(self.headers.get("Range") or "")
            if m is None or not served.honour_range:
                self._answer(200, body, etag=etag)
                return
            first, last = int(m.group(1)), int(m.group(2) or len(body) - 1)
            if first >= len(body):
                self._answer(416, b"", extra={"Content-Range": f"bytes */{len(body)}"})
                return
            last = min(last, len(body) - 1)  # a range past the end is cut, as servers do
            content_range = f"bytes {first}-{last}/{len(body)}"
            self._answer(
                206, body[first : last + 1], etag=etag, extra={"Content-Range": content_range}
            )

        def _answer(
            self,
            status: int,
            body: bytes,
            etag: str | None = None,
            extra: dict[str, str] | None = None,
        ) -> None:
            # Counted before anything goes: the client may act on the status line alone (a 404
            # sends it on to the next URL) and the test read the count before this thread got
            # back from writing the headers, let alone the body.
            with served.lock:
                served.bytes_sent += len(body)
            self.send_response(status)
            if etag:
                self.send_header("ETag", etag)
            for k, v in (extra or {}).items():
                self.send_header(k, v)
            if status != 304:
                self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            with contextlib.suppress(ConnectionError):
                self.wfile.write(body)

        def log_message(self, *args: object) -> None:
            pass

    return Handler


class GribServer:
    def __init__(self, served: Served) -> None:
        self.served = served
        self.port = 0
        self.httpd: http.server.ThreadingHTTPServer | None = None
        self.start()

    def start(self) -> None:
        """Serve on 127.0.0.1; after a stop, on the same port again (the same URLs)."""
        self.httpd = http.server.ThreadingHTTPServer(
            ("127.0.0.1", self.port), _handler(self.served)
        )
        self.port = self.httpd.server_address[1]
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()

    def stop(self) -> None:
        if self.httpd is not None:
            self.httpd.shutdown()
            self.httpd.server_close()
            self.httpd = None

    def url(self, path: str) -> str:
        return f"http://127.0.0.1:{self.port}{path}"


@pytest.fixture
def server(grib: bytes) -> Iterator[GribServer]:
    served = Served()
    served.publish("/gfs.grib2", grib)
    s = GribServer(served)
    yield s
    s.stop()


def http_source(
    url: str,
    *,
    cache_dir: Path | None = None,
    cache_max_bytes: int = 2 * 1024**3,
    timeout_s: float = TIMEOUT_S,
    byte_ranges: bool = True,
) -> HttpGribSource:
    src = open_grib_source(
        url,
        cache_dir=cache_dir,
        cache_max_bytes=cache_max_bytes,
        timeout_s=timeout_s,
        byte_ranges=byte_ranges,
    )
    assert isinstance(src, HttpGribSource)
    return src


# --- HTTP: byte ranges --------------------------------------------------------------------------


def test_byte_ranges_fetch_only_the_wanted_messages_and_decode_the_same(
    server: GribServer, grib: bytes, whole_fields: list[ModelField]
) -> None:
    src = http_source(server.url("/gfs.grib2"))
    blobs = src.fetch()
    assert blobs is not None and len(blobs) == 1 and blobs[0].name == src.url
    served = server.served
    ranges = wanted_ranges(parse_idx(inventory(grib), "idx"), IDX_WANTED, MIN_LEVEL_HPA)
    # One request for the .idx, then one per merged range, each with a Range header; the
    # nearest joined until there are no more than MAX_RANGE_REQUESTS (servers count them).
    requests = min(len(ranges), MAX_RANGE_REQUESTS)
    assert served.paths() == ["/gfs.grib2.idx"] + ["/gfs.grib2"] * requests
    assert all("Range" in h for _, h in served.requests[1:])
    assert all(h["User-Agent"].startswith("wxsky/") for _, h in served.requests)
    # About half of this small file is fields wxsky reads (a 0.25 degree file: far less)
    assert served.bytes_sent < 0.6 * len(grib)
    assert len(blobs[0].data) < 0.6 * len(grib)
    got = decoded(blobs)
    assert_same_fields(got, whole_fields)
    # NCEP packs each u/v pair in one message: both must survive the ranges.
    levels = {n: {f.level for f in got if f.name == n and f.level_type == "isobaric"} for n in "uv"}
    assert levels["u"] == levels["v"] and len(levels["u"]) == PRESSURE_LEVELS_READ


def test_a_second_poll_is_one_conditional_request_answered_304(server: GribServer) -> None:
    src = http_source(server.url("/gfs.grib2"))
    assert src.fetch() is not None
    server.served.reset_counts()
    assert src.fetch() is None
    assert server.served.paths() == ["/gfs.grib2.idx"]
    assert server.served.requests[0][1]["If-None-Match"].startswith('"')
    assert server.served.bytes_sent == 0
    src.forget()  # the caller lost what it had: the data again, though unchanged
    again = src.fetch()
    assert again is not None and len(again) == 1


def test_a_changed_file_and_idx_are_fetched_again(server: GribServer, grib: bytes) -> None:
    src = http_source(server.url("/gfs.grib2"))
    first = src.fetch()
    # The file republished cut before its 150th field (and a new .idx).
    cut_b = parse_idx(inventory(grib), "idx")[150].offset_b
    server.served.publish("/gfs.grib2", grib[:cut_b])
    second = src.fetch()
    assert first is not None and second is not None
    assert second[0].digest != first[0].digest
    names = {f.name for f in decoded(second)}
    assert "u" in names and "tcc" not in names  # the cloud decks were past the cut
    assert src.fetch() is None


def test_without_an_idx_the_whole_file_comes_and_decodes_the_same(
    server: GribServer, grib: bytes, whole_fields: list[ModelField]
) -> None:
    server.served.publish("/gfs.grib2", grib, idx=False)
    src = http_source(server.url("/gfs.grib2"))
    blobs = src.fetch()
    assert blobs is not None and blobs[0].data == grib
    # NOAA's .idx, then ECMWF's .index beside a .grib2, then the file
    assert server.served.paths() == ["/gfs.grib2.idx", "/gfs.index", "/gfs.grib2"]
    assert "Range" not in server.served.requests[2][1]
    assert_same_fields(decoded(blobs), whole_fields)
    server.served.reset_counts()
    assert src.fetch() is None  # a 304 on the file itself
    assert server.served.requests[-1][1]["If-None-Match"].startswith('"')
    assert server.served.bytes_sent == 2 * len(NOT_FOUND)  # the indexes' 404s, nothing else


def test_byte_ranges_off_fetches_the_whole_file(server: GribServer, grib: bytes) -> None:
    src = http_source(server.url("/gfs.grib2"), byte_ranges=False)
    blobs = src.fetch()
    assert blobs is not None and blobs[0].data == grib
    assert server.served.paths() == ["/gfs.grib2"]


def test_a_server_that_ignores_range_sends_the_whole_file(
    server: GribServer, grib: bytes, whole_fields: list[ModelField]
) -> None:
    server.served.honour_range = False
    src = http_source(server.url("/gfs.grib2"))
    blobs = src.fetch()
    assert blobs is not None and blobs[0].data == grib
    assert server.served.paths() == ["/gfs.grib2.idx", "/gfs.grib2"]  # no second range asked
    assert_same_fields(decoded(blobs), whole_fields)


def test_a_short_range_is_an_error_naming_the_url(server: GribServer, grib: bytes) -> None:
    # An inventory of the whole file in front of a file cut short: the last ranges cannot come.
    server.served.files["/gfs.grib2"] = grib[: len(grib) // 2 + 1234]
    src = http_source(server.url("/gfs.grib2"))
    with pytest.raises(GribError) as e:
        src.fetch()
    one_line_error(e, src.url)


def test_a_malformed_idx_is_an_error_naming_it_and_the_line(server: GribServer) -> None:
    server.served.files["/gfs.grib2.idx"] = b"1:0:d=2011011012:HGT:10 mb:anl:\n2:oops:d=1:TMP\n"
    src = http_source(server.url("/gfs.grib2"))
    with pytest.raises(GribError) as e:
        src.fetch()
    one_line_error(e, src.url + ".idx: line 2")


def test_http_errors_are_one_line_errors_naming_the_url(server: GribServer) -> None:
    url = server.url("/missing.grib2")
    with pytest.raises(GribError) as e:
        http_source(url).fetch()
    assert "HTTP 404" in one_line_error(e, url)
    server.stop()
    with pytest.raises(GribError) as e:
        http_source(server.url("/gfs.grib2")).fetch()
    assert "refused" in one_line_error(e, server.url("/gfs.grib2.idx"))


def test_a_server_that_never_answers_times_out() -> None:
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", 0))
        listener.listen(1)  # accepts the connection, never answers
        url = f"http://127.0.0.1:{listener.getsockname()[1]}/slow.grib2"
        with pytest.raises(GribError) as e:
            http_source(url, byte_ranges=False, timeout_s=0.3).fetch()
        assert "timed out" in one_line_error(e, url)


# --- HTTP: the disk cache ----------------------------------------------------------------------


def test_a_restarted_source_with_the_server_gone_returns_the_cached_blob(
    server: GribServer, tmp_path: Path, whole_fields: list[ModelField]
) -> None:
    url = server.url("/gfs.grib2")
    first = http_source(url, cache_dir=tmp_path).fetch()
    assert first is not None
    server.stop()
    restarted = http_source(url, cache_dir=tmp_path)
    kept = restarted.fetch()
    assert kept is not None and kept[0].digest == first[0].digest
    assert_same_fields(decoded(kept), whole_fields)
    with pytest.raises(GribError):  # only a first fetch falls back on the cache
        restarted.fetch()
    # The server back (same port, same URLs): the kept copy is revalidated, not downloaded.
    server.start()
    server.served.reset_counts()
    assert restarted.fetch() is None
    assert server.served.paths() == ["/gfs.grib2.idx"] and server.served.bytes_sent == 0
    # A third start with the server up: the kept copy again, for one 304.
    server.served.reset_counts()
    third = http_source(url, cache_dir=tmp_path).fetch()
    assert third is not None and third[0].digest == first[0].digest
    assert server.served.paths() == ["/gfs.grib2.idx"] and server.served.bytes_sent == 0


def test_a_damaged_cache_file_is_not_used(server: GribServer, tmp_path: Path) -> None:
    url = server.url("/gfs.grib2")
    assert http_source(url, cache_dir=tmp_path).fetch() is not None
    (entry,) = tmp_path.iterdir()
    with open(entry, "r+b") as f:
        f.seek(-10, os.SEEK_END)
        f.write(b"0123456789")
    server.stop()
    with pytest.raises(GribError) as e:
        http_source(url, cache_dir=tmp_path).fetch()
    one_line_error(e, url)


def test_the_cache_is_bounded_least_recently_used_first(grib: bytes, tmp_path: Path) -> None:
    served = Served()
    size_b = 200_000
    for k, name in enumerate("abcd"):
        served.publish(f"/{name}.grib2", grib[k * size_b : (k + 1) * size_b], idx=False)
    s = GribServer(served)
    try:

        def fetch(name: str, max_b: int) -> None:
            src = http_source(s.url(f"/{name}.grib2"), cache_dir=tmp_path, cache_max_bytes=max_b)
            assert src.fetch() is not None

        def kept() -> list[int]:
            return sorted(p.stat().st_size for p in tmp_path.iterdir())

        room_for_two = int(2.5 * size_b)
        fetch("a", room_for_two)
        fetch("b", room_for_two)
        assert len(kept()) == 2
        # "a" used last (a restarted source revalidated it): "b" is the least recently used.
        entries = sorted(tmp_path.iterdir(), key=lambda p: p.stat().st_mtime_ns)
        os.utime(entries[0], ns=(10**18, 10**18))
        os.utime(entries[1], ns=(10**17, 10**17))
        fetch("c", room_for_two)
        names = {p.name for p in tmp_path.iterdir()}
        assert entries[0].name in names and entries[1].name not in names and len(names) == 2
        # A bound smaller than one entry keeps the entry just written, and only that.
        fetch("d", 1000)
        assert len(kept()) == 1
        s.stop()
        back = http_source(s.url("/d.grib2"), cache_dir=tmp_path).fetch()
        assert back is not None and back[0].data == served.files["/d.grib2"]
    finally:
        s.stop()


# --- files and directories ---------------------------------------------------------------------


def test_a_file_is_read_again_only_when_it_changes(grib: bytes, tmp_path: Path) -> None:
    path = tmp_path / "gfs.grib2"
    path.write_bytes(grib)
    src = open_grib_source(str(path))
    assert isinstance(src, FileGribSource)
    first = src.fetch()
    assert first is not None and first[0].data == grib and first[0].name == str(path)
    assert src.fetch() is None
    # Rewritten by rename, same size and mtime: the inode tells.
    new = tmp_path / "new.grib2"
    new.write_bytes(grib)
    st = path.stat()
    os.utime(new, ns=(st.st_atime_ns, st.st_mtime_ns))
    os.replace(new, path)
    assert src.fetch() is not None
    path.write_bytes(grib[:100_000])
    changed = src.fetch()
    assert changed is not None and changed[0].data == grib[:100_000]
    assert src.fetch() is None
    src.forget()
    assert src.fetch() is not None
    path.unlink()
    with pytest.raises(GribError) as e:
        src.fetch()
    assert one_line_error(e, str(path)).endswith("no such file")


def test_a_file_over_the_limit_is_refused_unread(tmp_path: Path) -> None:
    path = tmp_path / "huge.grib2"
    with open(path, "wb") as f:
        f.truncate(MAX_GRIB_BYTES + 1)  # sparse: no gigabyte written
    with pytest.raises(GribError) as e:
        open_grib_source(str(path)).fetch()
    one_line_error(e, str(path), str(MAX_GRIB_BYTES + 1))


def test_a_directory_gives_every_grib_file_and_sees_changes(
    grib: bytes, tmp_path: Path, whole_fields: list[ModelField]
) -> None:
    folder = tmp_path / "steps"
    folder.mkdir()
    (folder / "gfs.f120").write_bytes(grib)
    cut_b = parse_idx(inventory(grib), "idx")[100].offset_b
    (folder / "step-two.bin").write_bytes(grib[:cut_b])  # any name
    # Not model data, or not yet: left out.
    (folder / "gfs.f120.idx").write_text(inventory(grib))
    (folder / ".hidden").write_bytes(b"junk")
    (folder / "gfs.f126.part").write_bytes(grib[:1000])
    (folder / "gfs.f132.tmp").write_bytes(grib[:1000])
    (folder / "sub").mkdir()
    src = open_grib_source(str(folder))
    assert isinstance(src, DirGribSource)
    blobs = src.fetch()
    assert blobs is not None
    assert [Path(b.name).name for b in blobs] == ["gfs.f120", "step-two.bin"]
    assert_same_fields(decode(blobs[0].data, "x", WINDOW), whole_fields)
    assert 0 < len(decode(blobs[1].data, "x", WINDOW)) < len(whole_fields)
    assert src.fetch() is None
    # One file changes: the list again, the unchanged file held (not read again, its bytes
    # not kept by the source), the changed one with its data
    (folder / "step-two.bin").write_bytes(grib[: cut_b // 2])
    again = src.fetch()
    assert again is not None and again[0].held and again[0].digest == blobs[0].digest
    assert not again[1].held and again[1].digest != blobs[1].digest
    assert src.fetch() is None
    (folder / "third").write_bytes(grib[:cut_b])
    added = src.fetch()
    assert added is not None and [Path(b.name).name for b in added][-1] == "third"
    (folder / "gfs.f120").unlink()
    removed = src.fetch()
    assert removed is not None and [Path(b.name).name for b in removed] == ["step-two.bin", "third"]
    src.forget()  # every file read again
    every = src.fetch()
    assert every is not None and not any(b.held for b in every)
    for p in ("step-two.bin", "third"):
        (folder / p).unlink()
    with pytest.raises(GribError) as e:
        src.fetch()
    one_line_error(e, str(folder), "no GRIB files")
    shutil.rmtree(folder)
    with pytest.raises(GribError) as e:
        src.fetch()
    one_line_error(e, str(folder), "no such directory")


def test_open_grib_source_refuses_other_schemes() -> None:
    with pytest.raises(GribError) as e:
        open_grib_source("ftp://example.invalid/gfs.grib2")
    one_line_error(e, "ftp://example.invalid/gfs.grib2")


# --- the .idx parser and range selection --------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "line", "says"),
    [
        ("1:0:d=2011011012:HGT:10 mb:anl:\n2:100:d=2011011012:TMP\n", 2, "fields"),
        ("1:0:d=2011011012:HGT:10 mb:anl:\n\n3:12a:d=1:TMP:10 mb:anl:\n", 3, "offset '12a'"),
        ("1:-5:d=1:HGT:10 mb:anl:\n", 1, "offset '-5'"),
        ("1:\u0661\u0662:d=1:HGT:10 mb:anl:\n", 1, "offset"),  # Arabic-Indic digits
        ("1:99999999999999999999:d=1:HGT:10 mb:anl:\n", 1, "past any GRIB file"),
        ("1:500:d=1:HGT:10 mb:anl:\n2:400:d=1:TMP:10 mb:anl:\n", 2, "before the line above"),
        ("x:0:d=1:HGT:10 mb:anl:\n", 1, "message number 'x'"),
        ("1:0:d=1:HGT:10 mb:anl:\r\n2\u2028:5:d=1:TMP:10 mb:anl:\r\n", 2, "message number"),
    ],
)
def test_parse_idx_errors_are_one_line_naming_the_line(text: str, line: int, says: str) -> None:
    with pytest.raises(GribError) as e:
        parse_idx(text, "gfs.idx")
    assert says in one_line_error(e, f"gfs.idx: line {line}:")


def test_parse_idx_reads_wgrib2_lines(grib: bytes) -> None:
    text = "1:0:d=2011011012:HGT:10 mb:anl:\r\n\n2.1:10:d=2011011012:UGRD:10 mb:anl:ENS=hi\n"
    assert parse_idx(text, "x") == [
        IdxEntry("1", 0, "d=2011011012", "HGT", "10 mb", "anl"),
        IdxEntry("2.1", 10, "d=2011011012", "UGRD", "10 mb", "anl"),
    ]
    entries = parse_idx(inventory(grib), "fixture.idx")
    assert entries[3] == IdxEntry("4.1", 25975, "d=2011011012", "UGRD", "10 mb", "120 hour fcst")
    assert entries[4].offset_b == 25975 and entries[4].var == "VGRD"


def _entries(*lines: tuple[str, int, str, str]) -> list[IdxEntry]:
    return [IdxEntry(n, off, "d=2011011012", var, level, "anl") for n, off, var, level in lines]


def test_wanted_ranges_merges_neighbours_and_counts_a_uv_message_once() -> None:
    entries = _entries(
        ("1", 0, "HGT", "10 mb"),
        ("2", 100, "ABSV", "10 mb"),
        ("3.1", 200, "UGRD", "10 mb"),
        ("3.2", 200, "VGRD", "10 mb"),
        ("4", 300, "TMP", "10 mb"),
        ("5", 450, "TMP", "2 m above ground"),
        ("6", 500, "O3MR", "10 mb"),
        ("7.1", 600, "UGRD", "tropopause"),  # not a wanted level: the pair is left out
        ("7.2", 600, "VGRD", "tropopause"),
        ("8", 700, "PRES", "surface"),
    )
    wanted = [("HGT", "mb"), ("UGRD", "mb"), ("VGRD", "mb"), ("TMP", "mb")]
    wanted += [("TMP", "2 m above ground"), ("PRES", "surface")]
    assert wanted_ranges(entries, wanted) == [(0, 99), (200, 499), (700, None)]
    # Only v wanted: its message (shared with u) still comes, once.
    assert wanted_ranges(entries, (("VGRD", "mb"),)) == [(200, 299)]
    assert wanted_ranges(entries, (("VGRD", "10 mb"),)) == [(200, 299)]
    assert wanted_ranges(entries, (("O3MR", "surface"),)) == []
    assert wanted_ranges([], wanted) == []
    # "mb" is any pressure level, not any level with "mb" in it.
    odd = _entries(("1", 0, "TMP", "30-0 mb above ground"), ("2", 50, "TMP", "500 mb"))
    assert wanted_ranges(odd, (("TMP", "mb"),)) == [(50, None)]


def test_wanted_ranges_of_the_fixture_cover_every_wanted_message_once(grib: bytes) -> None:
    entries = parse_idx(inventory(grib), "fixture.idx")
    ranges = wanted_ranges(entries, IDX_WANTED)
    ends = [len(grib) - 1 if last is None else last for _, last in ranges]
    starts = [first for first, _ in ranges]
    # Sorted, apart (neighbours would have merged), each starting at a message.
    assert all(e + 1 < s for e, s in zip(ends, starts[1:], strict=False))
    offsets = {e.offset_b for e in entries}
    assert set(starts) <= offsets and all(e + 1 in offsets | {len(grib)} for e in ends)
    assert all(grib[s : s + 4] == b"GRIB" for s in starts)


def test_fewer_ranges_joins_the_nearest_until_few_are_left() -> None:
    ranges = [(0, 9), (12, 19), (100, 199), (201, 300), (1000, None)]
    assert fewer_ranges(ranges, 10) == ranges
    assert fewer_ranges(ranges, 3) == [(0, 19), (100, 300), (1000, None)]
    assert fewer_ranges(ranges, 1) == [(0, None)]


def test_a_wind_and_temperature_profile_is_a_fifth_of_the_file(
    server: GribServer, grib: bytes, whole_fields: list[ModelField]
) -> None:
    """`[grib] fields = "wind"`: u, v and t on the pressure levels; the profile made of it has
    the whole file's winds and temperatures, and heights reckoned from the temperatures up
    from the standard atmosphere within 150 m of the model's own (the day's pressure
    anomaly, 8 m a hectopascal, and moisture the reckoning leaves out)."""
    src = open_grib_source(server.url("/gfs.grib2"), fields="wind")
    blobs = src.fetch()
    assert blobs is not None
    assert server.served.bytes_sent < 0.2 * len(grib)
    got = decoded(blobs)
    assert {f.name for f in got} == {"u", "v", "t"}
    lat, lon = WINDOW.lat_deg, WINDOW.lon_deg
    thin = profile_at(merge_steps(got, ("thin",)), lat, lon, VALID)
    full = profile_at(merge_steps(whole_fields, ("full",)), lat, lon, VALID)
    assert thin is not None and full is not None
    by_p = {lev.pressure_hpa: lev for lev in full.levels}
    for lev in thin.levels:
        ref = by_p[lev.pressure_hpa]
        assert (lev.u_mps, lev.v_mps, lev.t_k) == (ref.u_mps, ref.v_mps, ref.t_k)
        assert lev.height_m == pytest.approx(ref.height_m, abs=150.0)


def _ecmwf_index(data: bytes) -> str:
    """An index of the fixture as ECMWF open data writes one beside each file (one JSON
    object a message: its parameter, level type and level, offset and length), made with
    eccodes' own keys."""
    import json
    import os

    import eccodes

    items: list[dict[str, object]] = []
    eccodes.codes_grib_multi_support_on()
    with os.fdopen(os.memfd_create("idx"), "w+b") as f:
        f.write(data)
        f.seek(0)
        while (h := eccodes.codes_grib_new_from_file(f)) is not None:
            try:
                level_type = eccodes.codes_get(h, "typeOfLevel")
                item = {
                    "date": str(eccodes.codes_get(h, "dataDate")),
                    "time": f"{eccodes.codes_get(h, 'dataTime'):04d}",
                    "step": str(eccodes.codes_get(h, "stepRange")),
                    "levtype": "pl" if level_type == "isobaricInhPa" else "sfc",
                    "param": eccodes.codes_get(h, "shortName"),
                    "_offset": int(eccodes.codes_get(h, "offset")),
                }
                if level_type == "isobaricInhPa":
                    item["levelist"] = str(eccodes.codes_get(h, "level"))
                items.append(item)
            finally:
                eccodes.codes_release(h)
        eccodes.codes_grib_multi_support_reset_file(f)
    # a message's length: to the next message (NCEP's u and v share one; ECMWF's never do,
    # and eccodes' totalLength is a field's there, not the message's)
    starts = [*sorted({int(i["_offset"]) for i in items}), len(data)]
    after = dict(itertools.pairwise(starts))
    for item in items:
        item["_length"] = after[int(item["_offset"])] - int(item["_offset"])
    return "".join(json.dumps(item) + "\n" for item in items)


def test_ecmwf_open_datas_index_takes_the_byte_ranges_too(
    server: GribServer, grib: bytes, whole_fields: list[ModelField]
) -> None:
    """ECMWF open data publishes FILE.index (JSON lines with each message's offset and
    length) beside FILE.grib2, and no .idx: the wanted messages come by byte ranges, and
    decode as the whole file does."""
    server.served.publish("/ifs.grib2", grib, idx=False)
    server.served.files["/ifs.index"] = _ecmwf_index(grib).encode()
    src = http_source(server.url("/ifs.grib2"))
    blobs = src.fetch()
    assert blobs is not None
    paths = server.served.paths()
    assert paths[:2] == ["/ifs.grib2.idx", "/ifs.index"] and set(paths[2:]) == {"/ifs.grib2"}
    assert all("Range" in h for _, h in server.served.requests[2:])
    assert server.served.bytes_sent < 0.6 * len(grib)
    # ECMWF's parameters: the pressure levels' u, v, t, gh and r, and its surface fields
    # (cloud water and NCEP's cloud decks have no ECMWF name); each the whole file's
    got = _by_key(decoded(blobs))
    whole = _by_key(whole_fields)
    assert set(got) <= set(whole)
    for name in ("u", "v", "t", "gh", "r"):
        levels = {k[2] for k in got if k[0] == name and k[1] == "isobaric"}
        assert len(levels) >= PRESSURE_LEVELS_READ - 1, (name, levels)
    for key, mine in got.items():
        np.testing.assert_array_equal(mine.values, whole[key].values)
    server.served.reset_counts()
    assert src.fetch() is None  # the .index alone asked again, 304
    assert server.served.paths() == ["/ifs.index"]


def test_a_bad_ecmwf_index_line_is_one_line_naming_it() -> None:
    for text, why in (
        ("{not json\n", "not a JSON object"),
        ("[1, 2]\n", "not a JSON object"),
        ('{"param": "u", "_offset": -1, "_length": 10}\n', "byte counts"),
        ('{"param": "u", "_offset": "0", "_length": 10}\n', "byte counts"),
    ):
        with pytest.raises(GribError) as e:
            parse_ecmwf_index(text, "x.index")
        one_line_error(e, "x.index: line 1", why)
