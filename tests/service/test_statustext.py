"""STATUSTEXT chunks joined (link/statustext.py), as PX4 SITL sends them."""

from __future__ import annotations

from planner_service.service.link.statustext import CUT, STALE_S, StatusTexts

FIRST = "RTL: start return at 588 m (100 m above destinatio"  # 50 characters: more follow


def test_a_single_text_comes_out_at_once_without_px4s_event_tab() -> None:
    texts = StatusTexts()
    assert texts.feed("Armed by external command\t", 6, 0, 0, now=0.0) == [("Armed by external command", 6)]


def test_chunks_of_one_id_are_joined_at_the_short_last_one() -> None:
    texts = StatusTexts()
    assert len(FIRST) == 50
    assert texts.feed(FIRST, 6, 7, 0, now=0.0) == []
    assert texts.feed("n)\t", 6, 7, 1, now=0.1) == [(FIRST + "n)", 6)]


def test_a_text_whose_last_chunk_is_lost_is_given_out_cut_never_dropped() -> None:
    texts = StatusTexts()
    texts.feed(FIRST, 4, 7, 0, now=0.0)
    assert texts.flush(now=STALE_S / 2) == []
    assert texts.flush(now=STALE_S) == [(FIRST + CUT, 4)]
    texts.feed(FIRST, 4, 8, 0, now=10.0)  # the next text begins before this one ended
    assert texts.feed("Takeoff detected", 6, 0, 0, now=10.1) == [("Takeoff detected", 6)]
    assert texts.feed("x" * 50, 6, 9, 0, now=10.2) == [(FIRST + CUT, 4)]


def test_a_lost_middle_chunk_is_marked_where_it_was() -> None:
    texts = StatusTexts()
    texts.feed("a" * 50, 6, 3, 0, now=0.0)
    assert texts.feed("end", 6, 3, 2, now=0.1) == [("a" * 50 + CUT + "end" + CUT, 6)]


def test_px4s_first_text_of_a_boot_chunked_under_id_0_is_joined() -> None:
    """PX4 numbers texts from 0 at boot: its first, when long, comes as id 0, chunks 0 and 1
    (PX4 SITL 1.18, an arm refused in its first second)."""
    first = "Arming denied: Resolve system health failures firs"
    texts = StatusTexts(id_zero_chunks=True)
    assert texts.feed(first, 2, 0, 0, now=0.0) == []
    assert texts.feed("t\t", 2, 0, 1, now=0.01) == [(first + "t", 2)]
    assert texts.feed("Preflight Fail: no heading reference", 2, 1, 0, now=0.1) == [
        ("Preflight Fail: no heading reference", 2)]
    assert texts.feed("short, id 0", 6, 0, 0, now=0.2) == [("short, id 0", 6)]  # one message: at once
    # ArduPilot's id 0 is always one message, given out at once even when 50 characters long.
    assert StatusTexts().feed(first, 2, 0, 0, now=0.0) == [(first, 2)]
