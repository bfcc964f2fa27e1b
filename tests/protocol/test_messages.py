"""Message decoding: valid messages round-trip; each kind of bad input names its field."""

from __future__ import annotations

import json

import pytest

from protocol import (
    MAX_PAYLOAD_BYTES, Area, ErrorReply, Event, Keys, Plan, PlanPoint, ProtocolError, State, Status,
    TaskAck, TaskRequest, UserPlace, decode, decode_reply, decode_request, encode,
)
from protocol import PendingRequest
from protocol.messages import MAX_PLAN_BYTES, MAX_PLAN_POINTS, MAX_STATE_BYTES, MAX_TASKS

AREA = Area(side_m=500.0, max_altitude_m=150.0)


def request(**changes) -> bytes:
    body = {"kind": "task_request", "schema": 1, "user_id": "u-7", "x_m": 120.5, "y_m": 30.0, "tasks": 12}
    body.update(changes)
    return json.dumps({k: v for k, v in body.items() if v is not ...}).encode()


def refused(payload: bytes | str, kind=TaskRequest) -> ProtocolError:
    with pytest.raises(ProtocolError) as err:
        decode(payload, kind, AREA)
    return err.value


def test_a_valid_request_decodes() -> None:
    msg = decode_request(request(), AREA)
    assert msg == TaskRequest(user_id="u-7", x_m=120.5, y_m=30.0, tasks=12)
    assert msg.z_m == 0.0 and msg.schema == 1


def test_every_message_round_trips() -> None:
    status = Status(vehicle="uav1", time_s=12.5, phase="flying", armed=True, mode="AUTO", x_m=10.0,
                    y_m=20.0, z_m=100.0, battery_fraction=0.8, mission_seq=3, mission_total=9)
    plan = Plan(plan_id=4, time_s=1.0, points=[PlanPoint(10.0, 20.0, 100.0, 31.5, "u-1")], predicted_energy_j=5e4)
    messages = [
        TaskRequest(user_id="a", x_m=0.0, y_m=500.0, tasks=0, z_m=3.0, client_ref="r1"),
        TaskAck(request_id=17, user_id="a", accepted_at_s=3.5, queue_position=2, client_ref="r1"),
        ErrorReply(field="x_m", message="outside"),
        status, plan, Event(event="user_served", time_s=3.0, user_id="a", request_id=17),
        State(status=status, plan=plan),
    ]
    for msg in messages:
        assert decode(encode(msg), type(msg), AREA) == msg
    assert decode_reply(encode(messages[1])) == messages[1]
    assert decode_reply(encode(messages[2])) == messages[2]
    assert json.loads(encode(messages[0]))["kind"] == "task_request"


@pytest.mark.parametrize("payload, field", [
    (request(colour="red"), "colour"),  # unknown field
    (request(x_m="12"), "x_m"),  # wrong type
    (request(tasks=1.5), "tasks"),
    (request(user_id=""), "user_id"),
    (request(user_id="x" * 65), "user_id"),
    (request(user_id="a/b"), "user_id"),
    (request(tasks=-1), "tasks"),  # negative tasks
    (request(tasks=MAX_TASKS + 1), "tasks"),
    (request(x_m=500.5), "x_m"),  # outside the area
    (request(y_m=-0.1), "y_m"),
    (request(z_m=151.0), "z_m"),
    (request(tasks=...), "tasks"),  # missing
    (request(schema=2), "schema"),
    (request(kind="task_ack"), "kind"),
    (request(x_m=1e999), "x_m"),  # infinity as a number too large for a double
    (request().replace(b"120.5", b"NaN"), "x_m"),  # NaN, which JSON has no word for
    (request().replace(b"30.0", b"-Infinity"), "y_m"),
])
def test_bad_requests_name_the_field(payload: bytes, field: str) -> None:
    assert refused(payload).field == field


def test_oversize_payload_is_refused_before_parsing() -> None:
    payload = request(client_ref="x" * MAX_PAYLOAD_BYTES)
    assert refused(payload).field == "payload"


