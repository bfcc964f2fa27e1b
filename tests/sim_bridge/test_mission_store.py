"""The vehicle side of the mission protocol, with a pinned clock and no sockets."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from protocol.geodesy import GeoOrigin
from protocol.mission import HoverPoint, MissionItem, encode_path, same_items
from sim_bridge.vehicle.mission_store import MissionStore

GCS = ("127.0.0.1", 14550)
M = mavlink
ENC = mavlink.MAVLink(None, 255, 190)


def from_gcs(msg):
    """The message as the vehicle would parse it (with source ids)."""
    return mavlink.MAVLink(None).decode(bytearray(msg.pack(ENC)))


class Harness:
    def __init__(self, **kwargs) -> None:
        self.now = 0.0
        self.sent: list = []
        self.store = MissionStore(lambda msg, peer: self.sent.append((msg, peer)), lambda: self.now, **kwargs)

    def give(self, msg) -> list:
        self.sent.clear()
        assert self.store.handle(from_gcs(msg), GCS)
        return [m for m, _ in self.sent]

    def tick(self, seconds: float) -> list:
        self.sent.clear()
        self.now += seconds
        self.store.tick()
        return [m for m, _ in self.sent]


def items(n: int = 3) -> list[MissionItem]:
    return encode_path([HoverPoint(10.0 * i, 10.0, 50.0, 1.0) for i in range(n)], GeoOrigin(), "px4")


def count(n: int):
    return M.MAVLink_mission_count_message(1, 1, n, 0)


def upload(h: Harness, mission: list[MissionItem]) -> int:
    out = h.give(count(len(mission)))
    while True:
        (reply,) = out
        if reply.get_type() == "MISSION_ACK":
            return reply.type
        assert reply.get_type() == "MISSION_REQUEST_INT"
        out = h.give(mission[reply.seq].to_message(1, 1))


def test_upload_and_download() -> None:
    h = Harness()
    mission = items()
    assert upload(h, mission) == M.MAV_MISSION_ACCEPTED
    assert same_items(h.store.items, mission)
    (reply,) = h.give(M.MAVLink_mission_request_list_message(1, 1, 0))
    assert reply.get_type() == "MISSION_COUNT" and reply.count == len(mission)
    (item,) = h.give(M.MAVLink_mission_request_int_message(1, 1, 2, 0))
    assert MissionItem.from_message(item).same_as(mission[2])
    (legacy,) = h.give(M.MAVLink_mission_request_message(1, 1, 2, 0))
    assert legacy.get_type() == "MISSION_ITEM"
    (bad,) = h.give(M.MAVLink_mission_request_int_message(1, 1, 99, 0))
    assert bad.type == M.MAV_MISSION_INVALID_SEQUENCE


def test_a_lost_request_is_repeated_and_the_upload_then_completes() -> None:
    h = Harness(item_timeout_s=1.0, max_retries=3)
    mission = items(1)  # takeoff, waypoint, return to launch
    assert len(mission) == 3
    (first,) = h.give(count(len(mission)))
    assert h.tick(0.5) == []
    (again,) = h.tick(0.6)
    assert again.get_type() == "MISSION_REQUEST_INT" and again.seq == first.seq == 0
    out = h.give(mission[0].to_message(1, 1))
    # The ground station repeats item 0 (it missed our request for 1): ask for 1 again.
    (repeat,) = h.give(mission[0].to_message(1, 1))
    assert out[0].seq == repeat.seq == 1
    h.give(mission[1].to_message(1, 1))
    (ack,) = h.give(mission[2].to_message(1, 1))
    assert ack.type == M.MAV_MISSION_ACCEPTED
    # Our ACK was lost and the last item comes again: the ACK is repeated.
    (ack_again,) = h.give(mission[2].to_message(1, 1))
    assert ack_again.type == M.MAV_MISSION_ACCEPTED
    assert h.store.uploads_accepted == 1


def test_a_duplicated_count_does_not_restart_the_upload() -> None:
    h = Harness()
    mission = items()
    h.give(count(len(mission)))
    h.give(mission[0].to_message(1, 1))
    (reply,) = h.give(count(len(mission)))
    assert reply.seq == 1


def test_an_abandoned_upload_keeps_the_old_mission() -> None:
    h = Harness(item_timeout_s=1.0, max_retries=2)
    old = items(2)
    upload(h, old)
    h.give(count(5))
    h.give(items(5)[0].to_message(1, 1))
    assert len(h.tick(1.1)) == 1 and len(h.tick(1.1)) == 1
    (ack,) = h.tick(1.1)
    assert ack.type == M.MAV_MISSION_OPERATION_CANCELLED
    assert same_items(h.store.items, old) and not h.store.uploading


@pytest.mark.parametrize("change, result", [
    ({"command": 31000}, M.MAV_MISSION_UNSUPPORTED),
    ({"frame": M.MAV_FRAME_LOCAL_NED}, M.MAV_MISSION_UNSUPPORTED_FRAME),
    ({"z": math.inf}, M.MAV_MISSION_INVALID_PARAM7),
    ({"param1": -5.0}, M.MAV_MISSION_INVALID_PARAM1),
    ({"x": 950_000_000}, M.MAV_MISSION_INVALID_PARAM5_X),
])
def test_a_bad_item_is_refused_with_its_code_and_the_old_mission_stays(change, result) -> None:
    h = Harness()
    old = items(2)
    upload(h, old)
    new = items(4)
    new[2] = MissionItem(**{**new[2].__dict__, **change})
    assert upload(h, new) == result
    assert same_items(h.store.items, old)


def test_the_vehicle_check_refuses_the_whole_mission() -> None:
    h = Harness(check=lambda items: (M.MAV_MISSION_INVALID_PARAM6_Y, "outside") if len(items) > 4 else None)
    assert upload(h, items(2)) == M.MAV_MISSION_ACCEPTED
    assert upload(h, items(5)) == M.MAV_MISSION_INVALID_PARAM6_Y
    assert len(h.store.items) == 4


def test_capacity_clear_and_other_mission_types() -> None:
    h = Harness(capacity=10)
    (ack,) = h.give(count(11))
    assert ack.type == M.MAV_MISSION_NO_SPACE
    upload(h, items(2))
    (ack,) = h.give(M.MAVLink_mission_clear_all_message(1, 1, 0))
    assert ack.type == M.MAV_MISSION_ACCEPTED and h.store.items == []
    (fence,) = h.give(M.MAVLink_mission_count_message(1, 1, 3, M.MAV_MISSION_TYPE_FENCE))
    assert fence.type == M.MAV_MISSION_UNSUPPORTED and fence.mission_type == M.MAV_MISSION_TYPE_FENCE
    (rally,) = h.give(M.MAVLink_mission_request_list_message(1, 1, M.MAV_MISSION_TYPE_RALLY))
    assert rally.count == 0


def test_the_ground_station_can_cancel() -> None:
    h = Harness()
    h.give(count(3))
    assert h.store.uploading
    assert h.give(M.MAVLink_mission_ack_message(1, 1, M.MAV_MISSION_OPERATION_CANCELLED, 0)) == []
    assert not h.store.uploading
