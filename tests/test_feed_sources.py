"""Feed sources against real files, a real pipe and a real HTTP server on loopback."""

from __future__ import annotations

import asyncio
import contextlib
import gzip
import http.server
import os
import threading
import time
import tracemalloc
from collections.abc import Callable, Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import ClassVar

import pytest
from metar_helpers import gzip_bomb

from wxsky.errors import FeedChanging, FeedError, FeedTooLarge
from wxsky.inputs.feed_sources import (
    MAX_FEED_BYTES,
    FileSource,
    HttpSource,
    StreamSource,
    open_source,
)
from wxsky.weather.feeds import gunzip, read_feed

REPORT = b"KXYZ 261555Z 27010KT 9999 SCT030 20/10 Q1015\n"


def test_file_source_reads_only_when_the_file_changes(tmp_path: Path) -> None:
    path = tmp_path / "feed.txt"
    path.write_bytes(REPORT)
    os.utime(path, (1_700_000_000, 1_700_000_000))
    src = FileSource(path)
    first = src.fetch_now()
    assert first is not None and first.data == REPORT
    assert first.reference_utc == datetime.fromtimestamp(1_700_000_000, tz=UTC)
    assert src.fetch_now() is None
    # Replaced by rename, as feed tools do: new inode, same size and even the same mtime.
    new = tmp_path / "feed.tmp"
    new.write_bytes(REPORT.replace(b"SCT030", b"BKN040"))
    os.utime(new, (1_700_000_000, 1_700_000_000))
    new.replace(path)
    second = src.fetch_now()
    assert second is not None and b"BKN040" in second.data


def test_file_source_unzips_and_reports_missing_files(tmp_path: Path) -> None:
    path = tmp_path / "feed.csv.gz"
    path.write_bytes(gzip.compress(REPORT))
    # settle_s=0: read at once, although just written (the hold is tested on its own below).
    got = FileSource(path, settle_s=0.0).fetch_now()
    assert got is not None and got.data == REPORT
    with pytest.raises(FeedError, match=r"nope\.txt: no such file"):
        FileSource(tmp_path / "nope.txt").fetch_now()
    broken = tmp_path / "broken.gz"
    broken.write_bytes(gzip.compress(REPORT)[:12])
    with pytest.raises(FeedError, match="broken gzip"):
        FileSource(broken, settle_s=0.0).fetch_now()


def test_stream_source_delivers_lines_as_they_arrive() -> None:
    read_fd, write_fd = os.pipe()
    with os.fdopen(read_fd, "rb") as reader, os.fdopen(write_fd, "wb") as writer:
        src = StreamSource("pipe", reader)
        assert asyncio.run(src.fetch()) is None
        writer.write(REPORT)
        writer.flush()
        got = _wait_for(lambda: asyncio.run(src.fetch()))
        assert got.data == REPORT and got.format == "lines"
        writer.write(b"X" * 10_000 + b"\n")
        writer.close()
        long_line = _wait_for(lambda: asyncio.run(src.fetch()))
        # Cut at the line limit, the rest dropped, not buffered without end.
        assert long_line.data == b"X" * 4096 + b"\n"
        _wait_for(lambda: src.eof or None)
        with pytest.raises(FeedError, match="end of input"):
            asyncio.run(src.fetch())


def _wait_for(fn, timeout_s: float = 60.0):  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = fn()
        if value is not None:
            return value
        time.sleep(0.01)
    raise AssertionError("timed out")


class _Feed(http.server.BaseHTTPRequestHandler):
    body = REPORT
    status = 200
    content_type = "text/plain"
    encoding: str | None = None  # Content-Encoding
    send_length = True
    seen: ClassVar[list[dict[str, str]]] = []

    def do_GET(self) -> None:
        type(self).seen.append(dict(self.headers))
        etag = f'"v-{hash(self.body)}"'
        if self.headers.get("If-None-Match") == etag:
            self.send_response(304)
            self.end_headers()
            return
        self.send_response(self.status)
        self.send_header("Content-Type", self.content_type)
        self.send_header("ETag", etag)
        self.send_header("Last-Modified", "Wed, 26 Jul 2025 16:00:00 GMT")
        if self.encoding:
            self.send_header("Content-Encoding", self.encoding)
        if self.send_length:
            self.send_header("Content-Length", str(len(self.body)))
        self.end_headers()
        # A client that stops reading (an oversize body) closes the connection on us.
        with contextlib.suppress(ConnectionError):
            self.wfile.write(self.body)

    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def server() -> Iterator[str]:
    _Feed.body, _Feed.status, _Feed.seen = REPORT, 200, []
    _Feed.content_type, _Feed.encoding, _Feed.send_length = "text/plain", None, True
    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Feed)
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}/metar.txt"
    httpd.shutdown()
    httpd.server_close()