def test_a_state_and_a_plan_have_room_for_their_lists() -> None:
    # A state answering with the 40 requests a flood left pending is over 4096 bytes (the
    # flood test met it): the service's replies with lists are bounded by those lists.
    pending = [PendingRequest(request_id=i + 1, user_id=f"user-{i:04d}", x_m=120.0, y_m=130.0, z_m=0.0, tasks=6)
               for i in range(100)]
    points = [PlanPoint(x_m=100.0 + i, y_m=200.0, z_m=100.0, hold_s=46.0, user_id=f"user-{i:04d}")
              for i in range(MAX_PLAN_POINTS)]
    state = State(status=Status(authority_detail="x" * 256), plan=Plan(points=points), pending=pending)
    wire = encode(state)
    assert len(wire) > MAX_PAYLOAD_BYTES and len(encode(Plan(points=points))) > MAX_PAYLOAD_BYTES
    assert decode(wire, State) == state
    assert decode(encode(Plan(points=points)), Plan) == Plan(points=points)
    assert refused(b" " * (MAX_STATE_BYTES + 1), State).field == "payload"
    assert refused(b" " * (MAX_PLAN_BYTES + 1), Plan).field == "payload"
    assert refused(b" " * (MAX_PAYLOAD_BYTES + 1), Status).field == "payload"


def test_malformed_json_and_non_objects() -> None:
    assert refused(b"{not json").field == "payload"
    assert refused(b"[1, 2]").field == "payload"


def test_nested_fields_are_named_with_their_path() -> None:
    bad_point = {"kind": "plan", "points": [{"x_m": 1, "y_m": 2, "z_m": 3}, {"x_m": 1, "y_m": 600, "z_m": 3}]}
    assert refused(json.dumps(bad_point), Plan).field == "points[1].y_m"
    extra = {"kind": "plan", "points": [{"x_m": 1, "y_m": 2, "z_m": 3, "speed": 1}]}
    assert refused(json.dumps(extra), Plan).field == "points[0].speed"
    state = {"kind": "state", "status": {"kind": "status", "battery_fraction": 1.5}}
    assert refused(json.dumps(state), State).field == "status.battery_fraction"


def test_error_carries_a_readable_message() -> None:
    err = refused(request(x_m=900.0))
    assert "outside the area" in err.message and str(err).startswith("x_m:")


def test_keys() -> None:
    keys = Keys(prefix="uavmec", vehicle="uav7")
    assert [keys.request, keys.status, keys.plan, keys.events, keys.state, keys.alive] == [
        "uavmec/uav7/request", "uavmec/uav7/status", "uavmec/uav7/plan", "uavmec/uav7/events",
        "uavmec/uav7/state", "uavmec/uav7/alive",
    ]
    for bad in ("a/b", "*", "", "x y"):
        with pytest.raises(ProtocolError) as err:
            Keys(vehicle=bad)
        assert err.value.field == "vehicle"


def test_the_ack_s_optional_fields_and_the_user_place_round_trip() -> None:
    ack = TaskAck(request_id=17, user_id="a", accepted_at_s=3.5, queue_position=2, client_ref="r1", sortie=3,
                  served_tasks=12, place=2, eta_s=61.5, note="cannot be served in this sortie: no tasks to offload")
    assert decode_reply(encode(ack)) == ack
    assert decode_reply(b'{"kind": "task_ack", "request_id": 1, "user_id": "a"}') == \
        TaskAck(request_id=1, user_id="a")  # an ack without them is still one: None, None, ...
    place = UserPlace(user_id="u:1", sortie=2, plan_id=7, time_s=9.0, place=1, eta_s=0.0, request_id=4, backlog=3,
                      served_tasks=20, services=1)
    wire = encode(place)
    assert json.loads(wire)["kind"] == "user_place" and decode(wire, UserPlace) == place
    assert decode(b'{"kind": "user_place", "user_id": "u"}', UserPlace) == UserPlace(user_id="u")


@pytest.mark.parametrize("body, field", [
    ({"kind": "user_place"}, "user_id"),
    ({"kind": "user_place", "user_id": "u", "place": 0}, "place"),
    ({"kind": "user_place", "user_id": "u", "eta_s": -1.0}, "eta_s"),
    ({"kind": "user_place", "user_id": "u", "sortie": 0}, "sortie"),
    ({"kind": "user_place", "user_id": "u", "backlog": -1}, "backlog"),
    ({"kind": "user_place", "user_id": "u", "queue": 1}, "queue"),
    ('{"kind": "user_place", "user_id": "u", "eta_s": Infinity}', "eta_s"),
    ({"kind": "task_ack", "request_id": 1, "user_id": "u", "place": 0}, "place"),
    ({"kind": "task_ack", "request_id": 1, "user_id": "u", "eta_s": -0.5}, "eta_s"),
    ({"kind": "task_ack", "request_id": 1, "user_id": "u", "note": "x" * 257}, "note"),
])
def test_bad_places_name_the_field(body: dict | str, field: str) -> None:
    text = body if isinstance(body, str) else json.dumps(body)
    kind = UserPlace if '"user_place"' in text else TaskAck
    assert refused(text, kind).field == field


