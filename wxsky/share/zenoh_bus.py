"""The channel bus on Eclipse Zenoh: the **only** module that imports zenoh.

One session per daemon, one key space per site (`wxsky/<site>/...`):

    state           the master's sky state: reliable, blocking congestion control; and a
                    queryable answering the latest state, for a channel that joins late
    clock           the master's ticks: express, dropped under congestion (a newer one comes)
    clock/ping      a queryable answering the master's monotonic reading (clock sync)
    health/<name>   each daemon's fps and lag, once a second
    alive/master/<id>     the master's liveliness token, named by its run id (one per site)
    alive/channel/<name>  each channel's liveliness token

Endpoints are explicit (the master listens, channels connect) and multicast scouting is off:
it finds nothing on a loopback-only host and would reach past the machine elsewhere.

With `Credentials` the bus is Zenoh's own mutual TLS (a `tls/` endpoint: each side proves
its certificate against the dome's CA) and the master, through which every channel's traffic
passes, applies an access-control list by certificate common name: a `wxsky-channel` may
publish only its health, declare only a channel token, and ask only for the state and the
clock; nothing else is let in (docs/channels.md).
Payloads are bytes; what they hold is the app's business (`share.messages`, msgpack).
Zenoh calls the callbacks on its own threads.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from typing import Any

import zenoh

from wxsky.share.credentials import Credentials
from wxsky.share.errors import BusError

log = logging.getLogger(__name__)

ROLES = ("master", "channel")
QUERY_TIMEOUT_S = 1.0
MASTER_CN = "wxsky-master"  # the certificates' common names (tools/generate/dome_certs.py)
CHANNEL_CN = "wxsky-channel"


def _config(role: str, endpoint: str, site: str, credentials: Credentials | None) -> Any:
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps("peer"))
    cfg.insert_json5("scouting/multicast/enabled", "false")
    if role == "master":
        cfg.insert_json5("listen/endpoints", json.dumps([endpoint]))
    else:
        cfg.insert_json5("listen/endpoints", json.dumps([]))
        cfg.insert_json5("connect/endpoints", json.dumps([endpoint]))
    if credentials is not None:
        side = "listen" if role == "master" else "connect"
        tls = {
            "root_ca_certificate": credentials.ca_certificate,
            f"{side}_certificate": credentials.certificate,
            f"{side}_private_key": credentials.private_key,
            "enable_mtls": True,
        }
        for key, value in tls.items():
            cfg.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
        if role == "master":
            cfg.insert_json5("access_control", json.dumps(_access_control(site)))
    return cfg


def _access_control(site: str) -> dict[str, Any]:
    """What a channel's certificate may do through the master; everything else is denied."""
    root = f"wxsky/{site}"
    everything = [
        "put",
        "delete",
        "declare_subscriber",
        "query",
        "declare_queryable",
        "reply",
        "liveliness_token",
        "declare_liveliness_subscriber",
        "liveliness_query",
    ]
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": [
            {
                "id": "channel-health",
                "permission": "allow",
                "flows": ["ingress"],
                "messages": ["put"],
                "key_exprs": [f"{root}/health/*"],
            },
            {
                "id": "channel-token",
                "permission": "allow",
                "flows": ["ingress"],
                "messages": ["liveliness_token"],
                "key_exprs": [f"{root}/alive/channel/*"],
            },
            {
                "id": "channel-listen",
                "permission": "allow",
                "flows": ["ingress"],
                "messages": [
                    "declare_subscriber",
                    "declare_liveliness_subscriber",
                    "liveliness_query",
                ],
                "key_exprs": [f"{root}/**"],
            },
            {
                "id": "channel-ask",
                "permission": "allow",
                "flows": ["ingress"],
                "messages": ["query"],
                "key_exprs": [f"{root}/state", f"{root}/clock/ping"],
            },
            {
                "id": "to-channels",
                "permission": "allow",
                "flows": ["egress"],
                "messages": everything,
                "key_exprs": [f"{root}/**"],
            },
        ],
        "subjects": [{"id": "channels", "cert_common_names": [CHANNEL_CN]}],
        "policies": [
            {
                "rules": [
                    "channel-health",
                    "channel-token",
                    "channel-listen",
                    "channel-ask",
                    "to-channels",
                ],
                "subjects": ["channels"],
            }
        ],
    }


