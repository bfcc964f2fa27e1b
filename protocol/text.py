"""Text from the wire, made safe for a log line or a terminal.

A client chooses its ``client_ref``, the names of the fields it sends and (through them) the
text of the error it is answered; a vehicle chooses its STATUSTEXT. Written to a log as
they came, a newline forges a log line and an escape sequence drives the terminal that
shows it. ``escape_text`` writes every character that is not plain printable text as a
Python-style escape, so one message stays one line and reads the same everywhere.
"""

from __future__ import annotations

import unicodedata

_ESCAPED_CATEGORIES = frozenset({"Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"})
"""Control, format (bidirectional overrides, zero-width), surrogate, private-use and
unassigned characters, and the line and paragraph separators."""


def _escape(char: str) -> str:
    code = ord(char)
    if code <= 0xFF:
        return f"\\x{code:02x}"
    if code <= 0xFFFF:
        return f"\\u{code:04x}"
    return f"\\U{code:08x}"


def escape_text(text: str, limit: int | None = None) -> str:
    """``text`` with every non-printable character (and the backslash, so that an escape
    cannot be faked) written as an escape; cut to ``limit`` characters (before escaping,
    marked with ``...``) when given. Printable non-ASCII text (``é``, ``中文``) stays."""
    cut = limit is not None and len(text) > limit
    if cut:
        text = text[:limit]
    out = []
    for char in text:
        if char == "\\":
            out.append("\\\\")
        elif char == " " or unicodedata.category(char) not in _ESCAPED_CATEGORIES and not char.isspace():
            out.append(char)
        else:
            out.append(_escape(char))
    return "".join(out) + ("..." if cut else "")
