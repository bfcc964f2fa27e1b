"""Defects the payload fuzzing found in the decoders (tests/protocol/test_message_fuzz.py),
one regression test each: every one was an uncaught exception, an unsendable error or a
payload accepted that the wire contract refuses."""

from __future__ import annotations

from typing import Any

import pytest

from protocol import (
    Area, ErrorReply, Event, Keys, Plan, ProtocolError, State, Status, TaskRequest, decode, decode_operator_command,
    decode_operator_reply, decode_reply, decode_request, encode,
)

AREA = Area(side_m=500.0, max_altitude_m=150.0)
GOOD = b'"user_id": "u-1", "x_m": 1, "y_m": 2, "tasks": 3'


def refused(payload: bytes, kind: object = TaskRequest) -> ProtocolError:
    with pytest.raises(ProtocolError) as err:
        decode(payload, kind, AREA)
    return err.value


def test_nesting_deeper_than_the_recursion_limit_is_a_protocol_error() -> None:
    # Was RecursionError from decode_reply: to find the "kind" tag of a union msgspec
    # skips the values before it, and recursed through this one. Every top-level decode
    # is now a union (the tag is required), so every decoder is tested.
    deep = b'{"x": ' + b"[" * 1500 + b"NaN" + b"]" * 1500 + b', "kind": "%s"}'
    assert len(deep) < 4096
    with pytest.raises(ProtocolError):
        decode_reply(deep % b"error")
    assert refused(deep % b"task_request").field == "payload"
    for kind, tag in ((Status, b"status"), (Plan, b"plan"), (Event, b"event"), (State, b"state")):
        assert refused(deep % tag, kind).field == "payload"


def test_a_lone_surrogate_is_named_not_reported_as_truncated() -> None:
    # msgspec says "Input data was truncated" for "\ud800"; the field is named instead.
    err = refused(b'{"kind": "task_request", ' + GOOD + b', "client_ref": "\\ud800"}')
    assert (err.field, err.message) == ("client_ref", "is not valid Unicode (a lone surrogate escape)")
    key = refused(b'{"kind": "task_request", "\\udc00x": 1}')
    assert key.field == "\\udc00x"  # written as an escape: the error can be sent back
    assert isinstance(decode_reply(encode(ErrorReply(field=key.field, message=key.message))), ErrorReply)


def test_invalid_utf8_and_unencodable_str_payloads_are_refused() -> None:
    # Were UnicodeDecodeError from msgspec (it raises that, not a DecodeError, for these
    # bytes) and UnicodeEncodeError from payload.encode("utf-8").
    assert refused('{"kind": "task_request", "user_id": "\ud800"}'.encode("utf-8", "surrogatepass")).field == "payload"
    with pytest.raises(ProtocolError) as err:
        decode('{"kind": "status", "mode": "\ud800"}', Status)
    assert err.value.field == "payload"


def test_a_trailing_newline_is_not_part_of_a_valid_user_id() -> None:
    # The pattern ended in "$", which re.search also matches before a final newline.
    err = refused(b'{"kind": "task_request", "user_id": "u-1\\n", "x_m": 1, "y_m": 2, "tasks": 3}')
    assert err.field == "user_id"
    with pytest.raises(ProtocolError) as key_err:
        Keys("uavmec", "uav1\n")
    assert key_err.value.field == "vehicle"


def test_the_kind_tag_is_required() -> None:
    # A lone tagged type did not need its tag: b"{}" read as a default Status, Plan,
    # Event or State, and a request without "kind" was accepted.
    assert refused(b"{" + GOOD + b"}").field == "kind"
    for kind in (Status, Plan, Event, State):
        assert refused(b"{}", kind).field == "kind"
    assert refused(b'{"kind": "-"}', Status).field == "kind"
    assert decode_request(b'{"kind": "task_request", ' + GOOD + b"}", AREA).tasks == 3


def test_non_utf8_encodings_are_malformed_not_a_field() -> None:
    # json.loads guesses UTF-16; the fallback named a field of a payload msgspec could not read.
    payload = '{"kind": "task_request", "x_m": NaN}'.encode("utf-16")
    assert refused(payload).field == "payload"


def test_a_duplicated_key_does_not_hide_a_nan() -> None:
    # The fallback parser kept the last of two equal keys, lost the NaN, and named no field.
    err = refused(b'{"kind": {"": NaN, "": null}}', State)
    assert (err.field, err.message) == ("kind.", "must be a finite number (NaN and Infinity are not allowed)")


def test_an_empty_key_keeps_its_place_in_the_path() -> None:
    # {"": {"0": NaN}} was named "0", as if "0" were a top-level field.
    err = refused(b'{"client_ref": null, "": {"0": NaN}}')
    assert err.field == ".0"


DUPLICATED = [
    # (payload, decoder, the key named): the last of two equal keys used to win, silently
    (b'{"kind": "operator_command", "command": "hold", "command": "start"}', decode_operator_command, "command"),
    (b'{"kind": "operator_command", "command": "hold", "comm\\u0061nd": "start"}', decode_operator_command, "command"),
    (b'{"kind": "operator_command", "\\u0063ommand": "hold", "command": "hold"}', decode_operator_command, "command"),
    (b'{"kind": "task_request", ' + GOOD + b', "tasks": 900}', lambda p: decode_request(p, AREA), "tasks"),
    (b'{"kind": "task_request", "kind": "task_request", ' + GOOD + b"}", lambda p: decode_request(p, AREA), "kind"),
    (b'{"kind": "task_ack", "request_id": 1, "user_id": "u-1", "client_ref": "mine", "client_ref": "mine"}',
     decode_reply, "client_ref"),
    (b'{"kind": "operator_reply", "command": "start", "accepted": false, "authority": "none", "phase": "idle", '
     b'"status": {"kind": "status", "mode": "AUTO", "mode": "LOITER"}}', decode_operator_reply, "status.mode"),
    (b'{"kind": "plan", "points": [{"x_m": 1, "y_m": 2, "z_m": 3}, {"x_m": 1, "y_m": 2, "z_m": 3, "z_\\u006d": 3}]}',
     lambda p: decode(p, Plan), "points[1].z_m"),
]


@pytest.mark.parametrize("payload, decoder, key", DUPLICATED)
def test_an_object_that_names_a_key_twice_is_refused_naming_it(payload: bytes, decoder: Any, key: str) -> None:
    # msgspec kept the last value: {"command": "hold", "command": "start"} ran start, while
    # another reader of the same bytes (a log, a proxy) may take hold.
    with pytest.raises(ProtocolError) as err:
        decoder(payload)
    assert (err.value.field, err.value.message) == (
        key, "is named twice in one object (a duplicate key: which value counts would be a guess)")


def test_escaped_keys_and_colons_without_a_duplicate_decode() -> None:
    # The fast check counts colons; an escaped colon (\u003a) or an escaped key sends the
    # payload to the exact check, which clears it.
    command = decode_operator_command(b'{"kind": "operator_command", "comm\\u0061nd": "hold", '
                                      b'"reason": "a\\u003ab:c", "client_ref": "x:y"}')
    assert (command.command, command.reason, command.client_ref) == ("hold", "a:b:c", "x:y")
    plan = decode(b'{"kind": "plan", "points": [{"x_m": 1, "y_m": 2, "z_m": 3}, {"x_m": 1, "y_m": 2, "z_m": 3}]}', Plan)
    assert len(plan.points) == 2  # the same key in two objects is no duplicate
