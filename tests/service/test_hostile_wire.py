"""Hostile payloads over a real zenoh session into a running service: a few hundred drawn
from the fuzzing strategies (tests/support/hostile_payloads.py) on the request key and on
the state key. Each request gets a decodable ErrorReply, each state query the same State;
the service stays up, logs no traceback, leaves its journal as it was, and acks a valid
request afterwards with the next request id."""

from __future__ import annotations

import json
import time

import pytest
from hypothesis import HealthCheck, given, settings

from protocol import ErrorReply, State, TaskAck, decode
from tests.support.hostile_payloads import Case, batches, valid_request
from tests.support.stack import Stack

BATCH = 10
WIRE = settings(max_examples=50, deadline=None, database=None, derandomize=True,
                suppress_health_check=list(HealthCheck))
TABLES = ("requests", "services", "missions", "meta")
FOUND = [  # what the fuzzing found (each once crashed the handler or was accepted), sent first
    b"[" * 2000 + b"]" * 2000,
    b'{"kind": "task_request", "user_id": "u", "x_m": 1, "y_m": 1, "tasks": 1, "client_ref": "\\ud800"}',
    b'{"kind": "task_request", "\\udfff": NaN, "client_ref": "mine"}',
    b'{"x": ' + b"[" * 1500 + b"NaN" + b"]" * 1500 + b', "kind": "task_request"}',
    b'{"kind": "task_request", "user_id": "u\\n", "x_m": 1, "y_m": 1, "tasks": 1}',
    b'{"user_id": "u", "x_m": 1, "y_m": 1, "tasks": 1}',
    b'{"kind": "task_request", "user_id": "u", "x_m": 1, "y_m": 1, "tasks": 1, "` - at `$.x_m": 0}',
]


def hostile(case: Case) -> bool:
    """Not a valid request by the oracle (a duplicated key is left out: its fate is msgspec's)."""
    try:
        return valid_request(case.payload, 500.0, 120.0) is None
    except ValueError:
        return False


@pytest.mark.timeout(120)
def test_hostile_payloads_over_zenoh_change_nothing(stack: Stack) -> None:
    service = stack.service()  # no vehicle: nothing but requests can touch the journal
    client = stack.client
    assert client is not None
    first = client.submit_raw(json.dumps({"kind": "task_request", "user_id": "u-1", "x_m": 10.0, "y_m": 20.0,
                                          "tasks": 4}).encode())
    assert isinstance(first, TaskAck) and first.request_id == 1
    before = {table: stack.rows(f"SELECT * FROM {table}") for table in TABLES}
    state_before = client.state()
    seen = {"request": 0, "state": 0}
    for payload in FOUND:
        reply = client.submit_raw(payload, timeout_s=5.0)
        assert isinstance(reply, ErrorReply), (payload[:100], reply)

    @WIRE
    @given(batches("task_request", BATCH), batches("state", BATCH // 2))
    def send(requests: list[Case], queries: list[Case]) -> None:
        for case in filter(hostile, requests):
            reply = client.submit_raw(case.payload)  # decodes it: a ProtocolError would fail the test
            assert isinstance(reply, ErrorReply) and reply.field and reply.message, (case, reply)
            seen["request"] += 1
        for case in queries + requests[:BATCH // 2]:
            replies = [r.ok for r in client.session.get(client.keys.state, payload=case.payload, timeout=5.0)]
            assert len(replies) == 1 and replies[0] is not None, case
            state = decode(replies[0].payload.to_bytes(), State)
            assert (state.status.pending_requests, state.plan) == (state_before.status.pending_requests,
                                                                  state_before.plan), case
            seen["state"] += 1

    t0 = time.perf_counter()
    send()
    print(f"\nover zenoh: {seen['request']} hostile requests, {seen['state']} state queries in "
          f"{time.perf_counter() - t0:.1f} s")
    assert seen["request"] >= 200 and seen["state"] >= 200
    assert service.proc.poll() is None
    assert {table: stack.rows(f"SELECT * FROM {table}") for table in TABLES} == before
    after = client.submit_raw(json.dumps({"kind": "task_request", "user_id": "u-2", "x_m": 1.0, "y_m": 2.0,
                                          "tasks": 1, "client_ref": "after"}).encode())
    assert isinstance(after, TaskAck) and (after.request_id, after.client_ref) == (2, "after")
    log = service.log()
    assert "Traceback" not in log and "Exception in callback" not in log, log[-3000:]
