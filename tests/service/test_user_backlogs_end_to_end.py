"""``sim_bridge users`` with backlogs, end to end: the vehicle stub, the service and the users
as real processes, real zenoh and MAVLink on loopback. The users' requests in the journal
are backlogs, not fresh draws: between two requests of a user with no service of it near
them, the count never falls; none exceeds the cap. Each user learnt exactly what the
journal says it was served, if its last request came after its last service (the ack
carries the count), and never more. With every plan the service publishes each user's
place: the users of the plan in its order, the others with none."""

from __future__ import annotations

import re
import time

import pytest

from protocol import Plan, UserPlace
from tests.support.stack import Stack

SPEEDUP = "40"
SUMMARY = re.compile(r"^(user-\d+): (\d+) submitted, (\d+) acked, (\d+) refused; (\d+) tasks arrived, (\d+) lost "
                     r"to a full backlog, (\d+) served, backlog (\d+)$", re.M)


@pytest.mark.timeout(150)
def test_users_send_their_backlogs_and_learn_what_was_served(stack: Stack) -> None:
    stack.vehicle("--speedup", SPEEDUP)
    stack.service(mavlink__start_mission="true", planner__min_requests="4")
    assert stack.client is not None
    places: list[UserPlace] = []
    plans: list[Plan] = []
    stack.client.follow_places(places.append)
    stack.client.follow_plans(plans.append)
    users = stack.users("--count", "6", "--speedup", SPEEDUP, "--seed", "5", "--backlog-max", "20")
    served = []
    deadline = time.monotonic() + 100.0
    while time.monotonic() < deadline and len(served) < 4:
        served = [e for e in list(stack.events) if e.event == "user_served"]
        time.sleep(0.2)
    assert len(served) >= 4, f"{len(served)} services:\n{users.log()[-3000:]}"
    time.sleep(3.0)  # every user speaks at least once an interval (1 s of wall time at x40)
    assert users.stop() == 0
    log = users.log()

    rows = stack.rows("SELECT request_id, user_id, tasks, accepted_at_s, sortie FROM requests ORDER BY request_id")
    services = stack.rows("SELECT user_id, tasks, time_s, sortie FROM services ORDER BY service_id")
    assert all(tasks <= 20 for _, _, tasks, _, _ in rows)
    falls, steady = [], 0
    by_user: dict[tuple[str, int], list[tuple[int, int, float]]] = {}
    for rid, user, tasks, at, sortie in rows:
        by_user.setdefault((user, sortie), []).append((rid, tasks, at))
    for (user, sortie), reqs in by_user.items():
        times = [t for u, _, t, s in services if u == user and s == sortie]
        for (_, before, t0), (_, mid, t1), (rid, after, t2) in zip(reqs, reqs[1:], reqs[2:]):
            if any(t0 <= t <= t2 for t in times):
                continue  # a service near them: the backlog may fall
            steady += 1
            if after < mid:
                falls.append((user, rid, mid, after))
    print(f"\n{len(rows)} requests, {len(services)} services; {steady} requests with no service near them")
    assert steady >= 10 and not falls, falls  # a fresh draw each interval would fall about half the time

    summary = {m[0]: [int(v) for v in m[1:]] for m in SUMMARY.findall(log)}
    assert len(summary) == 6, log[-2000:]
    for user, (submitted, acked, _, arrived, _, learnt, backlog) in summary.items():
        journal_served = sum(t for u, t, _, _ in services if u == user)
        last_service = max((t for u, _, t, _ in services if u == user), default=-1.0)
        last_request = max((at for _, u, _, at, _ in rows if u == user), default=-1.0)
        assert learnt <= journal_served and backlog == arrived - learnt, (user, summary[user], journal_served)
        if last_request > last_service:
            assert learnt == journal_served, (user, learnt, journal_served)
        assert acked == sum(1 for _, u, _, _, _ in rows if u == user) and submitted >= acked
    assert sum(v[5] for v in summary.values()) > 0  # somebody learnt of a service

    checked = 0
    for plan in list(plans):
        of_plan = {p.user_id: p for p in list(places) if p.plan_id == plan.plan_id}
        order = list(dict.fromkeys(pt.user_id for pt in plan.points if pt.user_id is not None))
        if not of_plan:
            continue
        assert all(of_plan[u].place == i for i, u in enumerate(order, 1) if u in of_plan), (plan, of_plan)
        assert all(p.place is None and p.eta_s is None for u, p in of_plan.items() if u not in order)
        etas = [of_plan[u].eta_s for u in order if u in of_plan]
        assert etas == sorted(etas), etas  # later in the order, later in time
        checked += 1
    assert checked >= 1, (len(plans), len(places))
