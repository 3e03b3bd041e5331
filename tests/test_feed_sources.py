"""Feed sources against real files, a real pipe and a real HTTP server on loopback."""

from __future__ import annotations

import asyncio
import gzip
import http.server
import os
import threading
import time
from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path
from typing import ClassVar

import pytest

from wxsky.errors import FeedError
from wxsky.inputs.feed_sources import FileSource, HttpSource, StreamSource, open_source

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
    got = FileSource(path).fetch_now()
    assert got is not None and got.data == REPORT
    with pytest.raises(FeedError, match=r"nope\.txt: no such file"):
        FileSource(tmp_path / "nope.txt").fetch_now()
    broken = tmp_path / "broken.gz"
    broken.write_bytes(gzip.compress(REPORT)[:12])
    with pytest.raises(FeedError, match="broken gzip"):
        FileSource(broken).fetch_now()


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


def _wait_for(fn, timeout_s: float = 5.0):  # type: ignore[no-untyped-def]
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
        self.end_headers()
        self.wfile.write(self.body)

    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def server() -> Iterator[str]:
    _Feed.body, _Feed.status, _Feed.seen = REPORT, 200, []
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
        start = time.monotonic()
        with pytest.raises(FeedError, match="timed out"):
            HttpSource(url, timeout_s=0.3).fetch_now()
        assert time.monotonic() - start < 5.0
    finally:
        listener.close()


def test_open_source_picks_by_spec(tmp_path: Path) -> None:
    assert isinstance(open_source(str(tmp_path / "x.csv")), FileSource)
    assert isinstance(open_source("https://example.invalid/metar.csv"), HttpSource)
    with pytest.raises(FeedError, match="ftp://x"):
        open_source("ftp://x/y")