def test_http_source_uses_conditional_requests(server: str) -> None:
    src = HttpSource(server, timeout_s=5.0)
    first = src.fetch_now()
    assert first is not None and first.data == REPORT
    # The server's Date header, not our clock, dates a feed without dates.
    assert abs((first.reference_utc - datetime.now(UTC)).total_seconds()) < 60
    assert src.fetch_now() is None  # 304
    assert _Feed.seen[1]["If-None-Match"].startswith('"v-')
    assert _Feed.seen[1]["If-Modified-Since"] == "Wed, 26 Jul 2025 16:00:00 GMT"
    _Feed.body = gzip.compress(REPORT.replace(b"SCT", b"OVC"))
    changed = src.fetch_now()
    assert changed is not None and b"OVC030" in changed.data


def test_http_errors_are_one_line_feed_errors(server: str) -> None:
    _Feed.status = 503
    with pytest.raises(FeedError, match="HTTP 503"):
        HttpSource(server).fetch_now()
    with pytest.raises(FeedError, match=r"127\.0\.0\.1:9/none: .*refused"):
        HttpSource("http://127.0.0.1:9/none", timeout_s=2.0).fetch_now()


def test_http_timeout_is_a_feed_error() -> None:
    import socket

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)  # accepts the connection, never answers
    try:
        url = f"http://127.0.0.1:{listener.getsockname()[1]}/slow"
        # The error, not a stopwatch, shows the 0.3 s timeout fired (without it, a hang).
        with pytest.raises(FeedError, match="timed out"):
            HttpSource(url, timeout_s=0.3).fetch_now()
    finally:
        listener.close()


def test_open_source_picks_by_spec(tmp_path: Path) -> None:
    assert isinstance(open_source(str(tmp_path / "x.csv")), FileSource)
    assert isinstance(open_source("https://example.invalid/metar.csv"), HttpSource)
    with pytest.raises(FeedError, match="ftp://x"):
        open_source("ftp://x/y")


# --- bounded reads: gzip bombs, oversize bodies, a writer far ahead of the polls ---------------

BOMB_UNPACKED = 256 * 1024 * 1024  # 8 times the limit, unpacked; about 1 MB packed


@pytest.fixture(scope="module")
def bomb() -> bytes:
    return gzip_bomb(BOMB_UNPACKED)


