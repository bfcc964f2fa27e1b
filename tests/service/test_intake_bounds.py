"""The intake's bounds with a pinned clock: pending requests, distinct users, accepted
requests per second; the token bucket itself."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from planner_service.service.config import IntakeConfig
from planner_service.service.intake import Accepted, Intake, Rejected
from planner_service.service.journal import Journal
from planner_service.service.throttle import RateLimit
from protocol import Area


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def request(user: str, tasks: int = 5) -> bytes:
    return json.dumps({"kind": "task_request", "user_id": user, "x_m": 10.0, "y_m": 20.0, "tasks": tasks}).encode()


def make(tmp_path: Path, **limits: float) -> tuple[Intake, Journal, Clock]:
    journal = Journal(tmp_path / "j.sqlite")
    clock = Clock()
    return Intake(journal, Area(500.0, 120.0, 10.0), clock, IntakeConfig(**limits)), journal, clock  # type: ignore[arg-type]


def test_pending_bound_refuses_a_new_user_but_not_a_replacement(tmp_path: Path) -> None:
    intake, journal, _ = make(tmp_path, max_pending_requests=2)
    assert isinstance(intake.handle(request("a")), Accepted)
    assert isinstance(intake.handle(request("b")), Accepted)
    refused = intake.handle(request("c"))
    assert isinstance(refused, Rejected) and refused.reply.field == "service"
    assert refused.reply.message.startswith("busy: 2 requests pending (intake.max_pending_requests)")
    again = intake.handle(request("a", tasks=9))  # a replaces its own: still taken
    assert isinstance(again, Accepted) and again.replaced == (1,)
    assert [r.user_id for r in journal.pending()] == ["b", "a"]
    assert journal.user_ids() == {"a", "b"}  # the refused user left no row


def test_user_bound_counts_users_already_in_the_journal(tmp_path: Path) -> None:
    intake, journal, _ = make(tmp_path, max_users=2)
    intake.handle(request("a"))
    intake.handle(request("b"))
    journal.close()
    intake, journal, _ = make(tmp_path, max_users=2)  # a restart reads the users back
    refused = intake.handle(request("c"))
    assert isinstance(refused, Rejected)
    assert refused.reply.message == "full: this sortie already has 2 users (intake.max_users); a new user id is not taken"
    assert isinstance(intake.handle(request("b")), Accepted)


def test_rate_bound_is_a_one_second_bucket(tmp_path: Path) -> None:
    intake, journal, clock = make(tmp_path, max_requests_per_s=3.0)
    outcomes = [intake.handle(request(f"u{i}")) for i in range(5)]
    assert [type(o).__name__ for o in outcomes] == ["Accepted"] * 3 + ["Rejected"] * 2
    assert outcomes[3].reply.message.startswith("busy: over 3 requests/s (intake.max_requests_per_s)")
    clock.t += 1.0 / 3.0  # one token back
    assert isinstance(intake.handle(request("u3")), Accepted)
    assert isinstance(intake.handle(request("u4")), Rejected)
    assert len(journal.requests()) == 4


def test_a_bad_request_costs_no_token(tmp_path: Path) -> None:
    intake, _, _ = make(tmp_path, max_requests_per_s=1.0)
    for _ in range(5):
        assert intake.handle(b"{bad").reply.field == "payload"  # type: ignore[union-attr]
    assert isinstance(intake.handle(request("a")), Accepted)


def test_rate_limit_refills_to_its_burst_and_ignores_a_clock_going_back() -> None:
    bucket = RateLimit(2.0, now_s=0.0, burst=4.0)
    assert [bucket.take(0.0) for _ in range(5)] == [True] * 4 + [False]
    assert bucket.take(0.5)  # 0.5 s at 2/s: one token
    assert not bucket.take(-100.0)  # back in time: nothing added
    assert bucket.take(100.0) and bucket.tokens == pytest.approx(3.0)  # capped at the burst
    with pytest.raises(ValueError, match="rate_per_s"):
        RateLimit(0.0, 0.0)
