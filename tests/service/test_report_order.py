"""Which mission a progress report is about, when it comes while an upload may commit: the
pymavlink link holds such reports back and sorts them by the MAVLink packet sequence of the
ACK that accepted the upload (real packed and parsed MAVLink 2 messages, no socket)."""

from __future__ import annotations

from typing import Any

from pymavlink.dialects.v20 import common as M

from planner_service.service.link import Current, LinkEvent, LinkSettings, Reached
from planner_service.service.link.mavlink_link import PymavlinkLink
from planner_service.service.link.upload import MissionUpload
from protocol import GeoOrigin, HoverPoint, encode_path

ITEMS = encode_path([HoverPoint(10.0, 20.0, 50.0, 3.0), HoverPoint(60.0, 20.0, 50.0, 3.0)], GeoOrigin(), "ardupilot")


def from_vehicle(msg: Any, seq: int) -> Any:
    """``msg`` as the vehicle (1/1) sends it with packet sequence ``seq``, parsed back."""
    mav = M.MAVLink(None, srcSystem=1, srcComponent=1)
    mav.seq = seq
    return M.MAVLink(None).parse_char(msg.pack(mav))


def link_in_upload() -> tuple[PymavlinkLink, list[LinkEvent]]:
    """A link whose upload has sent its last item: the vehicle may hold either mission."""
    events: list[LinkEvent] = []
    link = PymavlinkLink(LinkSettings("udpout:127.0.0.1:9", "ardupilot"), events.append)
    link._connected.set()
    link.state.autopilot = (1, 1)
    op = MissionUpload(ITEMS, lambda _msg: None, (1, 1), 3)
    op.begin()
    for seq in range(len(ITEMS)):
        op.on_message(M.MAVLink_mission_request_int_message(255, 190, seq, M.MAV_MISSION_TYPE_MISSION))
    link._mission_op = op
    link._note_commit_possible(op)
    assert link._commit_possible
    return link, events


def kinds(events: list[LinkEvent]) -> list[tuple[str, int, int]]:
    return [("reached" if isinstance(e, Reached) else "current", e.seq, e.mission)
            for e in events if isinstance(e, (Reached, Current))]


def reached(seq: int) -> Any:
    return M.MAVLink_mission_item_reached_message(seq)


def current(seq: int) -> Any:
    return M.MAVLink_mission_current_message(seq, len(ITEMS))


def test_reports_before_the_ack_are_about_the_old_mission_and_after_it_the_new() -> None:
    link, events = link_in_upload()
    old = link.generation
    link._on_message(from_vehicle(reached(3), 199))  # the old mission's point, just before it committed
    link._on_message(from_vehicle(current(0), 200))  # either mission's (the stub announces the new one so)
    link._on_message(from_vehicle(current(1), 202))  # the new mission, overtaking the ACK
    assert kinds(events) == []  # held back: nobody can tell yet
    link._on_message(from_vehicle(M.MAVLink_mission_ack_message(255, 190, M.MAV_MISSION_ACCEPTED,
                                                                 M.MAV_MISSION_TYPE_MISSION), 201))
    assert kinds(events) == [("reached", 3, old), ("current", 1, old + 1)]
    assert link.generation == old + 1 and link.telemetry.mission_seq == 1


def test_the_sequence_wraps_at_256() -> None:
    link, events = link_in_upload()
    old = link.generation
    link._on_message(from_vehicle(reached(2), 255))
    link._on_message(from_vehicle(reached(1), 1))
    link._on_message(from_vehicle(M.MAVLink_mission_ack_message(255, 190, M.MAV_MISSION_ACCEPTED,
                                                                 M.MAV_MISSION_TYPE_MISSION), 0))
    assert [(seq, mission) for _, seq, mission in kinds(events)] == [(2, old), (1, old + 1)]


def test_without_an_ack_the_reports_are_about_the_mission_kept() -> None:
    link, events = link_in_upload()
    old = link.generation
    link._on_message(from_vehicle(reached(4), 50))
    link._commit_possible = False
    link._sort_reports(None)  # the upload failed: the vehicle kept its mission
    assert kinds(events) == [("reached", 4, old)]
    assert link.generation == old


def test_a_late_report_of_the_old_mission_keeps_its_generation() -> None:
    link, events = link_in_upload()
    old = link.generation
    link._on_message(from_vehicle(M.MAVLink_mission_ack_message(255, 190, M.MAV_MISSION_ACCEPTED,
                                                                 M.MAV_MISSION_TYPE_MISSION), 100))
    link._commit_possible = False
    link._on_message(from_vehicle(reached(3), 98))  # sent before the ACK, delayed past it
    link._on_message(from_vehicle(current(1), 99))  # either mission's: dropped
    link._on_message(from_vehicle(current(2), 102))
    assert kinds(events) == [("reached", 3, old), ("current", 2, old + 1)]
