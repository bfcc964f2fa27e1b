"""Hostile payloads into the client-side decoders (what ``protocol.client`` decodes: the
request queryable's reply, status, plan, events, the state snapshot and a user's place) and the operator's
messages (the command the service decodes, the reply the operator's client does): at least 10 000
generated payloads per type. Each decoder returns a message of its type or raises
``ProtocolError`` naming a field; nothing else escapes. A decoded message holds only
finite numbers and survives a re-encode; a valid message decodes; a message with one
field perturbed is refused naming that field.
"""

from __future__ import annotations

import json
import math
import time
from typing import Any, Callable

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings

from protocol import (ErrorReply, Event, OperatorCommand, OperatorReply, Plan, ProtocolError, State, Status, TaskAck,
                      UserPlace, decode, decode_operator_command, decode_operator_reply, decode_reply, encode)
from tests.support.hostile_payloads import Case, batches, field_root

PAYLOADS = 10_000
BATCH = 10
FUZZ = settings(max_examples=PAYLOADS // BATCH, deadline=None, database=None, derandomize=True,
                suppress_health_check=list(HealthCheck))
"""derandomize: the same payloads on every run (a CI failure reproduces); no example database."""

DECODERS: dict[str, tuple[Callable[[bytes], Any], tuple[type, ...]]] = {
    "reply": (decode_reply, (TaskAck, ErrorReply)),
    "status": (lambda p: decode(p, Status), (Status,)),
    "plan": (lambda p: decode(p, Plan), (Plan,)),
    "event": (lambda p: decode(p, Event), (Event,)),
    "state": (lambda p: decode(p, State), (State,)),
    "user_place": (lambda p: decode(p, UserPlace), (UserPlace,)),
    "operator_command": (decode_operator_command, (OperatorCommand,)),
    "operator_reply": (decode_operator_reply, (OperatorReply, ErrorReply)),
}


def _printable(text: str) -> str:
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _floats(value: Any) -> list[float]:
    if isinstance(value, float):
        return [value]
    if isinstance(value, msgspec.Struct):
        return [x for name in value.__struct_fields__ for x in _floats(getattr(value, name))]
    if isinstance(value, list):
        return [x for item in value for x in _floats(item)]
    return []


def check(decoder: Callable[[bytes], Any], types: tuple[type, ...], case: Case, seen: dict[str, int]) -> None:
    seen["payloads"] += 1
    try:
        message = decoder(case.payload)
    except ProtocolError as err:
        assert err.field and err.message, case
        assert case.what != "valid", (case, err)
        if case.field is not None and len(case.payload) <= 4096:
            assert _printable(case.field) in (err.field, field_root(err.field)), (case, err)
        return
    seen["decoded"] += 1
    assert isinstance(message, types), (case, message)
    assert all(math.isfinite(x) for x in _floats(message)), (case, message)
    assert decoder(encode(message)) == message, case
    assert json.loads(case.payload)["kind"] == message.__struct_config__.tag, case


@pytest.mark.parametrize("name", list(DECODERS))
def test_client_decoders_raise_only_protocol_errors(name: str) -> None:
    decoder, types = DECODERS[name]
    kinds = {"reply": ["task_ack", "error"], "operator_reply": ["operator_reply", "error"]}.get(name, [name])
    seen = {"payloads": 0, "decoded": 0}

    @FUZZ
    @given(batches(kinds[0], BATCH // len(kinds)), batches(kinds[-1], BATCH // len(kinds)))
    def fuzz(first: list[Case], second: list[Case]) -> None:
        for case in (first + second if len(kinds) > 1 else first):
            check(decoder, types, case, seen)

    t0 = time.perf_counter()
    fuzz()
    print(f"\n{name}: {seen['payloads']} payloads ({seen['decoded']} decoded) in {time.perf_counter() - t0:.1f} s")
    assert seen["payloads"] >= PAYLOADS
    assert seen["decoded"] >= 100, "the strategies should also produce valid messages"
