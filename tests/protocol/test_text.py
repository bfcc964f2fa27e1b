"""``protocol.text.printable``: text from the wire made safe for a log line or a terminal.
Whatever comes in, what goes out has no character a terminal or a log reader would act
on, fits the limit, is unchanged by a second pass, and leaves ordinary text alone."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.text import MIN_LIMIT, printable


@pytest.mark.parametrize("text, shown", [
    ("AUTO", "AUTO"),
    ("héllo wörld 中文 \U0001f600", "héllo wörld 中文 \U0001f600"),
    ("line\nINFO forged", "line\\x0aINFO forged"),
    ("\x1b[2J\x1b]0;title\x07", "\\x1b[2J\\x1b]0;title\\x07"),
    ("tab\there\r\x00\x7f\x85", "tab\\x09here\\x0d\\x00\\x7f\\x85"),
    ("abc\u202edef\u200b\u2028", "abc\\u202edef\\u200b\\u2028"),
    ("lone \ud800 surrogate", "lone \\ud800 surrogate"),
    (b"bytes\n", "b'bytes\\n'"),  # any object: its str() (a backslash is kept)
])
def test_what_is_escaped(text: object, shown: str) -> None:
    assert printable(text) == shown


def test_long_text_is_cut_with_its_length() -> None:
    assert printable("x" * 1000, 40) == "x" * 25 + "...(1000 chars)"
    assert printable("\n" * 1000, 40) == "\\x0a" * 6 + "...(1000 chars)"  # whole escapes only
    assert printable("y" * 40, 40) == "y" * 40
    with pytest.raises(ValueError, match="at least 32"):
        printable("x", 8)


@settings(max_examples=2000, deadline=None, database=None, derandomize=True)
@given(st.text(alphabet=st.characters(), max_size=600), st.integers(MIN_LIMIT, 400))
def test_any_text_comes_out_safe_bounded_and_stable(text: str, limit: int) -> None:
    out = printable(text, limit)
    assert len(out) <= limit
    assert all(c == " " or c.isprintable() for c in out), out
    assert printable(out, limit) == out  # a second pass (service, then client) changes nothing
    if len(text) <= limit and all(c == " " or c.isprintable() for c in text):
        assert out == text
