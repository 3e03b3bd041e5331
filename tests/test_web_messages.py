"""The page's message decoder (wxsky/web/messages.py): what it takes, and a one-line error
naming what is wrong with anything else."""

from __future__ import annotations

import json

import pytest

from wxsky.web.messages import (
    MAX_DEPTH,
    MAX_MESSAGE_BYTES,
    MessageError,
    decode_message,
    finite,
    reply,
    reply_error,
    to_text,
)


def test_a_command_with_params_is_read() -> None:
    msg = decode_message(
        json.dumps({"id": 7, "cmd": "set_weather", "params": {"visibility_m": 800}})
    )
    assert (msg.id, msg.cmd, msg.params) == (7, "set_weather", {"visibility_m": 800})


def test_params_may_be_left_out_and_bytes_are_read_as_utf8() -> None:
    msg = decode_message(b'{"id": 0, "cmd": "presets"}')
    assert (msg.id, msg.cmd, msg.params) == (0, "presets", {})


@pytest.mark.parametrize(
    ("data", "says", "msg_id"),
    [
        ("{bad", "not JSON", None),
        ("[1, 2]", "must be a JSON object, got list", None),
        ('"hello"', "must be a JSON object, got str", None),
        ('{"cmd": "release"}', "id: must be an integer", None),
        ('{"id": -1, "cmd": "release"}', "id: must be an integer", None),
        ('{"id": true, "cmd": "release"}', "id: must be an integer", None),
        ('{"id": 1.5, "cmd": "release"}', "id: must be an integer", None),
        ('{"id": 9007199254740992, "cmd": "release"}', "id: must be an integer", None),
        ('{"id": 3, "cmd": "status"}', 'cmd: unknown command "status"', 3),
        ('{"id": 3, "cmd": 5}', "cmd: unknown command 5", 3),
        ('{"id": 3, "cmd": "release", "extra": 1}', "extra: unknown key", 3),
        ('{"id": 3, "cmd": "release", "params": [1]}', "params: must be an object, got list", 3),
        ('{"id": 3, "cmd": "release", "params": {"x": NaN}}', "not JSON", None),
        ('{"id": 3, "cmd": "release", "params": {"x": Infinity}}', "not JSON", None),
        (b'{"id": 3, "cmd": "\xff"}', "not UTF-8 (byte 18)", None),
    ],
)
def test_a_message_that_is_none_is_one_line_naming_what(
    data: str | bytes, says: str, msg_id: int | None
) -> None:
    with pytest.raises(MessageError) as caught:
        decode_message(data)
    text = str(caught.value)
    assert says in text
    assert "\n" not in text
    assert caught.value.id == msg_id


def test_too_long_a_message_is_refused_by_its_size_before_reading_it() -> None:
    data = json.dumps({"id": 1, "cmd": "set_weather", "params": {"x": "a" * MAX_MESSAGE_BYTES}})
    with pytest.raises(MessageError, match=f"more than {MAX_MESSAGE_BYTES}"):
        decode_message(data)


def test_deep_nesting_is_refused_whether_json_could_read_it_or_not() -> None:
    shallow_enough = {"id": 1, "cmd": "set_weather", "params": {"a": [[[[[1]]]]]}}
    decode_message(json.dumps(shallow_enough))
    too_deep = (
        '{"id": 1, "cmd": "set_weather", "params": ' + "[" * MAX_DEPTH + "]" * MAX_DEPTH + "}"
    )
    with pytest.raises(MessageError, match="nested more than"):
        decode_message(too_deep)
    # Deeper than Python's own recursion limit, within the size limit.
    abyss = "[" * 30_000 + "]" * 30_000
    with pytest.raises(MessageError, match=r"nested more than|not JSON"):
        decode_message(abyss)


def test_huge_integers_are_no_json_the_decoder_hangs_on() -> None:
    with pytest.raises(MessageError, match="not JSON"):
        decode_message('{"id": ' + "9" * 50_000 + ', "cmd": "release"}')


def test_answers_are_strict_json_with_no_nan() -> None:
    text = to_text({"type": "view", "fps": float("nan"), "rows": [float("inf"), 1.0]})
    assert json.loads(text) == {"type": "view", "fps": None, "rows": [None, 1.0]}
    assert finite((1.0, float("-inf"))) == [1.0, None]
    assert json.loads(reply(4, {"ok": 1})) == {
        "type": "reply",
        "id": 4,
        "ok": True,
        "result": {"ok": 1},
    }
    assert json.loads(reply_error(4, "set_weather: bad")) == {
        "type": "reply",
        "id": 4,
        "ok": False,
        "error": "set_weather: bad",
    }
    assert json.loads(reply_error(None, "message: not JSON")) == {
        "type": "error",
        "error": "message: not JSON",
    }
