"""A restart resumes from the journal: pending requests and request ids carry on, plan ids
continue, and the vehicle gets the resumed plan. SIGTERM stops the service cleanly."""

from __future__ import annotations

import pytest

from tests.support.stack import Stack


@pytest.mark.timeout(90)
def test_restart_resumes_from_the_journal(stack: Stack) -> None:
    stack.vehicle()
    first = stack.service()
    client = stack.client
    assert client is not None
    ids = [client.submit("u1", 100.0, 120.0, 9).request_id, client.submit("u2", 300.0, 320.0, 11).request_id,
           client.submit("u1", 110.0, 130.0, 12).request_id]
    assert ids == [1, 2, 3]
    stack.wait_event(lambda e: e.event == "mission_uploaded" and "newest_request=3" in e.detail, 20.0,
                     "a mission with every request")
    plans_before = max(p for (p,) in stack.rows("SELECT plan_id FROM missions"))
    first.proc.terminate()  # SIGTERM: the one shutdown path
    assert first.proc.wait(15) == 0
    assert "journal flushed" in first.log()

    stack.events.clear()
    stack.service()
    state = stack.fleet()
    assert [(p.request_id, p.user_id, p.tasks) for p in state.pending] == [(2, "u2", 11), (3, "u1", 12)]
    assert client.submit("u3", 200.0, 200.0, 7).request_id == 4
    ev = stack.wait_event(lambda e: e.event == "mission_uploaded" and "newest_request=4" in e.detail, 20.0,
                          "a mission after the restart")
    plan_id = int(ev.detail.split(":")[0].split()[1])
    assert plan_id > plans_before
    statuses = stack.rows("SELECT request_id, status FROM requests ORDER BY request_id")
    assert statuses == [(1, "replaced"), (2, "pending"), (3, "pending"), (4, "pending")]
