"""Who may reach the web station (wxsky/web/access.py): the token file, the comparison, and
the Host and Origin checks that keep another site's pages from driving it."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from wxsky.errors import ConfigError
from wxsky.web.access import (
    bearer,
    host_allowed,
    is_loopback,
    load_or_create_token,
    origin_allowed,
    token_matches,
)


def test_the_token_is_made_once_readable_by_its_owner_only(tmp_path: Path) -> None:
    path = tmp_path / "cfg" / "wxsky" / "web-token"
    token = load_or_create_token(path)
    assert len(token) >= 40
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert load_or_create_token(path) == token  # the second run reads it
    other = tmp_path / "other"
    assert load_or_create_token(other) != token  # random, not derived


def test_a_token_file_others_may_read_or_holding_no_token_stops_the_start(
    tmp_path: Path,
) -> None:
    path = tmp_path / "web-token"
    path.write_text("a-long-enough-token-for-the-check\n")
    os.chmod(path, 0o644)
    with pytest.raises(ConfigError, match=r"others may read it \(mode 644\); chmod 600 it"):
        load_or_create_token(path)
    os.chmod(path, 0o600)
    assert load_or_create_token(path) == "a-long-enough-token-for-the-check"
    path.write_text("short\n")
    with pytest.raises(ConfigError, match="holds no token"):
        load_or_create_token(path)


def test_token_comparison_takes_only_the_exact_token() -> None:
    token = "abcdefghijklmnopqrstuvwxyz012345"
    assert token_matches(token, token)
    assert not token_matches(token[:-1], token)
    assert not token_matches(token + "x", token)
    assert not token_matches(None, token)
    assert not token_matches("é" * 10, token)  # not ASCII: compared as bytes, no exception
    assert not token_matches("a" * 100_000, token)
    assert bearer("Bearer xyz") == "xyz"
    assert bearer("bearer  xyz ") == "xyz"
    assert bearer("Basic xyz") is None
    assert bearer(None) is None


@pytest.mark.parametrize(
    ("host", "loopback"),
    [
        ("127.0.0.1", True),
        ("127.9.9.9", True),
        ("::1", True),
        ("[::1]", True),
        ("localhost", True),
        ("0.0.0.0", False),
        ("10.1.2.3", False),
        ("example.org", False),
    ],
)
def test_loopback_addresses(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback


def test_on_loopback_a_request_must_name_a_loopback_host() -> None:
    assert host_allowed("127.0.0.1:8080", "127.0.0.1", 8080)
    assert host_allowed("localhost:8080", "127.0.0.1", 8080)
    assert host_allowed("[::1]:8080", "::1", 8080)
    # A site that rebinds its own name to 127.0.0.1 still names itself.
    assert not host_allowed("evil.example:8080", "127.0.0.1", 8080)
    assert not host_allowed("127.0.0.1:9999", "127.0.0.1", 8080)
    assert not host_allowed(None, "127.0.0.1", 8080)
    assert not host_allowed("127.0.0.1:notaport", "127.0.0.1", 8080)
    # Off loopback the token guards every request, whatever name it came by.
    assert host_allowed("ios.cockpit.lan:8080", "0.0.0.0", 8080)


def test_a_browser_page_must_come_from_the_station_itself() -> None:
    assert origin_allowed("http://127.0.0.1:8080", "127.0.0.1:8080")
    assert origin_allowed(None, "127.0.0.1:8080")  # a program, not a page of another site
    assert not origin_allowed("http://evil.example", "127.0.0.1:8080")
    assert not origin_allowed("http://127.0.0.1:8081", "127.0.0.1:8080")
    assert not origin_allowed("null", "127.0.0.1:8080")
    assert not origin_allowed("file://", "127.0.0.1:8080")


def test_a_pages_mailbox_keeps_the_newest_view_and_picture_and_a_bounded_queue() -> None:
    """What a page that reads nothing costs: one view, one picture and MAX_QUEUED_REPLIES
    replies at most, then it is closed."""
    from wxsky.web.server import MAX_QUEUED_REPLIES, WebClient

    client = WebClient(1, None, "test")  # type: ignore[arg-type]  # never sent to here
    for k in range(1000):
        client.send_view(f"view {k}")
        client.send_picture(b"jpeg %d" % k)
    assert client._view == "view 999" and client._picture == b"jpeg 999"
    assert client.dropped_views == 999 and client.dropped_pictures == 999
    assert all(client.send_text(f"reply {k}") for k in range(MAX_QUEUED_REPLIES))
    assert client.closed_why is None
    assert not client.send_text("one too many")
    assert client.closed_why == f"{MAX_QUEUED_REPLIES} replies unread"
    assert len(client._replies) == MAX_QUEUED_REPLIES