def _peak_bytes(fn: Callable[[], object]) -> int:
    """The most memory Python held at once while `fn` ran, above what it held before."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        with contextlib.suppress(FeedError):
            fn()
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


def test_a_gzip_bomb_file_is_refused_within_the_limit(tmp_path: Path, bomb: bytes) -> None:
    path = tmp_path / "metar.csv.gz"
    path.write_bytes(bomb)
    os.utime(path, (1_700_000_000, 1_700_000_000))
    src = FileSource(path)
    with pytest.raises(FeedTooLarge) as refused:
        src.fetch_now()
    message = str(refused.value)
    assert str(path) in message and f"{MAX_FEED_BYTES}-byte limit" in message
    assert "\n" not in message
    assert src.fetch_now() is None  # refused content is not unpacked again until it changes
    # Unpacking stops at the limit: never the bomb's 256 MiB in memory at once.
    peak = _peak_bytes(FileSource(path).fetch_now)
    assert peak < MAX_FEED_BYTES + 8 * 1024 * 1024
    # The one-shot readers go through the same bounded gunzip.
    with pytest.raises(FeedTooLarge, match=r"metar\.csv\.gz: gzip data unpacks to more than"):
        read_feed(path)


def test_gunzip_keeps_data_up_to_the_limit_and_reads_concatenated_members() -> None:
    members = gzip.compress(REPORT) + gzip.compress(REPORT.replace(b"KXYZ", b"KABC"))
    data, trouble = gunzip(members, name="two")
    assert data == REPORT + REPORT.replace(b"KXYZ", b"KABC") and trouble is None
    exact, trouble = gunzip(gzip_bomb(1024 * 1024), name="x", limit=1024 * 1024)
    assert len(exact) == 1024 * 1024 and trouble is None
    with pytest.raises(FeedTooLarge, match=r"^x: .* 1048575-byte limit"):
        gunzip(gzip_bomb(1024 * 1024), name="x", limit=1024 * 1024 - 1)


def test_a_file_over_the_limit_is_refused_unread(tmp_path: Path) -> None:
    path = tmp_path / "huge.txt"
    with open(path, "wb") as f:
        f.truncate(MAX_FEED_BYTES + 1)  # sparse: no disk or time spent
    with pytest.raises(FeedTooLarge, match=r"huge\.txt: \d+ bytes, over the \d+-byte limit"):
        FileSource(path, settle_s=0.0).fetch_now()


def test_an_http_gzip_bomb_is_refused_within_the_limit(server: str, bomb: bytes) -> None:
    _Feed.body, _Feed.content_type, _Feed.encoding = bomb, "text/csv", "gzip"
    with pytest.raises(FeedTooLarge, match=rf"{server}: gzip data unpacks to more than"):
        HttpSource(server, timeout_s=10.0).fetch_now()
    peak = _peak_bytes(HttpSource(server, timeout_s=10.0).fetch_now)
    assert peak < MAX_FEED_BYTES + 8 * 1024 * 1024
    # Refused content leaves no validators behind: the next poll fetches it whole, not a 304.
    src = HttpSource(server, timeout_s=10.0)
    for _ in range(2):
        with pytest.raises(FeedTooLarge):
            src.fetch_now()
    assert "If-None-Match" not in _Feed.seen[-1]


def test_http_content_encoding_gzip_and_oversize_bodies(server: str) -> None:
    _Feed.body, _Feed.encoding = gzip.compress(REPORT), "gzip"
    got = HttpSource(server).fetch_now()
    assert got is not None and got.data == REPORT
    _Feed.body = REPORT  # says gzip, is not
    with pytest.raises(FeedError, match="Content-Encoding gzip, but the body is not gzip"):
        HttpSource(server).fetch_now()
    _Feed.body, _Feed.encoding = REPORT, "br"
    with pytest.raises(FeedError, match="Content-Encoding 'br' is not supported"):
        HttpSource(server).fetch_now()
    _Feed.body, _Feed.encoding = b"K" * (MAX_FEED_BYTES + 1), None
    with pytest.raises(FeedTooLarge, match=rf"{server}: Content-Length \d+ over the"):
        HttpSource(server).fetch_now()
    _Feed.send_length = False  # no Content-Length: the read itself stops at the limit
    with pytest.raises(FeedTooLarge, match=rf"{server}: the body over the"):
        HttpSource(server).fetch_now()


def test_a_stream_writer_far_ahead_of_the_polls_waits_in_the_pipe() -> None:
    line = b"K" * 4095 + b"\n"
    count = (MAX_FEED_BYTES + 8 * 1024 * 1024) // len(line)
    read_fd, write_fd = os.pipe()
    with os.fdopen(read_fd, "rb") as reader, os.fdopen(write_fd, "wb") as writer:
        src = StreamSource("pipe", reader)

        def write_all() -> None:
            with contextlib.suppress(BrokenPipeError, ValueError):
                writer.write(line * count)
                writer.close()

        thread = threading.Thread(target=write_all, daemon=True)
        thread.start()
        # Time for a reader without a bound to take all 40 MiB into memory; with the bound it
        # stops at the limit whenever the fetch comes.
        thread.join(0.5)
        sizes = []
        while not src.eof:
            got = asyncio.run(src.fetch())
            if got is not None:
                sizes.append(len(got.data))
            else:
                time.sleep(0.01)
        thread.join(5.0)
    assert sum(sizes) == count * len(line)  # nothing lost
    assert max(sizes) < MAX_FEED_BYTES + len(line)


# --- a file caught while it is being written --------------------------------------------------


def test_a_file_written_in_two_parts_is_read_only_when_whole(tmp_path: Path) -> None:
    path = tmp_path / "metar.txt"
    # A settling time no stall of this machine can outlast (the default is 0.5 s).
    src = FileSource(path, settle_s=600.0)
    with open(path, "wb") as writer:  # rewritten in place, as some tools do
        writer.write(REPORT[:12])  # "KXYZ 261555Z"
        writer.flush()
        with pytest.raises(FeedChanging, match=r"metar\.txt: written .* ago") as held:
            src.fetch_now()
        assert held.value.retry_in_s == 600.0
        writer.write(REPORT[12:])
    # Changed again since it was held back: still not taken.
    with pytest.raises(FeedChanging):
        src.fetch_now()
    # Unchanged since the last look (the input looks again after retry_in_s): read, whole.
    got = src.fetch_now()
    assert got is not None and got.data == REPORT
    assert src.fetch_now() is None


def test_a_file_that_never_stops_changing_is_read_all_the_same(tmp_path: Path) -> None:
    path = tmp_path / "metar.txt"
    src = FileSource(path, settle_s=600.0, max_settle_s=0.0)  # held back at most once
    path.write_bytes(REPORT)
    with pytest.raises(FeedChanging):
        src.fetch_now()
    path.write_bytes(REPORT + REPORT)
    got = src.fetch_now()
    assert got is not None and got.data == REPORT + REPORT


def test_a_file_whose_writer_pauses_past_the_settling_time_is_not_read_half_written(
    tmp_path: Path,
) -> None:
    """The soak's writer stops 1.5 s mid-file, longer than the 0.5 s settling time: what is
    there by then ('KXYZ 261555Z 27010KT 9999', no newline) reads as a shorter report."""
    path = tmp_path / "metar.txt"
    src = FileSource(path, settle_s=0.05, max_settle_s=600.0)
    half = REPORT[:25]
    path.write_bytes(half)
    os.utime(path, ns=(time.time_ns() - 10**10,) * 2)  # written 10 s ago: long settled
    for _ in range(3):  # the input looks again every retry_in_s, for up to max_settle_s
        with pytest.raises(FeedChanging, match=r"metar\.txt: its last line has no end") as held:
            src.fetch_now()
        assert held.value.retry_in_s == 0.05
    with open(path, "ab") as writer:
        writer.write(REPORT[25:])
    os.utime(path, ns=(time.time_ns() - 10**10,) * 2)
    got = src.fetch_now()
    assert got is not None and got.data == REPORT
    assert src.fetch_now() is None


def test_a_whole_file_without_a_final_newline_is_read_after_the_longest_hold(
    tmp_path: Path,
) -> None:
    path = tmp_path / "metar.txt"
    src = FileSource(path, settle_s=0.05, max_settle_s=0.2)
    path.write_bytes(REPORT.rstrip(b"\n"))
    os.utime(path, ns=(time.time_ns() - 10**10,) * 2)
    with pytest.raises(FeedChanging):
        src.fetch_now()
    time.sleep(0.25)
    got = src.fetch_now()
    assert got is not None and got.data == REPORT.rstrip(b"\n")
    # An empty file (truncated at the start of a rewrite in place) is held the same way;
    # settle_s 0 (a one-shot command) reads at once.
    path.write_bytes(b"")
    os.utime(path, ns=(time.time_ns() - 10**10,) * 2)
    with pytest.raises(FeedChanging, match="empty"):
        src.fetch_now()
    once = FileSource(path, settle_s=0.0).fetch_now()
    assert once is not None and once.data == b""


def test_a_last_line_cut_mid_group_is_left_out_after_the_longest_hold(tmp_path: Path) -> None:
    """Issue 40: `... 9999 OVC0` and no newline, for longer than the longest hold, was read as
    a report with its cloud group garbled; now that line is left out, saying which station
    and file, and the lines before it are read."""
    path = tmp_path / "metar.txt"
    src = FileSource(path, settle_s=0.05, max_settle_s=0.2)
    path.write_bytes(REPORT + b"EDDF 261555Z 25012KT 9999 OVC0")
    os.utime(path, ns=(time.time_ns() - 10**10,) * 2)
    with pytest.raises(FeedChanging, match="its last line has no end"):
        src.fetch_now()
    time.sleep(0.25)  # past max_settle_s: held back no longer
    got = src.fetch_now()
    assert got is not None and got.data == REPORT
    assert got.dropped is not None
    assert str(path) in got.dropped and "EDDF" in got.dropped and "'OVC0'" in got.dropped
    assert "\n" not in got.dropped
    # The writer finishes the line: the file changed, read whole.
    path.write_bytes(REPORT + b"EDDF 261555Z 25012KT 9999 OVC008\n")
    os.utime(path, ns=(time.time_ns() - 10**10,) * 2)
    got = src.fetch_now()
    assert got is not None and got.data.endswith(b"OVC008\n") and got.dropped is None


def test_a_last_line_ending_with_a_whole_group_is_still_read(tmp_path: Path) -> None:
    path = tmp_path / "metar.txt"
    src = FileSource(path, settle_s=0.05, max_settle_s=0.0)  # held back at most once
    path.write_bytes(REPORT + b"EDDF 261555Z 25012KT 9999 OVC008")
    os.utime(path, ns=(time.time_ns() - 10**10,) * 2)
    with pytest.raises(FeedChanging):
        src.fetch_now()
    got = src.fetch_now()
    assert got is not None and got.data.endswith(b"OVC008") and got.dropped is None
    # Only a cut line in the file: nothing to read, the file is refused with the reason.
    path.write_bytes(b"EDDF 261555Z 25012KT 9999 OVC0")
    os.utime(path, ns=(time.time_ns() - 10**8,) * 2)
    with pytest.raises(FeedChanging):
        src.fetch_now()
    with pytest.raises(FeedError, match=r"EDDF: the last line ends mid-group \('OVC0'"):
        src.fetch_now()
    assert src.fetch_now() is None  # refused until it changes