def test_per_user_keys() -> None:
    keys = Keys(prefix="uavmec", vehicle="uav7")
    assert keys.user_request("u:1") == "uavmec/uav7/request/u:1" and keys.user_requests == "uavmec/uav7/request/*"
    assert keys.user("u:1") == "uavmec/uav7/users/u:1" and keys.users == "uavmec/uav7/users/*"
    assert keys.request_user("uavmec/uav7/request") is None
    assert keys.request_user("uavmec/uav7/request/u:1") == "u:1"
    for bad in ("uavmec/uav7/request/*", "uavmec/uav7/request/**", "uavmec/uav7/**", "uavmec/*/request",
                "uavmec/uav7/request/a/b", "uavmec/uav8/request/u", "uavmec/uav7/request/", "uavmec/uav7/requests/u"):
        with pytest.raises(ProtocolError) as err:
            keys.request_user(bad)
        assert err.value.field == "key", bad
    for bad_user in ("a/b", "*", "", "x" * 65, "u-1\n", "$*"):
        with pytest.raises(ProtocolError) as err:
            keys.user_request(bad_user)
        assert err.value.field == "user_id"
        with pytest.raises(ProtocolError):
            keys.user(bad_user)
    assert keys.place_user("uavmec/uav7/users/u:1") == "u:1"
    assert keys.place_user("uavmec/uav7/users/*") is None and keys.place_user("uavmec/uav7/status") is None


# --- a request says what it knew was served (served_seen, sortie) ----------------------------------
def test_served_seen_and_its_sortie_are_left_out_unless_given() -> None:
    import msgspec

    from protocol.client import request_for

    plain = request_for("u-7", 120.5, 30.0, 12, client_ref="r")
    assert plain.served_seen is msgspec.UNSET and plain.sortie is msgspec.UNSET
    # the same bytes as a client that knows nothing of them: a service of any version reads it
    assert json.loads(encode(plain)) == {"kind": "task_request", "schema": 1, "user_id": "u-7", "x_m": 120.5,
                                         "y_m": 30.0, "tasks": 12, "z_m": 0.0, "client_ref": "r"}
    said = request_for("u-7", 120.5, 30.0, 12, client_ref="r", served_seen=8, sortie=2)
    assert {k: v for k, v in json.loads(encode(said)).items() if k in ("served_seen", "sortie")} == \
        {"served_seen": 8, "sortie": 2}
    assert decode_request(encode(said), AREA) == said and decode_request(encode(plain), AREA) == plain
    assert "sortie" not in json.loads(encode(request_for("u-7", 1.0, 1.0, 1, sortie=2)))  # it qualifies served_seen
    nulls = decode_request(request(served_seen=None, sortie=None), AREA)  # null: not given
    assert (nulls.seen_in(1), nulls.counted_backlog(1, 30)) == (None, 12)


@pytest.mark.parametrize("fields, sortie, served, seen, counted", [
    ({}, 1, 30, None, 12),  # not said (an older client): taken as it is
    ({"served_seen": 20}, 1, 20, 20, 12),  # nothing served since the user counted
    ({"served_seen": 20}, 1, 26, 20, 6),  # 6 served since: taken off
    ({"served_seen": 20, "sortie": 1}, 1, 26, 20, 6),
    ({"served_seen": 0}, 1, 40, 0, 0),  # more served since than it counted: nothing left
    ({"served_seen": 20, "sortie": 1}, 2, 5, 0, 7),  # its news is of sortie 1: none of sortie 2's known
    ({"served_seen": 50}, 1, 10, 50, 12),  # beyond what was served (stale, false): nothing taken off
])
def test_the_backlog_the_service_counts(fields: dict, sortie: int, served: int, seen: int | None,
                                        counted: int) -> None:
    msg = decode_request(request(**fields), AREA)
    assert (msg.seen_in(sortie), msg.counted_backlog(sortie, served)) == (seen, counted)


@pytest.mark.parametrize("payload, field", [
    (request(served_seen=-1), "served_seen"),
    (request(served_seen=2 ** 31), "served_seen"),
    (request(served_seen=True), "served_seen"),
    (request(served_seen=1.0), "served_seen"),
    (request(sortie=0), "sortie"),
    (request(sortie="1"), "sortie"),
    (request(sortie=2 ** 63), "sortie"),
])
def test_bad_served_seen_or_sortie_is_named(payload: bytes, field: str) -> None:
    assert refused(payload).field == field
