"""The journal's requests as data waiting (docs/PROTOCOL.md, "Requests"): the request in force
for a user at a moment, a service that consumes part of a backlog, a request of no tasks, a
newer request during a hold, and how a sortie closes a backlog partly served."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner_service.service.errors import JournalError
from planner_service.service.journal import Journal, UserBacklog

XYZ = (100.0, 100.0, 100.0)


def serve(j: Journal, request_id: int, tasks: int, at_s: float) -> int:
    return j.record_service(request_id, 3, XYZ, tasks, tasks * 1e5, 0.2, 90_000.0, at_s)


def test_a_service_consumes_part_of_a_backlog_and_the_rest_stays_pending(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    rid, _ = j.accept("u1", 10.0, 20.0, 0.0, 30, "a", 1.0)
    serve(j, rid, 12, 5.0)  # was: the request became "served" whatever was left of it
    row = j.request(rid)
    assert row is not None and (row.status, row.tasks, row.served_tasks, row.backlog) == ("pending", 30, 12, 18)
    assert [(r.request_id, r.backlog) for r in j.pending()] == [(rid, 18)]
    with pytest.raises(JournalError, match="19 tasks served of request 1, whose backlog is 18"):
        serve(j, rid, 19, 6.0)
    with pytest.raises(JournalError, match="0 tasks served"):
        serve(j, rid, 0, 6.0)
    serve(j, rid, 18, 7.0)
    row = j.request(rid)
    assert row is not None and (row.status, row.backlog) == ("served", 0) and j.pending() == []
    with pytest.raises(JournalError, match="request 1 is served, not pending"):
        serve(j, rid, 1, 8.0)
    assert [(s.request_id, s.tasks) for s in j.services()] == [(1, 12), (1, 18)]


def test_the_request_in_force_at_a_moment(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    assert j.request_in_force("u1") is None
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 20, None, 10.0)
    j.accept("u2", 50.0, 50.0, 0.0, 5, None, 11.0)
    serve(j, a, 8, 15.0)
    b, _ = j.accept("u1", 12.0, 22.0, 0.0, 16, None, 20.0)
    assert j.request_in_force("u1", 9.0) is None
    at_12 = j.request_in_force("u1", 12.0)
    assert at_12 is not None and (at_12.request_id, at_12.backlog, at_12.status) == (a, 20, "replaced")
    at_15 = j.request_in_force("u1", 15.0)
    assert at_15 is not None and (at_15.request_id, at_15.served_tasks, at_15.backlog) == (a, 8, 12)
    now = j.request_in_force("u1")
    assert now is not None and (now.request_id, now.x_m, now.backlog) == (b, 12.0, 16)
    assert j.request_in_force("u1", 20.0) == now
    done, _ = j.accept("u1", 12.0, 22.0, 0.0, 0, None, 30.0)  # nothing more to offload
    last = j.request_in_force("u1")
    assert last is not None and (last.request_id, last.backlog, last.status) == (done, 0, "not_served")


def test_a_newer_request_during_the_hold_keeps_the_users_own_count(tmp_path: Path) -> None:
    # The hold began bound to request a (20 tasks); during it the user said what it still
    # had (4, or 0: done). The service is recorded against a; b is the user's own count,
    # left as it is. Was: "record_service: request 1 is not pending".
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 20, None, 1.0)
    bound = j.request_in_force("u1", 2.0)
    assert bound is not None and bound.request_id == a
    b, replaced = j.accept("u1", 10.0, 20.0, 0.0, 4, None, 3.0)
    assert replaced == [a]
    serve(j, bound.request_id, 16, 4.0)
    rows = {r.request_id: r for r in j.requests()}
    assert (rows[a].status, rows[a].served_tasks) == ("replaced", 16)
    assert (rows[b].status, rows[b].backlog) == ("pending", 4)
    assert j.user_backlogs() == [UserBacklog("u1", b, 4, 1, 16)]
    c, _ = j.accept("u1", 10.0, 20.0, 0.0, 0, None, 5.0)
    assert j.pending() == [] and j.user_backlogs() == [UserBacklog("u1", c, 0, 1, 16)]
    with pytest.raises(JournalError, match="not_served"):  # a request of no tasks has nothing to serve
        serve(j, c, 1, 6.0)


def test_user_backlogs_and_service_counts(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 20, None, 1.0)
    j.accept("u2", 50.0, 50.0, 0.0, 5, None, 2.0)
    serve(j, a, 20, 3.0)
    c, _ = j.accept("u1", 10.0, 20.0, 0.0, 18, None, 4.0)
    serve(j, c, 10, 5.0)
    assert j.user_backlogs() == [UserBacklog("u1", c, 8, 2, 30), UserBacklog("u2", 2, 5, 0, 0)]
    assert j.service_counts() == {"u1": 2} and j.served_tasks("u1") == 30 and j.served_tasks("u2") == 0


def test_a_sortie_ending_closes_a_backlog_partly_served_as_served(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 20, None, 1.0)
    b, _ = j.accept("u2", 50.0, 50.0, 0.0, 5, None, 2.0)
    serve(j, a, 12, 3.0)
    j.end_sortie("the vehicle landed", {a: "fairness: a repeat needs more than 15 tasks, asked 8",
                                        b: "sortie ended before its turn"}, 9.0)
    rows = {r.request_id: (r.status, r.reason) for r in j.requests()}
    assert rows == {a: ("served", "8 of 20 tasks left: fairness: a repeat needs more than 15 tasks, asked 8"),
                    b: ("not_served", "sortie ended before its turn")}
    j.begin_sortie(10.0)
    with pytest.raises(JournalError, match="not a request of sortie 2"):
        serve(j, a, 1, 11.0)
    assert j.request_in_force("u1") is None and j.user_backlogs() == []