class ShareBus:
    """A daemon's Zenoh session on one site, as `role` ("master" or "channel")."""

    def __init__(
        self,
        endpoint: str,
        *,
        role: str,
        site: str,
        name: str,
        credentials: Credentials | None = None,
    ) -> None:
        if role not in ROLES:
            raise ValueError(f"role must be one of {ROLES}")
        self.endpoint = endpoint
        self.role = role
        self.site = site
        self.name = name
        self._closed = False
        self._declared: list[Any] = []
        try:
            self._session = zenoh.open(_config(role, endpoint, site, credentials))
        except zenoh.ZError as exc:
            raise BusError(f"zenoh:{endpoint}: cannot open the bus as {role}: {exc}") from None
        try:
            self._state_pub = self._session.declare_publisher(
                self.key("state"), congestion_control=zenoh.CongestionControl.BLOCK
            )
            self._clock_pub = self._session.declare_publisher(
                self.key("clock"), congestion_control=zenoh.CongestionControl.DROP, express=True
            )
            self._health_pub = self._session.declare_publisher(
                self.key("health", name), congestion_control=zenoh.CongestionControl.DROP
            )
        except BaseException:
            self._session.close()  # type: ignore[no-untyped-call]
            raise

    def key(self, *parts: str) -> str:
        return "/".join(("wxsky", self.site, *parts))

    # -- the master's side --------------------------------------------------------------

    def master_alive(self, wait_s: float = 1.0) -> bool:
        """Whether a master's token is on the site (asked for up to `wait_s`: a master there
        answers in milliseconds; a channel that just connected may need a moment)."""
        deadline = time.monotonic() + wait_s
        while True:
            replies = self._session.liveliness().get(self.key("alive", "master", "**"), timeout=0.2)
            if any(reply.ok is not None for reply in replies):
                return True
            if time.monotonic() >= deadline:
                return False

    def claim_master(self, master_id: str, wait_s: float = 0.5) -> None:
        """Declare this daemon the site's master, its token named by its run id (a channel
        takes ticks and states only from the run whose token is alive); BusError if another
        master is alive on it."""
        if self.master_alive(wait_s):
            raise BusError(
                f"zenoh:{self.endpoint}: site {self.site!r} already has a sky master; "
                "stop it or use another [share] site"
            )
        token = self._session.liveliness().declare_token(self.key("alive", "master", master_id))
        self._declared.append(token)

    def serve(self, latest_state: Callable[[], bytes | None], mono_s: Callable[[], bytes]) -> None:
        """Answer state queries with the latest state, and pings with the monotonic clock."""

        def on_state(query: Any) -> None:
            payload = latest_state()
            if payload is not None:
                query.reply(self.key("state"), payload)

        def on_ping(query: Any) -> None:
            query.reply(self.key("clock", "ping"), mono_s())

        self._declared.append(self._session.declare_queryable(self.key("state"), on_state))
        self._declared.append(self._session.declare_queryable(self.key("clock", "ping"), on_ping))

    def publish_state(self, payload: bytes) -> None:
        self._state_pub.put(payload)

    def publish_tick(self, payload: bytes) -> None:
        self._clock_pub.put(payload)

    def publish_health(self, payload: bytes) -> None:
        self._health_pub.put(payload)

    # -- a channel's side ---------------------------------------------------------------

    def announce_channel(self) -> None:
        token = self._session.liveliness().declare_token(self.key("alive", "channel", self.name))
        self._declared.append(token)

    def on_state(self, callback: Callable[[bytes], None]) -> None:
        self._subscribe(self.key("state"), callback)

    def on_tick(self, callback: Callable[[bytes], None]) -> None:
        self._subscribe(self.key("clock"), callback)

    def on_health(self, callback: Callable[[str, bytes], None]) -> None:
        def deliver(sample: Any) -> None:
            callback(str(sample.key_expr).rsplit("/", 1)[-1], sample.payload.to_bytes())

        self._declared.append(self._session.declare_subscriber(self.key("health", "*"), deliver))

    def on_master(self, callback: Callable[[str, bool], None]) -> None:
        """callback(master_id, True) when a master's token appears (or is there already),
        (master_id, False) when it goes: a master that stops, is killed or is cut off."""
        self._on_token(self.key("alive", "master", "*"), callback)

    def on_channel(self, callback: Callable[[str, bool], None]) -> None:
        """callback(name, True) when a channel's token appears (or is there already), (name,
        False) when it goes: with its session, at once for a process killed on this machine."""
        self._on_token(self.key("alive", "channel", "*"), callback)

    def _on_token(self, key: str, callback: Callable[[str, bool], None]) -> None:
        def deliver(sample: Any) -> None:
            name = str(sample.key_expr).rsplit("/", 1)[-1]
            callback(name, sample.kind == zenoh.SampleKind.PUT)

        self._declared.append(
            self._session.liveliness().declare_subscriber(key, deliver, history=True)
        )

    def fetch_state(self, timeout_s: float = QUERY_TIMEOUT_S) -> bytes | None:
        """The master's latest state, asked for (a late joiner); None without an answer."""
        return self._query(self.key("state"), timeout_s)

    def ping(self, timeout_s: float = QUERY_TIMEOUT_S) -> tuple[float, bytes, float] | None:
        """(sent, the master's answer, received) on this process's monotonic clock."""
        sent = time.monotonic()
        answer = self._query(self.key("clock", "ping"), timeout_s)
        return None if answer is None else (sent, answer, time.monotonic())

    # -- both ---------------------------------------------------------------------------

    def close(self) -> None:
        """Undeclare everything and close the session; idempotent."""
        if self._closed:
            return
        self._closed = True
        for entity in reversed(self._declared):
            try:
                entity.undeclare()
            except zenoh.ZError as exc:  # the session may already be going
                log.debug("zenoh undeclare: %s", exc)
        self._declared.clear()
        self._session.close()  # type: ignore[no-untyped-call]

    def __enter__(self) -> ShareBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _subscribe(self, key: str, callback: Callable[[bytes], None]) -> None:
        def deliver(sample: Any) -> None:
            callback(sample.payload.to_bytes())

        self._declared.append(self._session.declare_subscriber(key, deliver))

    def _query(self, key: str, timeout_s: float) -> bytes | None:
        for reply in self._session.get(key, timeout=timeout_s):
            if reply.ok is not None:
                payload: bytes = reply.ok.payload.to_bytes()
                return payload
        return None
