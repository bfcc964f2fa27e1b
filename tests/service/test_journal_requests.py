"""The journal's requests as data waiting (docs/PROTOCOL.md, "Requests"): the request in force
for a user at a moment, a service that consumes part of a backlog, a request of no tasks, a
newer request during a hold, and how a sortie closes a backlog partly served."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner_service.service.errors import JournalError
from planner_service.service.journal import Journal
from planner_service.service.rows import UserBacklog

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


# --- a request that crossed a service: ``served_seen`` (docs/PROTOCOL.md, "Requests") ---------------
def test_a_service_between_a_users_count_and_its_request_is_not_served_twice(tmp_path: Path) -> None:
    # The user had 10 tasks (request a). It counts 13 (3 new), knowing of no service; before
    # its request arrives the vehicle serves 6 of a. Its request says it had taken 0 served
    # off its count: the service counts 13 - 6 = 7, what the user really has waiting. Was:
    # 13, and the 6 served tasks could be served again.
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 10, None, 1.0, served_seen=0)
    serve(j, a, 6, 2.0)  # crosses the user's next request on the wire
    b, _ = j.accept("u1", 10.0, 20.0, 0.0, 13, None, 3.0, served_seen=0)
    row = j.request(b)
    assert row is not None and (row.tasks, row.served_seen, row.user_served, row.backlog) == (13, 0, 6, 7)
    assert j.user_backlogs() == [UserBacklog("u1", b, 7, 1, 6)]
    bound = j.request_in_force("u1", 4.0)
    assert bound is not None and (bound.request_id, bound.backlog) == (b, 7)
    with pytest.raises(JournalError, match="8 tasks served of request 2, whose backlog is 7"):
        serve(j, b, 8, 5.0)
    serve(j, b, 7, 5.0)
    assert sum(s.tasks for s in j.services()) == 13  # every task the user had, each served once
    assert j.pending() == [] and (j.request(b).status, j.request(b).backlog) == ("served", 0)  # type: ignore[union-attr]


def test_a_request_that_knew_of_the_service_is_taken_as_it_is(tmp_path: Path) -> None:
    # The same, but the user heard of the 6 served (ack or place) before it counted 7.
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 10, None, 1.0, served_seen=0)
    serve(j, a, 6, 2.0)
    b, _ = j.accept("u1", 10.0, 20.0, 0.0, 7, None, 3.0, served_seen=6)
    assert j.user_backlogs() == [UserBacklog("u1", b, 7, 1, 6)]
    # an older client's request says nothing: its count is taken as it is (the documented limit)
    c, _ = j.accept("u1", 10.0, 20.0, 0.0, 13, None, 4.0)
    assert j.user_backlogs() == [UserBacklog("u1", c, 13, 1, 6)]


def test_a_hold_that_ends_after_the_users_newer_request_is_taken_off_it(tmp_path: Path) -> None:
    # The hold binds to a (20 tasks); during it the user counts 23 (3 new), not knowing of
    # the hold's service yet. The service of 16 is recorded on a when the hold ends: the
    # user's request in force, b, loses those 16 too (it counted them). Was: b kept 23.
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 20, None, 1.0, served_seen=0)
    bound = j.request_in_force("u1", 2.0)
    assert bound is not None and bound.request_id == a
    b, _ = j.accept("u1", 10.0, 20.0, 0.0, 23, None, 3.0, served_seen=0)
    serve(j, bound.request_id, 16, 4.0)
    assert (j.request(a).status, j.request(a).served_tasks) == ("replaced", 16)  # type: ignore[union-attr]
    assert j.user_backlogs() == [UserBacklog("u1", b, 7, 1, 16)]
    assert j.request_in_force("u1", 3.5).backlog == 23  # type: ignore[union-attr]  # as it stood before the service
    # a user that took off its own upload (it knows what it sent) says so: 20 of 23 gone
    c, _ = j.accept("u1", 10.0, 20.0, 0.0, 3, None, 5.0, served_seen=20)
    assert j.user_backlogs() == [UserBacklog("u1", c, 3, 1, 16)]


def test_a_service_that_empties_the_request_in_force_through_another_closes_it(tmp_path: Path) -> None:
    # During the hold on a the user moved and sent its count again (no new tasks); the hold
    # served everything: nothing is left of b, which must not wait to be served.
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 10, None, 1.0, served_seen=0)
    b, _ = j.accept("u1", 60.0, 20.0, 0.0, 10, None, 2.0, served_seen=0)
    serve(j, a, 10, 3.0)
    row = j.request(b)
    assert row is not None and (row.status, row.reason, row.backlog) == ("served", "its tasks were served under "
                                                                         f"request {a}", 0)
    assert j.pending() == [] and j.user_backlogs() == [UserBacklog("u1", b, 0, 1, 10)]


def test_a_request_whose_tasks_were_all_served_before_it_arrived_closes_as_it_arrives(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 5, None, 1.0, served_seen=0)
    serve(j, a, 5, 2.0)
    b, _ = j.accept("u1", 10.0, 20.0, 0.0, 5, None, 3.0, served_seen=0)
    row = j.request(b)
    assert row is not None and row.status == "not_served" and row.reason.startswith("no tasks to offload: its 5 tasks "
                                                                                    "were served before it arrived")
    assert j.pending() == []


def test_a_stale_or_false_served_seen_gives_nothing_back(tmp_path: Path) -> None:
    # A served_seen beyond what was served (another sortie's count, a lie) takes nothing off,
    # and the services naming the request still consume it.
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 10, None, 1.0, served_seen=50)
    assert j.request(a).backlog == 10  # type: ignore[union-attr]
    serve(j, a, 4, 2.0)
    assert j.request(a).backlog == 6  # type: ignore[union-attr]
    serve(j, a, 6, 3.0)
    assert j.request(a).status == "served" and j.pending() == []  # type: ignore[union-attr]


def test_a_sortie_ending_counts_what_is_left_of_a_request_that_crossed_a_service(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite", now_s=0.0)
    a, _ = j.accept("u1", 10.0, 20.0, 0.0, 10, None, 1.0, served_seen=0)
    serve(j, a, 4, 2.0)
    b, _ = j.accept("u1", 10.0, 20.0, 0.0, 12, None, 3.0, served_seen=0)  # 12 - 4 = 8 left
    serve(j, b, 5, 4.0)
    j.end_sortie("the vehicle landed", {b: "sortie ended before its turn"}, 9.0)
    row = j.request(b)
    assert row is not None and (row.status, row.reason) == ("served", "3 of 12 tasks left: sortie ended before its turn")
    j.begin_sortie(10.0)  # a new sortie counts its own services only
    c, _ = j.accept("u1", 10.0, 20.0, 0.0, 3, None, 11.0, served_seen=0)
    assert j.user_backlogs() == [UserBacklog("u1", c, 3, 0, 0)]
