"""The zenoh side of the service: one session, the request and state queryables, the
status / plan / events publishers and the liveliness token.

zenoh-python calls its handlers on its own threads; each query is handed to the event
loop with ``call_soon_threadsafe`` and answered there (a Query may be replied to from any
thread until it is dropped; ``reply_and_drop`` finalises it at once so the client's get
completes without waiting for the garbage collector).
"""

from __future__ import annotations

import asyncio
import json
from typing import Any, Callable

import zenoh

from protocol import Keys

from .config import ZenohConfig
from .errors import ServiceError


class ZenohError(ServiceError):
    """The zenoh session could not be opened or used."""


def session_config(mode: str, listen: tuple[str, ...] | list[str] = (), connect: tuple[str, ...] | list[str] = (),
                   multicast_scouting: bool = False) -> zenoh.Config:
    """A zenoh Config: mode, explicit endpoints, multicast scouting on or off."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "true" if multicast_scouting else "false")
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    return conf


def reply_and_drop(query: Any, key: str, payload: bytes) -> None:
    try:
        query.reply(key, payload)
    finally:
        query.drop()


class ZenohIO:
    def __init__(self, cfg: ZenohConfig, keys: Keys) -> None:
        self.cfg = cfg
        self.keys = keys
        self.session: Any = None
        self._request_q: Any = None
        self._state_q: Any = None
        self._pubs: dict[str, Any] = {}
        self._token: Any = None

    def open(self, loop: asyncio.AbstractEventLoop, on_request: Callable[[Any], None],
             on_state: Callable[[Any], None]) -> None:
        """Open the session and declare everything; handlers run on ``loop``'s thread."""
        c = self.cfg
        try:
            self.session = zenoh.open(session_config(c.mode, c.listen, c.connect, c.multicast_scouting))
        except zenoh.ZError as err:
            raise ZenohError(f"cannot open a zenoh session ({c.mode}, listen {list(c.listen)}, "
                             f"connect {list(c.connect)}): {err}") from None

        def hand_over(handler: Callable[[Any], None]) -> Callable[[Any], None]:
            def callback(query: Any) -> None:
                try:
                    loop.call_soon_threadsafe(handler, query)
                except RuntimeError:  # the loop is closed: refuse rather than hang the client
                    query.drop()
            return callback

        s = self.session
        self._pubs = {name: s.declare_publisher(getattr(self.keys, name)) for name in ("status", "plan", "events")}
        self._state_q = s.declare_queryable(self.keys.state, hand_over(on_state))
        self._request_q = s.declare_queryable(self.keys.request, hand_over(on_request))
        self._token = s.liveliness().declare_token(self.keys.alive)

    def publish(self, name: str, payload: bytes) -> None:
        pub = self._pubs.get(name)
        if pub is not None:
            pub.put(payload)

    def stop_intake(self) -> None:
        """Undeclare the request queryable: no new request reaches the service."""
        if self._request_q is not None:
            self._request_q.undeclare()
            self._request_q = None

    def close(self) -> None:
        self.stop_intake()
        for item in (self._token, self._state_q, *self._pubs.values()):
            if item is not None:
                try:
                    item.undeclare()
                except zenoh.ZError:
                    pass
        self._token, self._state_q, self._pubs = None, None, {}
        if self.session is not None:
            self.session.close()
            self.session = None
