"""JSON objects that name a key twice, found at any depth.

JSON leaves a duplicate key's meaning open, and msgspec (like most parsers) keeps the last
value without a word: ``{"command": "hold", "command": "start"}`` would read as ``start``,
while another reader of the same bytes (a log, a proxy, an audit) may see ``hold``. A wire
message must mean one thing, so every decoder refuses it (msgspec has no option for it:
msgspec issue 648).

The check runs on a payload the typed decode has already read, so the bytes are valid JSON
and nested no deeper than the message types allow. It counts instead of parsing pairs in
Python, which would double the cost of a request's decode: outside strings a colon appears
only between a key and its value, once per key written, and msgspec's plain decode keeps one
key per name in each object. Re-encoded (msgspec writes a colon as it is, never escaped),
that decode holds as many colons as the payload exactly when no object lost a key: a lost
key takes its colon away, and the strings of its value can only take more away. Only an
escaped colon (``\\u003a``) could make up for one, so a payload with a ``\\u`` escape
anywhere, or whose count differs, is read once more pair by pair to find the key and name
it (or to clear it).
"""

from __future__ import annotations

import json
from typing import Any

import msgspec

from .errors import ProtocolError

_PLAIN = msgspec.json.Decoder()
_ENCODER = msgspec.json.Encoder()


def refuse_duplicate_keys(data: bytes) -> None:
    """``ProtocolError`` naming a key that one object of ``data`` names twice (of the first
    such object, depth first), as a dotted path such as ``command``, ``status.mode`` or
    ``points[1].x_m``. ``data`` must be JSON that msgspec has read."""
    if b"\\u" not in data and _ENCODER.encode(_PLAIN.decode(data)).count(b":") == data.count(b":"):
        return
    path = _first_duplicate(json.loads(data.decode("utf-8"), object_pairs_hook=_Pairs))
    if path == "":  # no message has a field without a name, but a field must be named
        raise ProtocolError("payload", "an object names the empty key twice")
    if path is not None:
        raise ProtocolError(path, "is named twice in one object (a duplicate key: which value counts would be "
                                  "a guess)")


class _Pairs(list):  # type: ignore[type-arg]
    """A JSON object as its (key, value) pairs, in order, duplicates kept."""


def _first_duplicate(value: Any) -> str | None:
    """The path of the first key named twice in one object (objects visited depth first,
    each one's keys in order), or None. The root's path is None, so that an empty key still
    shows (``{"": {"a": 1, "a": 2}}`` -> ``.a``)."""
    stack: list[tuple[str | None, Any]] = [(None, value)]
    while stack:
        path, item = stack.pop()
        if isinstance(item, _Pairs):
            seen: set[str] = set()
            children: list[tuple[str | None, Any]] = []
            for key, child in item:
                child_path = key if path is None else f"{path}.{key}"
                if key in seen:
                    return child_path
                seen.add(key)
                children.append((child_path, child))
            stack.extend(reversed(children))
        elif isinstance(item, list):
            stack.extend(reversed([(f"{path or ''}[{i}]", child) for i, child in enumerate(item)]))
    return None

