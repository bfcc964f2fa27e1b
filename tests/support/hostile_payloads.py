"""Hypothesis strategies of hostile zenoh payloads, and an oracle for task requests.

A payload is built as JSON *text* from fragments, not with ``json.dumps`` of a Python
value, so that it can hold what ``json.dumps`` cannot write: nesting deeper than the
interpreter's recursion limit, lone surrogate escapes, duplicate keys, a truncated tail.

Every strategy yields a ``Case``: the payload and, when exactly one field of an otherwise
valid message was perturbed, that field's path (the refusal must then name it).

The oracle (``valid_request``) decides what a valid task request is from the wire
contract in docs/PROTOCOL.md with the standard library only (json, re), independently of
msgspec and of ``protocol.messages``.
"""

from __future__ import annotations

import json
import math
import random
import re
from dataclasses import dataclass
from typing import Any, Callable, get_args

from hypothesis import strategies as st

from protocol.messages import EventKind, Phase

MAX_PAYLOAD_BYTES = 4096
MAX_COUNTER = 2 ** 31 - 1
"""The largest ``sortie`` and ``served_seen`` of a request (docs/PROTOCOL.md)."""
ID_CHARS = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789_.:-"
KINDS = ("task_request", "task_ack", "error", "status", "plan", "event", "state", "user_place", "operator_command",
         "operator_reply")
PHASES = get_args(Phase)
AUTHORITIES = ("none", "operator", "revoked")
BATTERY_SOURCES = ("autopilot", "model", "unknown")
OPERATOR_COMMANDS = ("start", "hold", "status", "hello")
LAYOUTS = {"status": 2, "state": 2, "operator_command": 3, "operator_reply": 3, "event": 2}
"""Each message type's layout version (docs/PROTOCOL.md); 1 for the others."""
EVENTS = get_args(EventKind)
"""Every event kind the wire knows (derived from the type: this list cannot drift)."""


@dataclass(frozen=True)
class Case:
    """One payload; ``field`` is the path of the one perturbed field of a valid message."""

    payload: bytes
    field: str | None = None
    what: str = ""


# --- JSON text fragments ------------------------------------------------------------------------
def dump(value: Any) -> str:
    """A Python value as JSON text (NaN and Infinity as their literals, as json does)."""
    return json.dumps(value)


SPECIAL_STRINGS = ["NaN", "nan", "Infinity", "-Infinity", "inf", "1e999", "-0", "", " ", "0", "12", "\n",
                   "\x00", "u-1\n", "a/b", "*", "**", "$", "'; DROP TABLE requests; --", "task_request"]
SPECIAL_NUMBERS = ["NaN", "Infinity", "-Infinity", "1e400", "-1e400", "1e308", "-0", "-0.0", "0.0",
                   "4.9e-324", "2.5", "1.0", "1e0", str(2 ** 31), str(2 ** 53 + 1), str(2 ** 63 - 1),
                   str(2 ** 63), str(2 ** 64), str(-(2 ** 63) - 1), "1" + "0" * 400, "-" + "9" * 60]
SURROGATES = ['"\\ud800"', '"\\udfff"', '"a\\udc00b"', '"\\ud83d"']

scalar_fragments: st.SearchStrategy[str] = st.one_of(
    st.sampled_from(["null", "true", "false"]),
    st.integers(min_value=-(2 ** 70), max_value=2 ** 70).map(dump),
    st.floats(allow_nan=True, allow_infinity=True).map(dump),
    st.sampled_from(SPECIAL_NUMBERS),
    st.sampled_from(SPECIAL_STRINGS).map(dump),
    st.sampled_from(SURROGATES),
    st.text(max_size=8).map(dump),
    # very long strings, ASCII and multi-byte (cheap: one draw for the length)
    st.tuples(st.integers(min_value=65, max_value=5000), st.sampled_from("xé\u4e2d\U0001f600\\\"")).map(
        lambda t: dump(t[1] * t[0])),
)


def _nest(depth: int, inner: str, opener: str) -> str:
    if opener == "[":
        return "[" * depth + inner + "]" * depth
    return '{"a":' * depth + inner + "}" * depth


deep_fragments: st.SearchStrategy[str] = st.builds(
    _nest, st.integers(min_value=2, max_value=1800), st.sampled_from(["1", "NaN", "null", '"\\ud800"', "[]"]),
    st.sampled_from(["[", "{"]))

