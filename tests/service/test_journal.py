"""The journal: requests, replacement, services, missions, and resuming from the file."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner_service.service.errors import JournalError
from planner_service.service.journal import Journal


def test_newer_request_replaces_older(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite")
    a, replaced = j.accept("u1", 10.0, 20.0, 0.0, 5, "r1", 100.0)
    b, _ = j.accept("u2", 30.0, 40.0, 0.0, 7, None, 101.0)
    c, replaced_c = j.accept("u1", 11.0, 21.0, 0.0, 9, "r2", 102.0)
    assert (a, b, c) == (1, 2, 3) and replaced == [] and replaced_c == [1]
    assert [(r.request_id, r.user_id, r.tasks) for r in j.pending()] == [(2, "u2", 7), (3, "u1", 9)]
    old = j.request(1)
    assert old is not None and old.status == "replaced" and old.reason == "replaced by request 3"
    # users in order of first request, positions from the latest
    assert [(u.user_id, u.x_m, u.services) for u in j.users()] == [("u1", 11.0, 0), ("u2", 30.0, 0)]


def test_service_and_not_served_and_resume(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path)
    j.accept("u1", 10.0, 20.0, 0.0, 5, None, 1.0)
    j.accept("u2", 30.0, 40.0, 0.0, 7, None, 2.0)
    j.record_service(1, 4, (20.0, 20.0, 100.0), 5, 5e5, 0.25, 90_000.0, 3.0)
    with pytest.raises(JournalError, match="not pending"):
        j.record_service(1, 4, (20.0, 20.0, 100.0), 5, 5e5, 0.25, 90_000.0, 3.5)
    j.record_mission(1, [{"seq": 0}], [{"hover_index": 4}], "accepted", 2.5)
    j.close()

    again = Journal(path)  # a restart
    assert [r.request_id for r in again.pending()] == [2]
    assert [(s.request_id, s.user_id, s.tasks, s.hover_index) for s in again.services()] == [(1, "u1", 5, 4)]
    assert [u.services for u in again.users()] == [1, 0]
    mission = again.last_mission()
    assert mission is not None and mission.plan_id == 1 and mission.points == [{"hover_index": 4}]
    nxt, _ = again.accept("u3", 1.0, 1.0, 0.0, 3, None, 4.0)
    assert nxt == 3  # ids continue after a restart
    again.close_pending({2: "fairness: test"}, 5.0)
    closed = again.request(2)
    assert closed is not None and closed.status == "not_served" and closed.reason == "fairness: test"
