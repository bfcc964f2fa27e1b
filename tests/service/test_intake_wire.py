"""The intake's guarantees over real zenoh sessions on loopback (issue 14.5, 14.6): the client
takes as its ack only a reply that answers its own request, a user's own request key binds
its user id, and wire text reaches the service's events escaped. The service runs as a
real process (no vehicle: only requests touch the journal)."""

from __future__ import annotations

import json
import threading
from typing import Any

import pytest
import zenoh

from planner_service.harness.processes import free_port
from protocol import ErrorReply, Keys, TaskAck, encode
from protocol.client import ClientError, PlannerClient
from tests.support.stack import Stack

KEYS = Keys()


class Rogue:
    """A zenoh peer that answers every request key of the vehicle with an ack of its own:
    ``echo`` copies the request's user id and client_ref (a forger that reads the request),
    else it names another client_ref."""

    def __init__(self, echo: bool = False) -> None:
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.session = zenoh.open(_listen(self.endpoint))
        self.echo = echo
        self.queries = 0
        self._lock = threading.Lock()
        self.queryable = self.session.declare_queryable(f"{KEYS.prefix}/{KEYS.vehicle}/request/**", self._answer)
        self.plain = self.session.declare_queryable(KEYS.request, self._answer)

    def _answer(self, query: Any) -> None:
        with self._lock:
            self.queries += 1
        body = json.loads(query.payload.to_bytes()) if query.payload is not None else {}
        ack = TaskAck(request_id=999, user_id=body.get("user_id", "u-1"),
                      client_ref=body.get("client_ref") if self.echo else "forged")
        query.reply(str(query.key_expr), encode(ack))
        query.drop()

    def close(self) -> None:
        self.session.close()


def _listen(endpoint: str) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
    return conf


@pytest.mark.timeout(60)
def test_the_client_refuses_an_ack_that_does_not_answer_its_request() -> None:
    # Was: the client took any queryable's first reply as its ack.
    rogue = Rogue()
    try:
        with PlannerClient([rogue.endpoint], timeout_s=3.0) as client:
            with pytest.raises(ClientError) as err:
                client.submit("u-1", 10.0, 20.0, 5, client_ref="mine")
            assert err.value.field == "reply" and rogue.queries == 1
            assert err.value.message == ("no reply answers the request of user_id 'u-1', client_ref 'mine' (a forged "
                                         "or misrouted reply?): got task_ack for user_id 'u-1', client_ref 'forged'")
            with pytest.raises(ClientError, match="client_ref 'forged'"):
                client.submit("u-1", 10.0, 20.0, 5)  # a client_ref is made when none is given
    finally:
        rogue.close()


@pytest.mark.timeout(90)
def test_beside_a_rogue_queryable_the_client_takes_the_service_s_ack(stack: Stack) -> None:
    stack.service()
    rogue, echoing = Rogue(), Rogue(echo=True)
    try:
        with PlannerClient([stack.endpoint, rogue.endpoint], timeout_s=5.0) as client:
            assert client.wait_for_service(10.0)
            ack = client.submit("u-1", 10.0, 20.0, 5, client_ref="mine")
            assert (ack.request_id, ack.client_ref, ack.sortie) == (1, "mine", 1) and rogue.queries >= 1
        # a forger that reads the request and echoes it: two answers that disagree are refused
        # (only access control keeps such a queryable off the key: test_zenoh_tls_acl.py)
        with PlannerClient([stack.endpoint, echoing.endpoint], timeout_s=5.0) as client:
            assert client.wait_for_service(10.0)
            with pytest.raises(ClientError, match="2 different replies answer the request") as err:
                client.submit("u-2", 10.0, 20.0, 5, client_ref="mine-2")
            assert err.value.field == "reply"
    finally:
        rogue.close()
        echoing.close()
    assert [r[0] for r in stack.rows("SELECT user_id FROM requests ORDER BY request_id")] == ["u-1", "u-2"]