container_fragments: st.SearchStrategy[str] = st.one_of(
    st.lists(scalar_fragments, max_size=4).map(lambda xs: "[" + ",".join(xs) + "]"),
    st.lists(st.tuples(st.text(max_size=6), scalar_fragments), max_size=4).map(
        lambda kv: "{" + ",".join(f"{dump(k)}:{v}" for k, v in kv) + "}"),
)

hostile_fragments: st.SearchStrategy[str] = st.one_of(scalar_fragments, container_fragments, deep_fragments)
"""Any JSON value (or a malformed one) that a field might be sent."""


# --- valid messages, as {field: JSON text} -------------------------------------------------------
# Built from a seed with random.Random, not from Hypothesis draws: a valid message has up to
# 13 fields, and at ~30-50 us per Hypothesis draw the valid part alone cost ~1 ms per payload
# (10 000 payloads x 7 types would take minutes). Hypothesis still draws every hostile part
# (which field, what goes wrong, the hostile value) and the seed.
VALID_IDS = ["a", "u-1", "U_2.b:c-d", "0", "-", ".", ":", "x" * 64, "Z9" * 32, "user.with:all_kinds-of_9"]
TEXTS = ["", "AUTO", "hello world", "é", "\u4e2d\u6587", "\U0001f600", "tab\tnew\nline", "quote\"back\\", "\x00\x1f",
         "\u2028\u2029", "x" * 256]


def _float(rng: random.Random, lo: float | None = None, hi: float | None = None) -> str:
    lo_v = -1e9 if lo is None else lo
    hi_v = 1e9 if hi is None else hi
    pick = rng.randrange(6)
    if pick == 0:
        return dump(lo_v)
    if pick == 1:
        return dump(hi_v)
    if pick == 2:
        return dump(rng.randint(int(math.ceil(lo_v)), int(hi_v)))  # an integer literal
    if pick == 3 and lo is None:
        return dump(rng.choice([-1e300, 1e300, 5e-324, -0.0]))
    return dump(rng.uniform(lo_v, hi_v))


def _id(rng: random.Random) -> str:
    if rng.random() < 0.5:
        return dump(rng.choice(VALID_IDS))
    return dump("".join(rng.choice(ID_CHARS) for _ in range(rng.randint(1, 64))))


def _text(rng: random.Random, limit: int = 256) -> str:
    return dump(rng.choice(TEXTS)[:limit])


def _count(rng: random.Random, hi: int = 10 ** 6) -> str:
    return dump(rng.choice([0, 1, hi, rng.randint(0, hi)]))


def _struct(fields: dict[str, str]) -> str:
    return "{" + ",".join(f"{dump(k)}:{v}" for k, v in fields.items()) + "}"


def _optional(rng: random.Random, fields: dict[str, str], optional: dict[str, Callable[[], str]],
              message: bool = True) -> dict[str, str]:
    for name, make in optional.items():
        if rng.random() < 0.6:
            fields[name] = make()
    if message and rng.random() < 0.5:  # messages carry it (optional); nested points do not
        fields["schema"] = str(LAYOUTS.get(json.loads(fields["kind"]), 1))
    return fields


def _plan_point(rng: random.Random) -> str:
    return _struct(_optional(rng, {"x_m": _float(rng), "y_m": _float(rng), "z_m": _float(rng)}, {
        "hold_s": lambda: _float(rng, 0.0, 1e6), "user_id": lambda: rng.choice(["null", _id(rng)])}, message=False))


def _pending(rng: random.Random) -> str:
    return _struct({"request_id": dump(rng.randint(1, 10 ** 9)),
                    "user_id": _id(rng), "x_m": _float(rng), "y_m": _float(rng), "z_m": _float(rng),
                    "tasks": _count(rng, 1000)})


def _list(rng: random.Random, make: Callable[[random.Random], str], most: int = 3) -> str:
    return "[" + ",".join(make(rng) for _ in range(rng.randint(0, most))) + "]"


