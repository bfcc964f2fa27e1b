"""A small zenoh client of the planner service: submit a task request and await the ack,
follow status, plans and events, read the state snapshot.

zenoh-python's API is synchronous (callbacks on zenoh's threads); so is this client. An
asyncio program can run ``submit`` in a thread (``asyncio.to_thread``).
"""

from __future__ import annotations

import json
import time
from typing import Any, Callable

import zenoh

from .errors import ProtocolError
from .keys import Keys
from .messages import ErrorReply, Event, Plan, State, Status, TaskAck, TaskRequest, decode, decode_reply, encode


class ClientError(ProtocolError):
    """The service refused a request (``field`` names why) or did not answer
    (``field`` is ``service``)."""


def client_config(connect: list[str] | tuple[str, ...], mode: str = "peer", multicast_scouting: bool = False) -> zenoh.Config:
    """A zenoh Config that reaches the service through explicit endpoints."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "true" if multicast_scouting else "false")
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    return conf


class PlannerClient:
    """One zenoh session talking to one vehicle's service."""

    def __init__(self, connect: list[str] | tuple[str, ...] = ("tcp/127.0.0.1:7447",), keys: Keys | None = None,
                 *, session: Any = None, mode: str = "peer", timeout_s: float = 5.0) -> None:
        self.keys = keys or Keys()
        self.timeout_s = timeout_s
        self._own = session is None
        self.session = session if session is not None else zenoh.open(client_config(connect, mode))
        self._subs: list[Any] = []

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self._subs = []
        if self._own:
            self.session.close()

    def __enter__(self) -> "PlannerClient":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # --- discovery ------------------------------------------------------------------------
    def wait_for_service(self, timeout_s: float = 10.0) -> bool:
        """True once the service's liveliness token is seen (its queryables are declared
        before the token, so a request sent afterwards finds them)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            replies = self.session.liveliness().get(self.keys.alive, timeout=0.5)
            for reply in replies:
                if reply.ok is not None:
                    return True
            time.sleep(0.05)
        return False

    # --- requests ------------------------------------------------------------------------------
    def _query(self, key: str, payload: bytes | None, timeout_s: float | None) -> bytes | None:
        replies = self.session.get(key, payload=payload, timeout=timeout_s or self.timeout_s)
        for reply in replies:
            if reply.ok is not None:
                return reply.ok.payload.to_bytes()
        return None

    def submit_raw(self, payload: bytes, timeout_s: float | None = None) -> TaskAck | ErrorReply:
        """Send any payload to the request queryable; the service's reply."""
        data = self._query(self.keys.request, payload, timeout_s)
        if data is None:
            raise ClientError("service", f"no reply on {self.keys.request} within {timeout_s or self.timeout_s:g} s")
        return decode_reply(data)

    def submit(self, user_id: str, x_m: float, y_m: float, tasks: int, z_m: float = 0.0,
               client_ref: str | None = None, timeout_s: float | None = None) -> TaskAck:
        """Submit a request and await the ack; ``ClientError`` names the field if refused."""
        request = TaskRequest(user_id=user_id, x_m=x_m, y_m=y_m, tasks=tasks, z_m=z_m, client_ref=client_ref)
        reply = self.submit_raw(encode(request), timeout_s)
        if isinstance(reply, ErrorReply):
            raise ClientError(reply.field, reply.message)
        return reply

    def state(self, timeout_s: float | None = None) -> State:
        data = self._query(self.keys.state, None, timeout_s)
        if data is None:
            raise ClientError("service", f"no reply on {self.keys.state}")
        return decode(data, State)

    # --- following ---------------------------------------------------------------------------------
    def _follow(self, key: str, kind: Any, callback: Callable[[Any], None]) -> None:
        def handler(sample: Any) -> None:
            try:
                callback(decode(sample.payload.to_bytes(), kind))
            except ProtocolError:
                pass  # a newer schema or a foreign publisher: not ours to parse
        self._subs.append(self.session.declare_subscriber(key, handler))

    def follow_status(self, callback: Callable[[Status], None]) -> None:
        self._follow(self.keys.status, Status, callback)

    def follow_plans(self, callback: Callable[[Plan], None]) -> None:
        self._follow(self.keys.plan, Plan, callback)

    def follow_events(self, callback: Callable[[Event], None]) -> None:
        self._follow(self.keys.events, Event, callback)
