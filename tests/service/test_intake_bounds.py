"""The intake's bounds with pinned clocks: pending requests (only those that can be served
hold a place), distinct users, accepted requests per second on the monotonic clock (the
wall clock only stamps the journal); the token bucket itself."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from planner_service.model import field
from planner_service.service.config import IntakeConfig
from planner_service.service.intake import Accepted, Intake, Rejected, fairness_rule
from planner_service.service.journal import Journal
from planner_service.service.throttle import RateLimit
from protocol import Area


class Clock:
    def __init__(self, t: float) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def request(user: str, tasks: int = 5) -> bytes:
    return json.dumps({"kind": "task_request", "user_id": user, "x_m": 10.0, "y_m": 20.0, "tasks": tasks}).encode()


def make(tmp_path: Path, fair: bool = False, **limits: float) -> tuple[Intake, Journal, Clock, Clock]:
    """The intake, its journal, its wall clock and its monotonic clock."""
    journal = Journal(tmp_path / "j.sqlite")
    wall, mono = Clock(1_732_312_000.0), Clock(1000.0)
    extra = {"unservable": fairness_rule(field())} if fair else {}
    intake = Intake(journal, Area(500.0, 120.0, 10.0), wall, IntakeConfig(**limits), monotonic=mono,  # type: ignore[arg-type]
                    **extra)
    return intake, journal, wall, mono


def test_pending_bound_refuses_a_new_user_but_not_a_replacement(tmp_path: Path) -> None:
    intake, journal, _, _ = make(tmp_path, max_pending_requests=2)
    assert isinstance(intake.handle(request("a")), Accepted)
    assert isinstance(intake.handle(request("b")), Accepted)
    refused = intake.handle(request("c"))
    assert isinstance(refused, Rejected) and refused.reply.field == "service"
    assert refused.reply.message.startswith("busy: 2 requests pending (intake.max_pending_requests)")
    again = intake.handle(request("a", tasks=9))  # a replaces its own: still taken
    assert isinstance(again, Accepted) and again.replaced == (1,)
    assert [r.user_id for r in journal.pending()] == ["b", "a"]
    assert {r.user_id for r in journal.requests()} == {"a", "b"}  # the refused user left no row


def test_requests_of_no_tasks_hold_no_pending_place(tmp_path: Path) -> None:
    # Was: 99 requests of "tasks": 0 stayed pending, filled the bound for the whole sortie,
    # and every real request after them was refused busy.
    intake, journal, _, mono = make(tmp_path, max_pending_requests=99)
    for i in range(99):
        mono.t += 1.0
        out = intake.handle(request(f"idle-{i}", tasks=0))
        assert isinstance(out, Accepted) and out.done and out.unservable == "no tasks to offload", out
        assert out.reply.queue_position == 0 and out.reply.note == "cannot be served in this sortie: no tasks to offload"
    assert journal.pending() == []
    assert {r.status for r in journal.requests()} == {"not_served"}
    for i in range(99):
        mono.t += 1.0
        assert isinstance(intake.handle(request(f"real-{i}", tasks=7)), Accepted), i
    mono.t += 1.0
    refused = intake.handle(request("one-too-many", tasks=7))
    assert isinstance(refused, Rejected) and refused.reply.message.startswith("busy: 99 requests pending")
    mono.t += 1.0
    assert isinstance(intake.handle(request("one-too-many", tasks=0)), Accepted)  # nothing to hold: taken


def test_a_user_the_fairness_rule_leaves_out_holds_no_place(tmp_path: Path) -> None:
    # field(): a repeat needs more than 15 tasks; at most 2 services per user per sortie.
    intake, journal, _, mono = make(tmp_path, fair=True, max_pending_requests=1)
    for user in ("once", "twice"):
        mono.t += 1.0
        out = intake.handle(request(user, tasks=20))
        assert isinstance(out, Accepted)
        journal.record_service(out.request_id, 0, (10.0, 20.0, 100.0), 20, 2e6, 0.3, 9e4, 1.0)
    journal.record_service(intake.handle(request("twice", tasks=20)).request_id,  # type: ignore[union-attr]
                           1, (10.0, 20.0, 100.0), 20, 2e6, 0.3, 9e4, 2.0)
    mono.t += 1.0
    assert isinstance(intake.handle(request("waiting", tasks=5)), Accepted)  # fills the one place
    for user, tasks, why in (("once", 10, "fairness: a repeat needs more than 15 tasks, asked 10"),
                             ("twice", 20, "fairness: already served 2 times (limit 2)")):
        mono.t += 1.0
        out = intake.handle(request(user, tasks=tasks))
        assert isinstance(out, Accepted) and out.unservable == why, out
        assert out.reply.note == f"cannot be served in this sortie: {why}"
        assert (out.reply.served_tasks, out.reply.sortie) == ({"once": 20, "twice": 40}[user], 1)
    mono.t += 1.0
    full = intake.handle(request("once", tasks=18))  # a repeat it may have: a place, and none is free
    assert isinstance(full, Rejected) and full.reply.message.startswith("busy: 1 requests pending")
    mono.t += 1.0
    assert isinstance(intake.handle(request("waiting", tasks=8)), Accepted)  # its own place


def test_user_bound_counts_users_already_in_the_journal(tmp_path: Path) -> None:
    intake, journal, _, _ = make(tmp_path, max_users=2)
    intake.handle(request("a"))
    intake.handle(request("b"))
    journal.close()
    intake, journal, _, _ = make(tmp_path, max_users=2)  # a restart reads the users back
    refused = intake.handle(request("c"))
    assert isinstance(refused, Rejected)
    assert refused.reply.message == "full: this sortie already has 2 users (intake.max_users); a new user id is not taken"
    assert isinstance(intake.handle(request("b")), Accepted)


def test_requests_that_cannot_be_served_hold_no_user_place(tmp_path: Path) -> None:
    # Was: 200 requests of "tasks": 0 from distinct ids took every place of intake.max_users,
    # and every new user after them was refused "full" for the rest of the sortie.
    intake, journal, _, mono = make(tmp_path, max_users=3)
    for i in range(200):
        mono.t += 1.0
        out = intake.handle(request(f"idle-{i}", tasks=0))
        assert isinstance(out, Accepted) and out.unservable == "no tasks to offload", (i, out)
    for user in ("a", "b", "c"):
        mono.t += 1.0
        assert isinstance(intake.handle(request(user, tasks=4)), Accepted), user
    mono.t += 1.0
    refused = intake.handle(request("d", tasks=4))
    assert isinstance(refused, Rejected)
    assert refused.reply.message == "full: this sortie already has 3 users (intake.max_users); a new user id is not taken"
    mono.t += 1.0
    assert isinstance(intake.handle(request("d", tasks=0)), Accepted)  # nothing to serve: needs no place
    mono.t += 1.0
    assert isinstance(intake.handle(request("a", tasks=0)), Accepted)  # a's backlog done: it keeps its place
    assert journal.counted_user_ids() == {"a", "b", "c"}
    assert [u.user_id for u in journal.users()] == ["a", "b", "c"]  # the planner sees no idle user
    journal.close()
    intake, journal, _, mono = make(tmp_path, max_users=3)  # a restart counts the same places
    assert isinstance(intake.handle(request("e", tasks=4)), Rejected)
    assert isinstance(intake.handle(request("b", tasks=6)), Accepted)


def test_a_request_the_rule_leaves_out_holds_no_user_place(tmp_path: Path) -> None:
    # The model's rule leaves out only users already served (who hold a place); any rule that
    # leaves out a new user's request gives it none either.
    journal = Journal(tmp_path / "j.sqlite")
    mono = Clock(1000.0)
    intake = Intake(journal, Area(500.0, 120.0, 10.0), Clock(1_732_312_000.0), IntakeConfig(max_users=1),
                    monotonic=mono, unservable=lambda tasks, services: "fairness: too few" if tasks < 3 else None)
    for user in ("small-1", "small-2"):
        mono.t += 1.0
        out = intake.handle(request(user, tasks=2))
        assert isinstance(out, Accepted) and out.unservable == "fairness: too few", out
    mono.t += 1.0
    assert isinstance(intake.handle(request("big", tasks=9)), Accepted)
    mono.t += 1.0
    assert isinstance(intake.handle(request("big-2", tasks=9)), Rejected)


def test_rate_bound_is_a_one_second_bucket_on_the_monotonic_clock(tmp_path: Path) -> None:
    intake, journal, wall, mono = make(tmp_path, max_requests_per_s=3.0)
    outcomes = [intake.handle(request(f"u{i}")) for i in range(5)]
    assert [type(o).__name__ for o in outcomes] == ["Accepted"] * 3 + ["Rejected"] * 2
    assert outcomes[3].reply.message.startswith("busy: over 3 requests/s (intake.max_requests_per_s)")
    wall.t += 10.0  # the wall clock alone adds no token
    assert isinstance(intake.handle(request("u3")), Rejected)
    mono.t += 1.0 / 3.0  # one token back
    assert isinstance(intake.handle(request("u3")), Accepted)
    assert isinstance(intake.handle(request("u4")), Rejected)
    assert len(journal.requests()) == 4


def test_a_wall_clock_stepped_back_an_hour_refuses_nothing(tmp_path: Path) -> None:
    # Was: the bucket ran on the wall clock and waited for it to catch up: after a step back
    # of an hour every request was refused "busy" for an hour.
    intake, journal, wall, mono = make(tmp_path, max_requests_per_s=2.0)
    assert all(isinstance(intake.handle(request(f"u{i}")), Accepted) for i in range(2))
    wall.t -= 3600.0
    for i in range(2, 8):
        mono.t += 0.5
        out = intake.handle(request(f"u{i}"))
        assert isinstance(out, Accepted), out
        assert out.reply.accepted_at_s == wall.t  # the journal and the ack keep the wall clock
    assert [r.accepted_at_s for r in journal.requests()][-1] == wall.t


def test_a_bad_request_costs_no_token(tmp_path: Path) -> None:
    intake, _, _, _ = make(tmp_path, max_requests_per_s=1.0)
    for _ in range(5):
        assert intake.handle(b"{bad").reply.field == "payload"  # type: ignore[union-attr]
    assert isinstance(intake.handle(request("a")), Accepted)


def test_rate_limit_refills_to_its_burst_and_ignores_a_clock_going_back() -> None:
    bucket = RateLimit(2.0, now_s=0.0, burst=4.0)
    assert [bucket.take(0.0) for _ in range(5)] == [True] * 4 + [False]
    assert bucket.take(0.5)  # 0.5 s at 2/s: one token
    assert not bucket.take(-100.0)  # back in time: nothing added
    assert bucket.take(-99.5)  # and it counts on from there, not from 0.5
    assert bucket.take(100.0) and bucket.tokens == pytest.approx(3.0)  # capped at the burst
    with pytest.raises(ValueError, match="rate_per_s"):
        RateLimit(0.0, 0.0)