def valid_message(kind: str, rng: random.Random, side_m: float = 500.0, max_alt_m: float = 120.0) -> dict[str, str]:
    """A valid message of ``kind`` as {field: JSON text}, ``kind`` first."""
    f: dict[str, str] = {"kind": dump(kind)}
    if kind == "task_request":
        f.update(user_id=_id(rng), x_m=_float(rng, 0.0, side_m), y_m=_float(rng, 0.0, side_m), tasks=_count(rng, 1000))
        return _optional(rng, f, {"z_m": lambda: _float(rng, 0.0, max_alt_m),
                                  "client_ref": lambda: rng.choice(["null", _text(rng, 64), _id(rng)]),
                                  "served_seen": lambda: rng.choice(["null", _count(rng, MAX_COUNTER)]),
                                  "sortie": lambda: rng.choice(["null", dump(rng.randint(1, 10)),
                                                                dump(MAX_COUNTER)])})
    if kind == "task_ack":
        f.update(request_id=dump(rng.randint(1, 10 ** 9)), user_id=_id(rng))
        return _optional(rng, f, {"accepted_at_s": lambda: _float(rng), "queue_position": lambda: _count(rng),
                                  "client_ref": lambda: rng.choice(["null", _text(rng, 64)]),
                                  "sortie": lambda: rng.choice(["null", dump(rng.randint(1, 10 ** 6))]),
                                  "served_tasks": lambda: rng.choice(["null", _count(rng)]),
                                  "place": lambda: rng.choice(["null", dump(rng.randint(1, 200))]),
                                  "eta_s": lambda: rng.choice(["null", _float(rng, 0.0, 1e6)]),
                                  "note": lambda: _text(rng)})
    if kind == "error":
        f.update(field=_text(rng), message=_text(rng))
        return _optional(rng, f, {"client_ref": lambda: rng.choice(["null", _text(rng, 64)])})
    if kind == "status":
        return _optional(rng, f, {
            "vehicle": lambda: _text(rng), "time_s": lambda: _float(rng), "phase": lambda: dump(rng.choice(PHASES)),
            "armed": lambda: rng.choice(["true", "false"]), "mode": lambda: _text(rng), "x_m": lambda: _float(rng),
            "y_m": lambda: _float(rng), "z_m": lambda: _float(rng),
            "battery_fraction": lambda: rng.choice(["null", _float(rng, 0.0, 1.0)]),
            "mission_seq": lambda: _count(rng), "mission_total": lambda: _count(rng),
            "pending_requests": lambda: _count(rng), "served_users": lambda: _count(rng),
            "authority": lambda: dump(rng.choice(AUTHORITIES)), "authority_detail": lambda: _text(rng),
            "battery_source": lambda: dump(rng.choice(BATTERY_SOURCES)),
            "position_ok": lambda: rng.choice(["true", "false"]), "waiting_for": lambda: _text(rng),
            "degraded": lambda: _text(rng)})
    if kind == "operator_command":
        f.update(command=dump(rng.choice(OPERATOR_COMMANDS)))
        return _optional(rng, f, {"reason": lambda: _text(rng),
                                  "client_ref": lambda: rng.choice(["null", _text(rng, 64), _id(rng)]),
                                  "sent_at_ms": lambda: rng.choice(["null", str(rng.randrange(0, 2 ** 53))]),
                                  "proof": lambda: rng.choice(["null", dump(rng.randbytes(32).hex())]),
                                  "nonce": lambda: rng.choice(["null", dump(rng.randbytes(16).hex())])})
    if kind == "operator_reply":
        f.update(command=dump(rng.choice(OPERATOR_COMMANDS)), accepted=rng.choice(["true", "false"]),
                 authority=dump(rng.choice(AUTHORITIES)), phase=dump(rng.choice(PHASES)))
        return _optional(rng, f, {"message": lambda: _text(rng),
                                  "client_ref": lambda: rng.choice(["null", _text(rng, 64)]),
                                  "status": lambda: rng.choice(["null", _struct(valid_message("status", rng))]),
                                  "nonce": lambda: rng.choice(["null", dump(rng.randbytes(16).hex())])})
    if kind == "plan":
        return _optional(rng, f, {"plan_id": lambda: _count(rng), "time_s": lambda: _float(rng),
                                  "predicted_energy_j": lambda: _float(rng, 0.0, 1e9),
                                  "points": lambda: _list(rng, _plan_point)})
    if kind == "event":
        return _optional(rng, f, {"event": lambda: dump(rng.choice(EVENTS)), "time_s": lambda: _float(rng),
                                  "user_id": lambda: rng.choice(["null", _id(rng)]),
                                  "request_id": lambda: rng.choice(["null", dump(rng.randint(1, 10 ** 9))]),
                                  "detail": lambda: _text(rng)})
    if kind == "state":
        return _optional(rng, f, {"status": lambda: _struct(valid_message("status", rng)),
                                  "plan": lambda: rng.choice(["null", _struct(valid_message("plan", rng))]),
                                  "pending": lambda: _list(rng, _pending)})
    if kind == "user_place":
        f.update(user_id=_id(rng))
        return _optional(rng, f, {"sortie": lambda: dump(rng.randint(1, 10 ** 6)), "plan_id": lambda: _count(rng),
                                  "time_s": lambda: _float(rng),
                                  "place": lambda: rng.choice(["null", dump(rng.randint(1, 200))]),
                                  "eta_s": lambda: rng.choice(["null", _float(rng, 0.0, 1e6)]),
                                  "request_id": lambda: rng.choice(["null", dump(rng.randint(1, 10 ** 9))]),
                                  "backlog": lambda: _count(rng), "served_tasks": lambda: _count(rng),
                                  "services": lambda: _count(rng)})
    raise ValueError(f"unknown kind {kind!r}")


