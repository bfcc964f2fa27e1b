"""Bad requests over zenoh each get an error reply naming the field, and change nothing:
the journal's rows and the service's pending list are the same before and after."""

from __future__ import annotations

import json

import pytest

from protocol import ErrorReply, TaskAck
from tests.support.stack import Stack


def payload(**fields: object) -> bytes:
    base = {"kind": "task_request", "schema": 1, "user_id": "u-1", "x_m": 100.0, "y_m": 100.0, "tasks": 8}
    base.update(fields)
    return json.dumps({k: v for k, v in base.items() if v is not None}).encode()


BAD = [
    (b"{not json", "payload"),
    (payload(x_m=501.0), "x_m"),
    (payload(y_m=-3.0), "y_m"),
    (payload(z_m=500.0), "z_m"),
    (payload(tasks=-2), "tasks"),
    (payload(tasks=2.5), "tasks"),
    (payload(user_id="a*b"), "user_id"),
    (payload(user_id=None), "user_id"),
    (payload(colour="red"), "colour"),
    (payload(schema=7), "schema"),
    (payload(kind="task_ack"), "kind"),
    (b'{"kind": "task_request", "user_id": "u", "x_m": 1, "y_m": Infinity, "tasks": 1}', "y_m"),
    (b"x" * 5000, "payload"),
]


@pytest.mark.timeout(60)
def test_each_bad_request_is_refused_and_changes_nothing(stack: Stack) -> None:
    stack.vehicle()
    stack.service()
    client = stack.client
    assert client is not None
    good = client.submit_raw(payload(client_ref="first"))
    assert isinstance(good, TaskAck) and good.request_id == 1
    stack.wait_event(lambda e: e.event == "mission_uploaded", 20.0, "a mission for the good request")
    before = stack.rows("SELECT * FROM requests ORDER BY request_id")
    pending_before = stack.fleet().pending
    for body, field in BAD:
        reply = client.submit_raw(body)
        assert isinstance(reply, ErrorReply), (body[:80], reply)
        assert reply.field == field, (body[:80], reply)
        assert reply.message
    assert stack.rows("SELECT * FROM requests ORDER BY request_id") == before
    assert stack.fleet().pending == pending_before
    # and a good one afterwards still works, with the next id
    after = client.submit_raw(payload(user_id="u-2", client_ref="again"))
    assert isinstance(after, TaskAck) and after.request_id == 2 and after.client_ref == "again"
