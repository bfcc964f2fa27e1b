"""Which mission a progress report is about, when it comes while an upload may commit or just
after the ACK that accepted it: the pure sequencer (``link.reports``) sorts reports by the
MAVLink packet sequence of that ACK; one test carries real packed and parsed MAVLink 2
messages through the pymavlink link's glue (no socket)."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import common as M

from planner_service.service.link import Current, LinkEvent, LinkSettings, Reached
from planner_service.service.link.mavlink_link import PymavlinkLink
from planner_service.service.link.reports import CURRENT, REACHED, Begin, Pass, ReportSequencer, sent_before


def test_sequence_numbers_compare_mod_256() -> None:
    assert sent_before(199, 201) and not sent_before(201, 199)
    assert sent_before(255, 0) and not sent_before(0, 255)
    assert not sent_before(7, 7)


def in_upload() -> ReportSequencer[str]:
    """A sequencer whose upload has sent its last item: the vehicle may hold either mission."""
    s: ReportSequencer[str] = ReportSequencer()
    s.upload_may_commit()
    return s


def test_reports_before_the_ack_are_about_the_old_mission_and_after_it_the_new() -> None:
    s = in_upload()
    assert s.on_report("reached 3", REACHED, 199, 10.0) == []  # the old mission's point, just before it committed
    assert s.on_report("current 0", CURRENT, 200, 10.0) == []  # either mission's (the stub announces the new one so)
    assert s.on_report("current 1", CURRENT, 202, 10.0) == []  # the new mission, overtaking the ACK
    assert s.on_accepted(201, 10.1, total=2) == [Pass("reached 3"), Begin(2), Pass("current 1")]
    assert s.held == [] and s.mark == (201, 10.1)


def test_the_sequence_wraps_at_256() -> None:
    s = in_upload()
    s.on_report("reached 2", REACHED, 255, 0.0)
    s.on_report("reached 1", REACHED, 1, 0.0)
    assert s.on_accepted(0, 0.0, total=5) == [Pass("reached 2"), Begin(5), Pass("reached 1")]


def test_without_an_ack_the_reports_are_about_the_mission_kept() -> None:
    s = in_upload()
    s.on_report("reached 4", REACHED, 50, 0.0)
    assert s.on_upload_ended() == [Pass("reached 4")]
    assert not s.commit_possible and s.mark is None  # no new mission began


def test_reports_after_the_ack_until_the_upload_ends_are_about_the_new_mission() -> None:
    s = in_upload()
    s.on_accepted(100, 0.0, total=2)
    assert s.on_report("current 1", CURRENT, 101, 0.0) == []
    assert s.on_upload_ended() == [Pass("current 1")]


def test_a_late_report_of_the_old_mission_keeps_its_generation() -> None:
    s = in_upload()
    s.on_accepted(100, 5.0, total=2)
    s.on_upload_ended()
    assert s.on_report("reached 3", REACHED, 98, 5.2) == [Pass("reached 3", before=True)]  # sent before the ACK
    assert s.on_report("current 1", CURRENT, 99, 5.2) == []  # either mission's: dropped, the stream repeats it
    assert s.on_report("current 2", CURRENT, 102, 5.2) == [Pass("current 2")]


def test_after_the_reorder_window_every_report_is_about_the_mission_held() -> None:
    s: ReportSequencer[str] = ReportSequencer(reorder_window_s=1.0)
    s.begin(100, 5.0)
    assert s.on_report("current 1", CURRENT, 99, 5.9) == []
    assert s.on_report("current 1", CURRENT, 99, 6.1) == [Pass("current 1")]  # a sequence number that wrapped
    assert s.mark is None


def test_a_mission_begun_without_a_message_fears_no_reordering() -> None:
    s: ReportSequencer[str] = ReportSequencer()
    s.begin(None, 0.0)  # a restart or a read-back
    assert s.on_report("reached 0", REACHED, 3, 0.0) == [Pass("reached 0")]


def test_forgotten_reports_are_never_passed_on() -> None:
    s = in_upload()
    s.on_report("reached 1", REACHED, 7, 0.0)
    s.forget()
    assert s.on_upload_ended() == []


def test_what_is_not_a_progress_report_is_refused() -> None:
    try:
        ReportSequencer().on_report("x", "HEARTBEAT", 0, 0.0)
    except ValueError as err:
        assert "HEARTBEAT" in str(err)
    else:
        raise AssertionError("a HEARTBEAT was taken for a progress report")


def from_vehicle(msg: Any, seq: int) -> Any:
    """``msg`` as the vehicle (1/1) sends it with packet sequence ``seq``, parsed back."""
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = seq
    return M.MAVLink(None).parse_char(msg.pack(mav))


def test_the_link_applies_the_decisions_to_generations_and_telemetry() -> None:
    events: list[LinkEvent] = []
    link = PymavlinkLink(LinkSettings("udpout:127.0.0.1:9", "ardupilot"), events.append)
    link.state.autopilot = (1, 1)
    old = link.generation
    link.reports.upload_may_commit()
    link.state.current_watch.expect(1)  # as upload_mission does: the upload marks item 1 current
    link._on_message(from_vehicle(M.MAVLink_mission_item_reached_message(3), 199))
    link._on_message(from_vehicle(M.MAVLink_mission_current_message(1, 2), 202))
    assert events == []
    link._apply(link.reports.on_accepted(201, 0.0, total=2))
    assert [(type(e), e.seq, e.mission) for e in events] == [(Reached, 3, old), (Current, 1, old + 1)]
    assert link.generation == old + 1 and link.telemetry.mission_seq == 1