seeds = st.integers(min_value=0, max_value=2 ** 32)


# --- hostile payloads of one kind -----------------------------------------------------------------
@st.composite
def near_valid(draw: st.DrawFn, kind: str) -> Case:
    """A valid message with one field replaced, removed or added, or the message itself."""
    fields = valid_message(kind, random.Random(draw(seeds)))
    how = draw(st.sampled_from(["valid", "replace", "replace", "remove", "unknown", "kind"]))
    names = list(fields)
    if how == "valid":
        return Case(_struct(fields).encode(), None, "valid")
    if how == "replace":
        name = draw(st.sampled_from(names))
        fields[name] = draw(hostile_fragments)
        return Case(_struct(fields).encode("utf-8", "surrogatepass"), name, "replace")
    if how == "remove":
        name = draw(st.sampled_from(names))
        del fields[name]
        return Case(_struct(fields).encode(), name, "remove")
    if how == "kind":
        fields["kind"] = draw(st.one_of(st.sampled_from(KINDS).map(dump), hostile_fragments))
        # Another message's kind turns the other fields into the culprits (a union decoder
        # then names one of them): only a kind that is no message's must be named itself.
        other = fields["kind"] in [dump(k) for k in KINDS]
        return Case(_struct(fields).encode("utf-8", "surrogatepass"), None if other else "kind", "kind")
    name = draw(st.one_of(st.sampled_from(["colour", "X_M", "x_m ", "schema2", "kind\n", "a.b", "c[0]", "`", "` - at `$.x_m"]),
                          st.text(min_size=1, max_size=6)).filter(lambda n: n not in fields))
    fields[name] = draw(hostile_fragments)
    return Case(_struct(fields).encode("utf-8", "surrogatepass"), name, "unknown")


@st.composite
def mangled(draw: st.DrawFn, kind: str) -> Case:
    """A valid message spoiled as a whole: truncated, padded past the size limit, in
    another encoding, with trailing bytes, a BOM, a duplicated key, inside an array."""
    text = _struct(valid_message(kind, random.Random(draw(seeds))))
    data = text.encode()
    how = draw(st.sampled_from(["truncate", "pad", "utf16", "trailing", "bom", "duplicate", "wrapped", "flip"]))
    if how == "truncate":
        data = data[:draw(st.integers(0, max(len(data) - 1, 0)))]
    elif how == "pad":
        data = data + b" " * draw(st.integers(max(MAX_PAYLOAD_BYTES - len(data) - 2, 0), MAX_PAYLOAD_BYTES + 50))
    elif how == "utf16":
        data = text.encode(draw(st.sampled_from(["utf-16", "utf-16-le", "utf-32"])))
    elif how == "trailing":
        data = data + draw(st.binary(min_size=1, max_size=8))
    elif how == "bom":
        data = b"\xef\xbb\xbf" + data
    elif how == "duplicate":
        data = (text[:-1] + "," + dump(draw(st.sampled_from(["kind", "schema", "x_m", "user_id", "status"]))) + ":"
                + draw(hostile_fragments) + "}").encode("utf-8", "surrogatepass")
    elif how == "wrapped":
        data = ("[" + text + "]").encode()
    else:
        i = draw(st.integers(0, len(data) - 1))
        data = data[:i] + bytes([data[i] ^ (1 << draw(st.integers(0, 7)))]) + data[i + 1:]
    return Case(data, None, how)


