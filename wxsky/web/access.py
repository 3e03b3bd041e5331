"""Who may reach the web station (docs/web.md, Access): on a loopback address only this
machine, with no token; on any other, a token every request carries (a header or the cookie
the login page sets), made on first run into a file only its owner reads. Also the checks
that keep another web site, open in the same browser, from driving the station: the Host a
request names must be the station's own and a browser's Origin must match it."""

from __future__ import annotations

import hmac
import ipaddress
import logging
import os
import secrets
import stat
from pathlib import Path
from urllib.parse import urlsplit

from wxsky.errors import ConfigError

log = logging.getLogger(__name__)

COOKIE = "wxsky_token"
TOKEN_BYTES = 32  # 256 bits, written as 43 URL-safe characters
MAX_TOKEN_CHARS = 256  # a longer token file, header or cookie is no token of ours


def is_loopback(host: str) -> bool:
    """True for an address only this machine reaches (127.0.0.0/8, ::1, localhost)."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def default_token_file() -> Path:
    base = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(base) / "wxsky" / "web-token"


def load_or_create_token(path: Path) -> str:
    """The token in `path`, made (0600, never replacing a file) if there is none. ConfigError
    (one line) for a file that others may read or that holds no token."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:
        return _read_token(path)
    except OSError as exc:
        raise ConfigError(f"[web] token_file {path}: cannot create: {exc.strerror}") from None
    token = secrets.token_urlsafe(TOKEN_BYTES)
    with os.fdopen(fd, "w", encoding="ascii") as f:
        f.write(token + "\n")
    log.info("web: made a token in %s (give it to the instructor's browser once)", path)
    return token


def _read_token(path: Path) -> str:
    try:
        mode = path.stat().st_mode
        if mode & (stat.S_IRWXG | stat.S_IRWXO):
            raise ConfigError(
                f"[web] token_file {path}: others may read it (mode {stat.S_IMODE(mode):o}); "
                f"chmod 600 it"
            )
        text = path.read_text(encoding="ascii").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"[web] token_file {path}: cannot read: {exc}") from None
    if not 16 <= len(text) <= MAX_TOKEN_CHARS or not text.isprintable() or " " in text:
        raise ConfigError(
            f"[web] token_file {path}: holds no token (16..{MAX_TOKEN_CHARS} printable "
            f"characters, no spaces)"
        )
    return text


def token_matches(given: str | None, token: str) -> bool:
    """Constant time in the token's contents: a wrong guess tells nothing of the right one."""
    if given is None or len(given) > MAX_TOKEN_CHARS:
        return False
    return hmac.compare_digest(given.encode("utf-8", "replace"), token.encode("ascii"))


def bearer(header: str | None) -> str | None:
    """The token of an `Authorization: Bearer <token>` header."""
    if header is None:
        return None
    scheme, _, value = header.partition(" ")
    return value.strip() if scheme.lower() == "bearer" else None


def host_allowed(host_header: str | None, listen_host: str, port: int) -> bool:
    """On loopback, a request must name the station by a loopback name: a page of another
    site that rebinds its own name to 127.0.0.1 (DNS rebinding) names its own host."""
    if not is_loopback(listen_host):
        return True  # the token stands guard there
    if not host_header:
        return False
    parsed = urlsplit(f"//{host_header}")
    try:
        named_port = parsed.port
    except ValueError:
        return False
    return is_loopback(parsed.hostname or "") and named_port in (port, None)


def origin_allowed(origin: str | None, host_header: str | None) -> bool:
    """A browser sends Origin with every WebSocket handshake and POST: it must be the page's
    own (scheme, host and port as the request's Host). No Origin is a program, not a page of
    another site."""
    if origin is None:
        return True
    parsed = urlsplit(origin)
    return (
        parsed.scheme in ("http", "https") and parsed.netloc.lower() == (host_header or "").lower()
    )
