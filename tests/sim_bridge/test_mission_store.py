"""The vehicle side of the mission protocol, with a pinned clock and no sockets: PX4's
all-or-nothing upload and ArduPilot's item-by-item one."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from protocol.geodesy import GeoOrigin
from protocol.mission import HoverPoint, MissionItem, encode_path, same_items
from sim_bridge.vehicle.mission_store import MissionStore, StoreHooks
from sim_bridge.vehicle.stored_items import ardupilot_problem, ardupilot_stored, px4_problem

GCS = ("127.0.0.1", 14550)
OTHER = ("127.0.0.1", 14551)
M = mavlink
ENC = mavlink.MAVLink(None, 255, 190)
ENC_OTHER = mavlink.MAVLink(None, 254, 190)


def from_gcs(msg, enc=ENC):
    """The message as the vehicle would parse it (with source ids)."""
    return mavlink.MAVLink(None).decode(bytearray(msg.pack(enc)))


class Harness:
    def __init__(self, flavour: str = "px4", **kwargs) -> None:
        self.now = 0.0
        self.sent: list = []
        self.changes: list[tuple[int, frozenset[int]]] = []
        self.commits: list[list[MissionItem]] = []
        self.texts: list[str] = []
        self.clear_ok = True
        hooks = StoreHooks(
            problem=ardupilot_problem if flavour == "ardupilot" else px4_problem,
            stored=ardupilot_stored if flavour == "ardupilot" else (lambda item: item),
            on_change=lambda items, written: self.changes.append((len(items), written)),
            on_commit=self.commits.append,
            home_item=lambda: MissionItem(seq=0, frame=M.MAV_FRAME_GLOBAL, command=16, x=473977420, y=85455940, z=488.0),
            can_clear=lambda: self.clear_ok,
            text=lambda text, peer: self.texts.append(text),
        )
        self.store = MissionStore(lambda msg, peer: self.sent.append((msg, peer)), lambda: self.now,
                                  flavour=flavour, hooks=hooks, **kwargs)

    def give(self, msg, peer=GCS, enc=ENC) -> list:
        self.sent.clear()
        assert self.store.handle(from_gcs(msg, enc), peer)
        return [m for m, _ in self.sent]

    def tick(self, seconds: float) -> list:
        self.sent.clear()
        self.now += seconds
        self.store.tick()
        return [m for m, _ in self.sent]


def items(n: int = 3, flavour: str = "px4") -> list[MissionItem]:
    return encode_path([HoverPoint(10.0 * i, 10.0, 50.0, 1.0 + i) for i in range(n)], GeoOrigin(), flavour)


def count(n: int):
    return M.MAVLink_mission_count_message(1, 1, n, 0)


def upload(h: Harness, mission: list[MissionItem]) -> int:
    out = h.give(count(len(mission)))
    while True:
        (reply,) = out
        if reply.get_type() == "MISSION_ACK":
            return reply.type
        assert reply.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST")
        out = h.give(mission[reply.seq].to_message(1, 1))


# --- PX4: the new mission replaces the old one only when complete ---------------------------

def test_upload_and_download() -> None:
    h = Harness()
    mission = items()
    assert upload(h, mission) == M.MAV_MISSION_ACCEPTED
    assert same_items(h.store.items, mission) and same_items(h.commits[-1], mission)
    (reply,) = h.give(M.MAVLink_mission_request_list_message(1, 1, 0))
    assert reply.get_type() == "MISSION_COUNT" and reply.count == len(mission)
    (item,) = h.give(M.MAVLink_mission_request_int_message(1, 1, 2, 0))
    assert MissionItem.from_message(item).same_as(MissionItem(**{**mission[2].__dict__, "current": 0}))
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
    # Our ACK was lost and the last item comes again: PX4 repeats the ACK.
    (ack_again,) = h.give(mission[2].to_message(1, 1))
    assert ack_again.type == M.MAV_MISSION_ACCEPTED
    assert h.store.uploads_accepted == 1


def test_a_repeated_count_before_any_item_asks_again() -> None:
    h = Harness()
    mission = items()
    h.give(count(len(mission)))
    (reply,) = h.give(count(len(mission)))
    assert reply.get_type() == "MISSION_REQUEST_INT" and reply.seq == 0


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


def test_capacity_clear_and_other_mission_types() -> None:
    h = Harness(capacity=10)
    (ack,) = h.give(count(11))
    assert ack.type == M.MAV_MISSION_NO_SPACE
    upload(h, items(2))
    (ack,) = h.give(M.MAVLink_mission_clear_all_message(1, 1, 0))
    assert ack.type == M.MAV_MISSION_ACCEPTED and h.store.items == [] and h.commits[-1] == []
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


# --- ArduPilot: truncated at MISSION_COUNT, written item by item ------------------------------

def test_ardupilot_writes_each_item_as_it_arrives_and_asks_with_mission_request() -> None:
    h = Harness("ardupilot")
    old = items(3, "ardupilot")  # home, takeoff, 3 points, return: 6 items
    assert upload(h, old) == M.MAV_MISSION_ACCEPTED
    assert h.texts == ["Flight plan received"]
    assert [written for _, written in h.changes] == [frozenset({i}) for i in range(6)]
    h.changes.clear()
    new = items(1, "ardupilot")  # 4 items
    (request,) = h.give(count(len(new)))
    assert request.get_type() == "MISSION_REQUEST" and request.seq == 0  # the legacy request (id 40)
    assert h.changes == [(4, frozenset())]  # truncated at once, before any item
    h.give(new[0].to_message(1, 1))
    h.give(new[1].to_message(1, 1))
    assert h.changes[-1] == (4, frozenset({1}))
    assert h.store.items[1] == ardupilot_stored(new[1]) and h.store.items[2] == ardupilot_stored(old[2])


def test_ardupilot_an_abandoned_upload_leaves_what_was_written() -> None:
    h = Harness("ardupilot", item_timeout_s=1.0, max_retries=2)
    old = items(3, "ardupilot")
    upload(h, old)
    new = items(1, "ardupilot")
    h.give(count(len(new)))
    h.give(new[0].to_message(1, 1))
    h.give(new[1].to_message(1, 1))
    for _ in range(2):
        h.tick(1.1)
    (ack,) = h.tick(1.1)
    assert ack.type == M.MAV_MISSION_OPERATION_CANCELLED and "Mission upload timeout" in h.texts
    # The new count, the new items 0 and 1, the old items 2 and 3 (seen on SITL).
    assert [i.param1 for i in h.store.items] == [0.0, 0.0, 1.0, 2.0]
    assert h.store.items[1] == ardupilot_stored(new[1]) and h.store.items[3] == ardupilot_stored(old[3])


def test_ardupilot_protocol_answers() -> None:
    h = Harness("ardupilot")
    mission = items(2, "ardupilot")
    h.give(count(len(mission)))
    h.give(mission[0].to_message(1, 1))
    # An item out of sequence: INVALID_SEQUENCE, and the upload goes on.
    (ack,) = h.give(mission[0].to_message(1, 1))
    assert ack.type == M.MAV_MISSION_INVALID_SEQUENCE and h.store.uploading
    # Another ground station may neither upload nor download meanwhile.
    (denied,) = h.give(count(2), OTHER, ENC_OTHER)
    assert denied.type == M.MAV_MISSION_DENIED
    (busy,) = h.give(M.MAVLink_mission_request_list_message(1, 1, 0), OTHER, ENC_OTHER)
    assert busy.type == M.MAV_MISSION_DENIED
    for item in mission[1:]:
        out = h.give(item.to_message(1, 1))
    assert out[-1].type == M.MAV_MISSION_ACCEPTED
    # The last item again after the ACK: not receiving any more, ERROR (ArduPilot).
    (again,) = h.give(mission[-1].to_message(1, 1))
    assert again.type == M.MAV_MISSION_ERROR
    # Item 0 reads back as home; past the end: the real count, then ERROR.
    (home,) = h.give(M.MAVLink_mission_request_int_message(1, 1, 0, 0))
    assert (home.frame, home.x, home.z) == (M.MAV_FRAME_GLOBAL, 473977420, 488.0)
    count_msg, error = h.give(M.MAVLink_mission_request_int_message(1, 1, 9, 0))
    assert count_msg.count == len(mission) and error.type == M.MAV_MISSION_ERROR
    # No clearing while the mission runs.
    h.clear_ok = False
    (refused,) = h.give(M.MAVLink_mission_clear_all_message(1, 1, 0))
    assert refused.type == M.MAV_MISSION_ERROR and len(h.store.items) == len(mission)


def test_ardupilot_empty_mission_counts_home_once_known() -> None:
    h = Harness("ardupilot")
    (reply,) = h.give(M.MAVLink_mission_request_list_message(1, 1, 0))
    assert reply.count == 0  # before home: nothing (SITL)
    h.store.home_known()
    (reply,) = h.give(M.MAVLink_mission_request_list_message(1, 1, 0))
    assert reply.count == 1  # home is item 0 (AP_Mission::write_home_to_storage)
    assert upload(h, []) == M.MAV_MISSION_ACCEPTED
    (reply,) = h.give(M.MAVLink_mission_request_list_message(1, 1, 0))
    assert reply.count == 0  # an empty upload truncates to 0 until home is written again
