"""Wire text made safe for a log line: no control character survives, printable text stays."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import escape_text


def test_control_characters_become_escapes() -> None:
    assert escape_text("plain text, é 中文 😀") == "plain text, é 中文 😀"
    assert escape_text("a\nb\r\x1b[31m\x00\x7f") == "a\\x0ab\\x0d\\x1b[31m\\x00\\x7f"
    assert escape_text("\u2028\u2029\u202e\u200b\x85\t") == "\\u2028\\u2029\\u202e\\u200b\\x85\\x09"
    assert escape_text("\ud800") == "\\ud800"  # a lone surrogate (from a JSON escape)
    assert escape_text("back\\x0aslash") == "back\\\\x0aslash"  # an escape cannot be faked
    assert escape_text("abcdef", limit=3) == "abc..."


@settings(max_examples=500, database=None, derandomize=True)
@given(st.text())
def test_nothing_unprintable_survives(text: str) -> None:
    out = escape_text(text)
    assert all(c == " " or c.isprintable() and not c.isspace() for c in out), out
    assert "\n" not in out and len(out.splitlines()) <= 1
