"""Text from the wire made safe to log or show on a terminal.

Anything a peer sends (a STATUSTEXT, a ``client_ref``, an event's detail, an operator's
reason, a mode name) may hold control characters: a newline forges a log line, an ESC
sequence rewrites the operator's terminal, a bidi override reverses what is read, a NUL
cuts a line short in some viewers. ``printable`` writes every such character as a visible
escape and bounds the length, so one line in is one line out.
"""

from __future__ import annotations

DEFAULT_LIMIT = 200
"""Characters kept by default: a log line stays a line."""
MIN_LIMIT = 32
"""The cut marker (``...(N chars)``) must fit."""


def _escape(ch: str) -> str:
    code = ord(ch)
    if code < 0x100:
        return f"\\x{code:02x}"
    if code < 0x10000:
        return f"\\u{code:04x}"
    return f"\\U{code:08x}"


def printable(text: object, limit: int = DEFAULT_LIMIT) -> str:
    """``text`` (any object: ``str()`` of it) with every character that is not printable
    (C0 and C1 controls, DEL, line and paragraph separators, format characters such as
    bidi overrides and zero-width ones, lone surrogates, unassigned code points) written as
    ``\\xNN``, ``\\uNNNN`` or ``\\UNNNNNNNN``, and cut to at most ``limit`` characters of
    output, ending in ``...(N chars)`` when cut (N: the input's length). The space is kept;
    every other whitespace character is escaped. A backslash is kept as it is, so that
    ``printable`` of its own output changes nothing: text escaped by the service and again
    by a client reads the same (a literal backslash-x in the input looks like an escape;
    what matters is that no control character gets through)."""
    if limit < MIN_LIMIT:
        raise ValueError(f"limit must be at least {MIN_LIMIT}, got {limit}")
    source = text if isinstance(text, str) else str(text)
    pieces: list[str] = []
    used = 0
    for ch in source:
        piece = ch if (ch == " " or ch.isprintable()) else _escape(ch)
        pieces.append(piece)
        used += len(piece)
        if used > limit:  # cut: keep what fits before the marker
            marker = f"...({len(source)} chars)"
            while pieces and used + len(marker) > limit:
                used -= len(pieces.pop())
            return "".join(pieces) + marker
    return "".join(pieces)