@pytest.mark.timeout(90)
def test_a_user_s_request_key_binds_its_user_id(stack: Stack) -> None:
    stack.service()
    client = stack.client
    assert client is not None

    def raw(key: str, user: str) -> TaskAck | ErrorReply:
        payload = json.dumps({"kind": "task_request", "user_id": user, "x_m": 1.0, "y_m": 2.0, "tasks": 3,
                              "client_ref": f"{user}@{key}"}).encode()
        return client.submit_raw(payload, key=key)

    other = raw(KEYS.user_request("u-2"), "u-1")
    assert isinstance(other, ErrorReply) and other.field == "user_id" and other.client_ref.startswith("u-1@")
    wild = raw(KEYS.user_requests, "u-1")  # "request/*": names no single user
    assert isinstance(wild, ErrorReply) and wild.field == "key"
    own = raw(KEYS.user_request("u-1"), "u-1")
    plain = raw(KEYS.request, "u-3")  # the plain key binds nobody (no access control)
    assert isinstance(own, TaskAck) and isinstance(plain, TaskAck) and (own.request_id, plain.request_id) == (1, 2)
    assert client.submit("u-4", 1.0, 2.0, 3).request_id == 3  # the library sends on the user's own key
    assert stack.rows("SELECT user_id FROM requests ORDER BY request_id") == [("u-1",), ("u-3",), ("u-4",)]


@pytest.mark.timeout(90)
def test_wire_text_reaches_the_events_escaped(stack: Stack) -> None:
    # Was: a field's name and the client's ref went into the request_rejected event as sent.
    service = stack.service()
    client = stack.client
    assert client is not None
    forged = b'{"kind": "task_request", "user_id": "u-1", "x_m": 1, "y_m": 2, "tasks": 3, ' \
             b'"client_ref": "x\\n\\u001b[31m", "evil\\nERROR fake line": 1}'
    reply = client.submit_raw(forged)
    assert isinstance(reply, ErrorReply) and reply.field == "evil\nERROR fake line"  # the sender gets its own text
    ok = client.submit("u-1", 1.0, 2.0, 3, client_ref="ok\r\n\u2028")
    assert ok.client_ref == "ok\r\n\u2028"
    rejected = stack.wait_event(lambda e: e.event == "request_rejected", 10.0, "the refusal's event")
    accepted = stack.wait_event(lambda e: e.event == "request_accepted", 10.0, "the acceptance's event")
    assert rejected.detail.startswith("evil\\x0aERROR fake line: ") and "(client_ref x\\x0a\\x1b[31m)" in rejected.detail
    assert accepted.detail == "3 tasks; client_ref ok\\x0d\\x0a\\u2028"
    for text in (rejected.detail, accepted.detail):
        assert not any(c in text for c in "\n\r\x1b\u2028"), text
    assert "Traceback" not in service.log()


@pytest.mark.timeout(60)
def test_the_service_s_place_publications_reach_each_user_on_its_key() -> None:
    """``ZenohIO.publish`` of ``user_place`` messages (what the loop calls on every re-plan) over a real session:
    a user following its own place gets its own; a simulator following all gets them all."""
    import asyncio

    from planner_service.service.config import ZenohConfig
    from planner_service.service.zenoh_io import ZenohIO
    from protocol import UserPlace

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    zio = ZenohIO(ZenohConfig(listen=(endpoint,)), KEYS)
    got: dict[str, list[UserPlace]] = {"u-1": [], "all": []}
    places = [UserPlace(user_id="u-1", sortie=1, plan_id=3, place=2, eta_s=40.0, request_id=7, backlog=9),
              UserPlace(user_id="u:2", sortie=1, plan_id=3, request_id=8, backlog=0, served_tasks=12, services=1)]

    async def run() -> None:
        assert await zio.open(asyncio.get_running_loop(), lambda q: q.drop(), lambda q: q.drop(), asyncio.Event())
        with PlannerClient([endpoint]) as client:
            client.follow_place("u-1", got["u-1"].append)
            client.follow_places(got["all"].append)
            assert client.wait_for_service(10.0)
            for _ in range(50):
                for place in places:
                    zio.publish(place)
                await asyncio.sleep(0.05)
                if got["u-1"] and len({p.user_id for p in got["all"]}) == 2:
                    break
        zio.close()

    asyncio.run(run())
    assert got["u-1"] and all(p == places[0] for p in got["u-1"])
    assert {p.user_id for p in got["all"]} == {"u-1", "u:2"} and places[1] in got["all"]