@st.composite
def random_object(draw: st.DrawFn, kind: str) -> Case:
    """A JSON object of known and unknown keys with hostile values."""
    known = sorted(valid_message(kind, random.Random(0)))
    keys = draw(st.lists(st.one_of(st.sampled_from(known), st.text(max_size=6)), max_size=4, unique=True))
    body = {k: draw(hostile_fragments) for k in keys}
    if draw(st.booleans()):
        body["kind"] = dump(kind)
    return Case(_struct(body).encode("utf-8", "surrogatepass"), None, "object")


def payloads(kind: str) -> st.SearchStrategy[Case]:
    """Every kind of hostile payload for a message of ``kind``."""
    return st.one_of(
        st.binary(max_size=200).map(lambda b: Case(b, None, "bytes")),
        st.integers(MAX_PAYLOAD_BYTES - 8, MAX_PAYLOAD_BYTES + 8).map(lambda n: Case(b"{" * n, None, "huge")),
        hostile_fragments.map(lambda f: Case(f.encode("utf-8", "surrogatepass"), None, "value")),
        random_object(kind),
        mangled(kind),
        near_valid(kind),
        near_valid(kind),
    )


def batches(kind: str, size: int) -> st.SearchStrategy[list[Case]]:
    """``size`` payloads per Hypothesis example: the engine's per-example cost is paid
    once per batch, and the failing payload is named in the assertion."""
    return st.lists(payloads(kind), min_size=size, max_size=size)


# --- the oracle -----------------------------------------------------------------------------------
_USER_ID = re.compile(r"[A-Za-z0-9_.:\-]{1,64}")
REQUEST_FIELDS = frozenset({"kind", "schema", "user_id", "x_m", "y_m", "tasks", "z_m", "client_ref", "served_seen",
                            "sortie"})


def _within(value: Any, hi: float) -> bool:
    """A JSON number (not a bool), finite as a float, in [0, hi]."""
    if not isinstance(value, (int, float)) or isinstance(value, bool):
        return False
    try:
        number = float(value)
    except OverflowError:  # an integer beyond the float range
        return False
    return math.isfinite(number) and 0.0 <= number <= hi


def _unicode(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


class _DuplicateKey(ValueError):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    keys = [k for k, _ in pairs]
    if len(set(keys)) != len(keys):
        raise _DuplicateKey("duplicate key")  # an object that names a key twice is refused
    return dict(pairs)


def valid_request(payload: bytes, side_m: float, max_alt_m: float) -> dict[str, Any] | None:
    """The request's fields if ``payload`` is a valid task request (docs/PROTOCOL.md), else
    None (an object that names a key twice, at any depth, is not valid)."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        return None
    try:
        text = payload.decode("utf-8")
    except UnicodeDecodeError:
        return None
    if text[:1] == "\ufeff":
        return None
    non_finite = []
    try:
        data = json.loads(text, parse_constant=lambda c: non_finite.append(c), object_pairs_hook=_no_duplicates)
    except RecursionError:
        return None
    except (json.JSONDecodeError, _DuplicateKey):
        return None
    if non_finite or not isinstance(data, dict) or set(data) - REQUEST_FIELDS:
        return None
    if data.get("kind") != "task_request":
        return None
    schema = data.get("schema", 1)
    if not isinstance(schema, int) or isinstance(schema, bool) or schema != 1:
        return None
    user = data.get("user_id")
    if not isinstance(user, str) or not _USER_ID.fullmatch(user):
        return None
    for name, hi, required in (("x_m", side_m, True), ("y_m", side_m, True), ("z_m", max_alt_m, False)):
        if name not in data and not required:
            continue
        if not _within(data.get(name), hi):
            return None
    tasks = data.get("tasks")
    if not isinstance(tasks, int) or isinstance(tasks, bool) or not 0 <= tasks <= 1000:
        return None
    ref = data.get("client_ref")
    if ref is not None and (not isinstance(ref, str) or len(ref) > 64 or not _unicode(ref)):
        return None
    counters = {}
    for name, lo in (("served_seen", 0), ("sortie", 1)):  # optional; null is not given
        value = data.get(name)
        if value is not None and (not isinstance(value, int) or isinstance(value, bool)
                                  or not lo <= value <= MAX_COUNTER):
            return None
        counters[name] = value
    return {"user_id": user, "x_m": float(data["x_m"]), "y_m": float(data["y_m"]),
            "z_m": float(data.get("z_m", 0.0)), "tasks": tasks, "client_ref": ref, **counters}


def field_root(path: str) -> str:
    """The top-level field of a dotted path: ``points[1].x_m`` -> ``points``."""
    return re.split(r"[.\[]", path, maxsplit=1)[0]
