"""The page's messages (docs/web.md): one JSON object `{"id", "cmd", "params"}` each, checked
here before anything acts on it, and the daemon's answers as JSON text.

A message that is not one (too long, not UTF-8, not JSON, nested too deep, not an object,
a key or command unknown, an id that is no id) raises MessageError with one line saying
what is wrong; the params are the command's own to check (`app/control.py`)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

from wxsky.errors import ProtocolError
from wxsky.logs import clip

# The largest message the page sends is a `set_weather` of every field: a few kilobytes.
MAX_MESSAGE_BYTES = 64 * 1024
# Weather is three levels deep (fog → rvr → runway); anything far deeper is no request, and
# the checkers walking it should never recurse far.
MAX_DEPTH = 8
MAX_ID = 2**53 - 1  # what JavaScript's numbers hold exactly
# The page's commands: the daemon's control commands of the same names, and two of the
# page's own (`view`: how wide it shows the picture; `presets`: the list again).
CONTROL_COMMANDS = ("apply_preset", "release", "save_preset", "set_weather", "set_time", "freeze")
PAGE_COMMANDS = ("view", "presets")
COMMANDS = CONTROL_COMMANDS + PAGE_COMMANDS
_KEYS = ("id", "cmd", "params")
_QUOTE_CHARS = 40  # how much of a bad value an error quotes


class MessageError(ProtocolError):
    """A page message that cannot be read; `id` is the message's where it had a good one."""

    def __init__(self, message: str, id: int | None = None) -> None:
        super().__init__(message)
        self.id = id


@dataclass(frozen=True)
class PageMessage:
    id: int
    cmd: str
    params: dict[str, Any]


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def _depth(value: Any) -> int:
    """How deeply `value` nests, counted without recursion."""
    deepest = 0
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            deepest = max(deepest, depth)
            stack.extend((v, depth + 1) for v in item.values())
        elif isinstance(item, list):
            deepest = max(deepest, depth)
            stack.extend((v, depth + 1) for v in item)
    return deepest


def decode_message(data: str | bytes) -> PageMessage:
    """One page message; MessageError (one line) for anything else."""
    size = len(data.encode("utf-8", "surrogatepass") if isinstance(data, str) else data)
    if size > MAX_MESSAGE_BYTES:
        raise MessageError(f"message: {size} bytes, more than {MAX_MESSAGE_BYTES}")
    if isinstance(data, bytes):
        try:
            data = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise MessageError(f"message: not UTF-8 (byte {exc.start})") from None
    try:
        value = json.loads(data, parse_constant=_reject_constant)
    except RecursionError:
        raise MessageError(f"message: nested more than {MAX_DEPTH} deep") from None
    except ValueError as exc:  # JSONDecodeError, a NaN, a lone surrogate
        raise MessageError(clip(f"message: not JSON: {exc}", 200)) from None
    if not isinstance(value, dict):
        raise MessageError(f"message: must be a JSON object, got {type(value).__name__}")
    msg_id = value.get("id")
    good_id = msg_id if isinstance(msg_id, int) and not isinstance(msg_id, bool) else None
    if good_id is None or not 0 <= good_id <= MAX_ID:
        raise MessageError(f"message: id: must be an integer 0..{MAX_ID}, got {_quote(msg_id)}")
    unknown = sorted(str(k) for k in value if k not in _KEYS)
    if unknown:
        raise MessageError(
            f"message: {clip(unknown[0], _QUOTE_CHARS)}: unknown key (known: {', '.join(_KEYS)})",
            good_id,
        )
    if _depth(value) > MAX_DEPTH:
        raise MessageError(f"message: nested more than {MAX_DEPTH} deep", good_id)
    cmd = value.get("cmd")
    if not isinstance(cmd, str) or cmd not in COMMANDS:
        raise MessageError(
            f"message: cmd: unknown command {_quote(cmd)} (known: {', '.join(COMMANDS)})",
            good_id,
        )
    params = value.get("params", {})
    if not isinstance(params, dict):
        raise MessageError(
            f"message: params: must be an object, got {type(params).__name__}", good_id
        )
    return PageMessage(good_id, cmd, params)


def _quote(value: Any) -> str:
    return clip(json.dumps(value, default=str), _QUOTE_CHARS)


def finite(value: Any) -> Any:
    """`value` with every NaN or infinity as None: the page's JSON.parse refuses them."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [finite(v) for v in value]
    return value


def to_text(message: dict[str, Any]) -> str:
    """A message for the page as JSON text (strict: non-finite numbers become null)."""
    return json.dumps(finite(message), separators=(",", ":"), allow_nan=False, default=str)


def reply(msg_id: int, result: Any) -> str:
    return to_text({"type": "reply", "id": msg_id, "ok": True, "result": result})


def reply_error(msg_id: int | None, error: str) -> str:
    if msg_id is None:
        return to_text({"type": "error", "error": clip(error, 1000)})
    return to_text({"type": "reply", "id": msg_id, "ok": False, "error": clip(error, 1000)})
