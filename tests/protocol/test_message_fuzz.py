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
import random
import time
from typing import Any, Callable

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings

from protocol import (Area, ErrorReply, Event, OperatorCommand, OperatorReply, Plan, ProtocolError, State, Status,
                      TaskAck, UserPlace, decode, decode_operator_command, decode_operator_reply, decode_reply,
                      decode_request, encode)
from tests.support.hostile_payloads import KINDS, Case, batches, field_root, seeds, valid_message

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


# --- duplicate keys --------------------------------------------------------------------------------
AREA = Area(side_m=500.0, max_altitude_m=120.0)  # valid_message's bounds
DUPLICATES = 300
"""Valid messages per type with one key named twice (and as many with their keys escaped)."""
EVERY_DECODER: dict[str, Callable[[bytes], Any]] = {
    **{name: decoder for name, (decoder, _) in DECODERS.items()},
    "task_request": lambda p: decode_request(p, AREA),
    "task_ack": decode_reply, "error": decode_reply,
}


class _Object(list):  # type: ignore[type-arg]
    """A JSON object as its (key, value) pairs."""


def _objects(value: Any, path: str | None = None) -> list[tuple[str | None, _Object]]:
    """Every object of a parsed message with its path, as the decoders write paths."""
    found: list[tuple[str | None, _Object]] = []
    if isinstance(value, _Object):
        found.append((path, value))
        for key, child in value:
            found += _objects(child, key if path is None else f"{path}.{key}")
    elif isinstance(value, list):
        for i, child in enumerate(value):
            found += _objects(child, f"{path or ''}[{i}]")
    return found


def _written(value: Any, rng: random.Random | None) -> str:
    """JSON text of a parsed message; with ``rng``, a key's characters now and then written
    as \\u escapes (``"comm\\u0061nd"``), as any JSON writer may."""
    if isinstance(value, _Object):
        return "{" + ",".join(f"{_key(k, rng)}:{_written(v, rng)}" for k, v in value) + "}"
    if isinstance(value, list):
        return "[" + ",".join(_written(v, rng) for v in value) + "]"
    return json.dumps(value)


def _key(key: str, rng: random.Random | None) -> str:
    if rng is None or rng.random() < 0.7:
        return json.dumps(key)
    return '"' + "".join(f"\\u{ord(c):04x}" if rng.random() < 0.3 else c for c in key) + '"'


@pytest.mark.parametrize("kind", KINDS)
def test_a_key_named_twice_at_any_depth_is_refused_naming_it(kind: str) -> None:
    decoder = EVERY_DECODER[kind]
    limit = {"plan": 64 * 1024, "state": 4 * 1024 * 1024}.get(kind, 4096)
    counts = {"refused": 0, "nested": 0, "counted": 0}

    @settings(max_examples=DUPLICATES, deadline=None, database=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(seeds)
    def check(seed: int) -> None:
        rng = random.Random(seed)
        text = "{" + ",".join(f"{json.dumps(k)}:{v}" for k, v in valid_message(kind, rng).items()) + "}"
        message = decoder(text.encode())
        tree = json.loads(text, object_pairs_hook=_Object)
        escaped = _written(tree, rng).encode()
        assert decoder(escaped) == message, escaped  # escaped keys are the same keys
        path, obj = rng.choice([(p, o) for p, o in _objects(tree) if o])
        key, value = rng.choice(obj)
        obj.insert(rng.randint(0, len(obj)), (key, value))  # the same key, and the same value
        payload = _written(tree, rng if rng.random() < 0.5 else None).encode()
        if len(payload) > limit:
            return
        counts["counted"] += b"\\u" not in payload  # cleared or refused by the count alone
        with pytest.raises(ProtocolError) as err:
            decoder(payload)
        assert err.value.field == (key if path is None else f"{path}.{key}"), payload
        assert err.value.message.startswith("is named twice in one object"), payload
        counts["refused"] += 1
        counts["nested"] += path is not None

    check()
    assert counts["refused"] >= DUPLICATES * 0.9
    assert counts["counted"] >= 15, "payloads without escapes: the fast check's own verdict"
    if kind in ("operator_reply", "plan", "state"):
        assert counts["nested"] >= 10, "duplicates inside nested objects too"
