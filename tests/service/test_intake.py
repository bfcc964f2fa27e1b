"""Intake with a pinned clock: a good request is journalled then acked; each bad one is
refused naming its field and changes nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from planner_service.service.intake import Accepted, Intake, Rejected
from planner_service.service.journal import Journal
from protocol import Area

NOW = 1_732_312_000.5


def make(tmp_path: Path) -> tuple[Intake, Journal]:
    journal = Journal(tmp_path / "j.sqlite")
    return Intake(journal, Area(500.0, 120.0, 10.0), clock=lambda: NOW), journal


def request(**fields: object) -> bytes:
    base = {"kind": "task_request", "schema": 1, "user_id": "u-7", "x_m": 120.5, "y_m": 30.0, "tasks": 12,
            "client_ref": "my-42"}
    base.update(fields)
    return json.dumps({k: v for k, v in base.items() if v is not None}).encode()


def test_accept_then_ack(tmp_path: Path) -> None:
    intake, journal = make(tmp_path)
    out = intake.handle(request())
    assert isinstance(out, Accepted)
    assert (out.reply.request_id, out.reply.accepted_at_s, out.reply.queue_position, out.reply.client_ref) == \
        (1, NOW, 1, "my-42")
    row = journal.request(1)
    assert row is not None and (row.user_id, row.x_m, row.tasks, row.accepted_at_s) == ("u-7", 120.5, 12, NOW)
    again = intake.handle(request(tasks=3, client_ref="my-43"))
    assert isinstance(again, Accepted) and again.replaced == (1,) and again.reply.queue_position == 1


@pytest.mark.parametrize("payload, field", [
    (b"not json", "payload"),
    (request(x_m=900.0), "x_m"),
    (request(tasks=-1), "tasks"),
    (request(tasks=5000), "tasks"),
    (request(user_id="a/b"), "user_id"),
    (request(extra=1), "extra"),
    (request(schema=2), "schema"),
    (request(user_id=None), "user_id"),
    (request(served_seen=-1), "served_seen"),
    (request(served_seen=2 ** 31), "served_seen"),
    (request(served_seen=1.5), "served_seen"),
    (request(served_seen="3"), "served_seen"),
    (request(served_seen=3, sortie=0), "sortie"),
    (request(served_seen=3, sortie=True), "sortie"),
    (b'{"kind": "task_request", "user_id": "u", "x_m": NaN, "y_m": 1, "tasks": 1}', "x_m"),
    (b"{" + b" " * 5000 + b"}", "payload"),
    (None, "payload"),
])
def test_bad_requests_change_nothing(tmp_path: Path, payload: bytes | None, field: str) -> None:
    intake, journal = make(tmp_path)
    intake.handle(request())
    before = journal.requests()
    out = intake.handle(payload)
    assert isinstance(out, Rejected) and out.reply.field == field, out
    assert out.reply.message
    assert journal.requests() == before


def test_closed_intake_refuses_with_the_reason(tmp_path: Path) -> None:
    intake, journal = make(tmp_path)
    intake.closed_reason = "the service is shutting down"
    out = intake.handle(request())
    assert isinstance(out, Rejected) and out.reply.field == "service"
    assert out.reply.message == "the service is shutting down" and out.reply.client_ref == "my-42"
    assert journal.requests() == []


# --- requests as data waiting (issue 13.1) -----------------------------------------------------
def test_a_newer_request_is_the_backlog_in_force_and_the_older_stays_as_history(tmp_path: Path) -> None:
    intake, journal = make(tmp_path)
    first = intake.handle(request(tasks=12, client_ref="a"))
    second = intake.handle(request(tasks=15, x_m=130.0, client_ref="b"))
    assert isinstance(first, Accepted) and isinstance(second, Accepted)
    assert (second.request_id, second.replaced, second.reply.request_id) == (2, (1,), 2)
    assert [(r.request_id, r.status, r.tasks, r.reason) for r in journal.requests()] == [
        (1, "replaced", 12, "replaced by request 2"), (2, "pending", 15, "")]
    in_force = journal.request_in_force("u-7")
    assert in_force is not None and (in_force.request_id, in_force.x_m, in_force.backlog) == (2, 130.0, 15)


def test_a_request_of_no_tasks_ends_the_wait(tmp_path: Path) -> None:
    intake, journal = make(tmp_path)
    intake.handle(request(tasks=12))
    done = intake.handle(request(tasks=0, client_ref="done"))
    assert isinstance(done, Accepted) and done.done and done.replaced == (1,)
    assert done.reply.queue_position == 0 and done.reply.note == "cannot be served in this sortie: no tasks to offload"
    assert journal.pending() == []
    row = journal.request(done.request_id)
    assert row is not None and (row.status, row.reason) == ("not_served", "no tasks to offload")
    assert journal.request(1).status == "replaced"  # type: ignore[union-attr]


def test_the_ack_says_the_sortie_what_was_served_and_the_place(tmp_path: Path) -> None:
    from planner_service.service.places import Place

    intake, journal = make(tmp_path)
    first = intake.handle(request(tasks=20))
    assert isinstance(first, Accepted)
    assert (first.reply.sortie, first.reply.served_tasks, first.reply.place, first.reply.eta_s, first.reply.note) == \
        (1, 0, None, None, "")
    journal.record_service(first.request_id, 3, (1.0, 2.0, 100.0), 12, 1.2e6, 0.3, 9e4, NOW)
    intake.set_places({"u-7": Place(2, 95.5), "u-8": Place(1, 10.0)})
    second = intake.handle(request(tasks=14))
    assert isinstance(second, Accepted)
    assert (second.reply.served_tasks, second.reply.place, second.reply.eta_s) == (12, 2, 95.5)
    intake.new_sortie()  # a new plan is needed before a place is known again
    assert intake.handle(request(tasks=3)).reply.place is None  # type: ignore[union-attr]


# --- a user's own request key binds its user id (issue 14.5) ------------------------------------
@pytest.mark.parametrize("key, outcome, field", [
    ("uavmec/uav1/request", Accepted, None),
    ("uavmec/uav1/request/u-7", Accepted, None),
    ("uavmec/uav1/request/u-8", Rejected, "user_id"),
    ("uavmec/uav1/request/*", Rejected, "key"),
    ("uavmec/uav1/request/**", Rejected, "key"),
    ("uavmec/uav1/**", Rejected, "key"),
    ("uavmec/*/request", Rejected, "key"),
    ("uavmec/uav2/request/u-7", Rejected, "key"),
])
def test_the_request_key_binds_the_user_id(tmp_path: Path, key: str, outcome: type, field: str | None) -> None:
    intake, journal = make(tmp_path)
    out = intake.handle(request(), key)
    assert isinstance(out, outcome), out
    if isinstance(out, Rejected):
        assert out.reply.field == field and out.reply.client_ref == "my-42"
        assert journal.requests() == []
    if field == "user_id":
        assert out.reply.message == ("this request key is user u-8's (uavmec/uav1/request/u-8); "  # type: ignore[union-attr]
                                     "a request on it must carry that user_id")


# --- wire text reaches a log line escaped (issue 14.6) ------------------------------------------
def test_wire_text_is_described_without_control_characters(tmp_path: Path) -> None:
    intake, _ = make(tmp_path)
    forged = "x\n2026-01-01 planner_service ERROR \x1b[31mfake\u2028"
    accepted = intake.handle(request(client_ref=forged[:64]))
    refused = intake.handle(json.dumps({"kind": "task_request", "user_id": "u-7", "x_m": 1, "y_m": 1, "tasks": 1,
                                        "client_ref": "r\r\n", "bad\nfield\x1b": 1}).encode())
    assert isinstance(accepted, Accepted) and isinstance(refused, Rejected)
    assert accepted.reply.client_ref == forged[:64]  # the reply echoes it as it came
    for line in (accepted.describe(), refused.describe()):
        assert not any(c in line for c in "\n\r\x1b\u2028"), line
    assert "client_ref x\\x0a2026-01-01" in accepted.describe()
    assert refused.describe().startswith("bad\\x0afield\\x1b: ") and refused.describe().endswith("(client_ref r\\x0d\\x0a)")


# --- a request that crossed a service on the wire: ``served_seen`` ---------------------------------
def test_a_request_is_counted_less_what_was_served_since_the_user_counted(tmp_path: Path) -> None:
    from planner_service.model import field
    from planner_service.service.intake import fairness_rule

    journal = Journal(tmp_path / "j.sqlite")
    intake = Intake(journal, Area(500.0, 120.0, 10.0), clock=lambda: NOW, unservable=fairness_rule(field()))
    first = intake.handle(request(tasks=20, served_seen=0, sortie=1))
    assert isinstance(first, Accepted) and (first.backlog, first.served_seen) == (20, 0)
    journal.record_service(first.request_id, 3, (1.0, 2.0, 100.0), 12, 1.2e6, 0.3, 9e4, NOW)
    # counted before the user heard of the 12 served: 20 + 2 new = 22, of which 12 went
    crossed = intake.handle(request(tasks=22, served_seen=0, sortie=1, client_ref="b"))
    assert isinstance(crossed, Accepted) and (crossed.tasks, crossed.backlog, crossed.done) == (22, 10, False)
    assert (crossed.reply.sortie, crossed.reply.served_tasks) == (1, 12)
    assert "22 tasks (0 served seen; 10 left)" in crossed.describe()
    assert journal.request_in_force("u-7").backlog == 10  # type: ignore[union-attr]
    # the fairness rule judges the count, not the statement: a repeat of 22 would be
    # eligible, one of 10 is not (rule (3), (9c): more than the threshold, 15 in this preset)
    threshold = field().fairness_threshold_tasks
    assert 10 <= threshold < 22 and crossed.unservable == f"fairness: a repeat needs more than {threshold:g} tasks, asked 10"
    # all of it served since the user counted: nothing left, the wait ends
    journal.record_service(crossed.request_id, 4, (1.0, 2.0, 100.0), 10, 1e6, 0.3, 9e4, NOW)
    late = intake.handle(request(tasks=10, served_seen=12, sortie=1, client_ref="c"))
    assert isinstance(late, Accepted) and late.backlog == 0 and late.done and late.reply.queue_position == 0
    assert late.reply.note.startswith("cannot be served in this sortie: no tasks to offload")
    assert journal.pending() == []


def test_a_served_seen_of_another_sortie_takes_off_everything_served_in_this_one(tmp_path: Path) -> None:
    # The user's news is of sortie 1 (it never heard an ack of sortie 2): none of sortie 2's
    # services are off its count. Without ``sortie``, ``served_seen`` counts in the current
    # sortie; without ``served_seen`` the request is taken as it is (an older client).
    intake, journal = make(tmp_path)
    journal.end_sortie("the vehicle landed", {}, NOW)
    journal.begin_sortie(NOW)
    intake.new_sortie()
    first = intake.handle(request(tasks=8))
    assert isinstance(first, Accepted)
    journal.record_service(first.request_id, 3, (1.0, 2.0, 100.0), 5, 5e5, 0.3, 9e4, NOW)
    stale = intake.handle(request(tasks=9, served_seen=40, sortie=1))
    assert isinstance(stale, Accepted) and (stale.backlog, stale.served_seen) == (4, 0)
    assert journal.request(stale.request_id).served_seen == 0  # type: ignore[union-attr]
    current = intake.handle(request(tasks=9, served_seen=3))
    assert isinstance(current, Accepted) and current.backlog == 7
    old = intake.handle(request(tasks=9))
    assert isinstance(old, Accepted) and (old.backlog, old.served_seen) == (9, None)
    assert journal.request(old.request_id).served_seen is None  # type: ignore[union-attr]
