"""The zenoh side of the service: one session, the request and state queryables, the
status / plan / events publishers and the liveliness token.

zenoh-python calls its handlers on its own threads; each query is handed to the event
loop with ``call_soon_threadsafe`` and answered there (a Query may be replied to from any
thread until it is dropped; ``reply_and_drop`` finalises it at once so the client's get
completes without waiting for the garbage collector).

Back-pressure: at most ``max_queries_in_flight`` queries wait for the loop. One more is
answered at once on zenoh's thread with ``ErrorReply(field="service", message="busy: ...")``
and dropped, so a flood costs bounded memory and every client gets an answer instead of a
timeout.
"""

from __future__ import annotations

import asyncio
import logging
import threading
from typing import Any, Callable, Sequence

import zenoh

from protocol import ErrorReply, Event, Keys, Plan, ProtocolError, Status, UserPlace, encode
from protocol.zenoh_config import error_text
from protocol.zenoh_config import session_config as _session_config

from .config import ZenohConfig
from .errors import ServiceError
from .fleet.presence import FleetPresence
from .intake import BUSY, client_ref

log = logging.getLogger("planner_service.zenoh")

PUBLICATIONS: dict[type, str] = {Status: "status", Plan: "plan", Event: "events"}
"""Each published message type and the key (``Keys`` attribute) it goes on."""
OPEN_RETRY_S = 2.0
"""In client mode, how long one attempt to reach a router lasts before the next."""
OPERATOR_QUERIES_IN_FLIGHT = 8
"""Operator commands waiting for the event loop (a person types them: a few at most)."""


class ZenohError(ServiceError):
    """The zenoh session could not be opened or used."""


def session_config(mode: str, listen: Sequence[str] = (), connect: Sequence[str] = (),
                   multicast_scouting: bool = False, config_file: str | None = None) -> zenoh.Config:
    """The service's zenoh Config (``protocol.zenoh_config.session_config``); ``ZenohError``
    naming ``zenoh.config_file`` if that file is refused."""
    try:
        return _session_config(mode, listen, connect, multicast_scouting, config_file)
    except ProtocolError as err:
        raise ZenohError(f"zenoh.config_file: {err.message}") from None


def reply_and_drop(query: Any, key: str, payload: bytes, attachment: bytes | None = None) -> None:
    """Answer ``query`` (with ``attachment``: the operator's reply's proof) and let it go."""
    try:
        query.reply(key, payload, attachment=attachment)
    finally:
        query.drop()


class InFlight:
    """Counts queries handed to the event loop and not yet answered (thread-safe: entered
    on zenoh's threads, left on the loop's)."""

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.count = 0
        self.refused = 0
        """Queries answered busy so far (for the log)."""
        self._lock = threading.Lock()

    def enter(self) -> bool:
        with self._lock:
            if self.count >= self.limit:
                self.refused += 1
                return False
            self.count += 1
            return True

    def leave(self) -> None:
        with self._lock:
            self.count -= 1


class ZenohIO:
    def __init__(self, cfg: ZenohConfig, keys: Keys, fleet: FleetPresence | None = None,
                 discovery_s: float = 0.0) -> None:
        self.cfg = cfg
        self.keys = keys
        self.fleet = fleet
        """The fleet membership joined once the session is open, before anything is declared
        (``fleet.enabled``); None: a lone UAV."""
        self.discovery_s = discovery_s
        self.session: Any = None
        self.in_flight = InFlight(cfg.max_queries_in_flight)
        self.operator_in_flight = InFlight(OPERATOR_QUERIES_IN_FLIGHT)
        """The operator's own bound: a flood of users' queries never answers a hold busy."""
        self._request_q: Any = None
        self._user_request_q: Any = None
        self._fleet_request_qs: list[Any] = []
        self._state_q: Any = None
        self._operator_q: Any = None
        self._pubs: dict[str, Any] = {}
        self._token: Any = None

    def _config(self) -> zenoh.Config:
        c = self.cfg
        conf = session_config(c.mode, c.listen, c.connect, c.multicast_scouting, c.config_file or None)
        if self.fleet is not None:  # zenoh.ext's advanced publisher orders its cache by timestamps
            conf.insert_json5("timestamping/enabled", "true")
        return conf

    async def open(self, loop: asyncio.AbstractEventLoop, on_request: Callable[[Any], None],
                   on_state: Callable[[Any], None], stopping: asyncio.Event,
                   on_operator: Callable[[Any], None] | None = None) -> bool:
        """Open the session and declare everything; handlers run on ``loop``'s thread
        (``on_operator``: the operator queryable, declared only if given).

        In client mode the session needs a router: while none answers, it is tried again
        every ``OPEN_RETRY_S`` (off the loop's thread, so shutdown stays possible) until one
        does or ``stopping`` is set (then False). Once open, zenoh itself reconnects to the
        ``connect`` endpoints after a router restarts, and the declarations are restored."""
        conf = self._config()
        if self.cfg.mode == "client":
            conf.insert_json5("connect/timeout_ms", str(int(OPEN_RETRY_S * 1000)))
        warned = False
        while True:
            try:
                self.session = await asyncio.to_thread(zenoh.open, conf)
                break
            except zenoh.ZError as err:
                c = self.cfg
                if c.mode != "client":
                    raise ZenohError(f"cannot open a zenoh session ({c.mode}, listen {list(c.listen)}, "
                                     f"connect {list(c.connect)}): {error_text(err)}") from None
                if not warned:
                    log.warning("waiting for a zenoh router at %s: %s", list(c.connect), error_text(err))
                    warned = True
                if stopping.is_set():
                    return False
                # a refused connection fails at once: wait before the next attempt
                try:
                    await asyncio.wait_for(stopping.wait(), OPEN_RETRY_S / 4)
                    return False
                except TimeoutError:
                    pass
        if stopping.is_set():
            self.close()
            return False
        if self.fleet is not None:
            try:
                await asyncio.to_thread(self.fleet.join, self.session, self.discovery_s)
            except BaseException:
                self.close()
                raise
        s = self.session
        self._pubs = {name: s.declare_publisher(getattr(self.keys, name)) for name in PUBLICATIONS.values()}
        self._state_q = s.declare_queryable(self.keys.state, self._hand_over(loop, on_state, self.keys.state))
        self._request_q = s.declare_queryable(self.keys.request, self._hand_over(loop, on_request, self.keys.request))
        # every user's own request key (request/{user_id}), which access control can bind to
        # that user's certificate; the same handler (it reads the user id from the key)
        self._user_request_q = s.declare_queryable(self.keys.user_requests,
                                                   self._hand_over(loop, on_request, self.keys.user_requests))
        if self.fleet is not None:  # a request to the fleet: every member holds it
            fk = self.fleet.keys
            self._fleet_request_qs = [s.declare_queryable(k, self._hand_over(loop, on_request, k))
                                      for k in (fk.request, fk.user_requests)]
        if on_operator is not None:
            self._operator_q = s.declare_queryable(
                self.keys.operator, self._hand_over(loop, on_operator, self.keys.operator, self.operator_in_flight))
        self._token = s.liveliness().declare_token(self.keys.alive)
        return True

    def _hand_over(self, loop: asyncio.AbstractEventLoop, handler: Callable[[Any], None],
                   key: str, gate: InFlight | None = None) -> Callable[[Any], None]:
        """A zenoh callback (zenoh's thread) that queues ``handler(query)`` on the loop, or
        answers busy at once when ``gate``'s limit (``max_queries_in_flight``) is queued."""
        gate = gate or self.in_flight

        def run(query: Any) -> None:
            try:
                handler(query)
            finally:
                gate.leave()

        def callback(query: Any) -> None:
            if not gate.enter():
                self._busy(query, gate)
                return
            try:
                loop.call_soon_threadsafe(run, query)
            except RuntimeError:  # the loop is closed: refuse rather than hang the client
                gate.leave()
                query.drop()
        return callback

    def _busy(self, query: Any, gate: InFlight) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else None
        waiting = ("operator commands are already waiting" if gate is self.operator_in_flight else
                   "queries are already waiting (zenoh.max_queries_in_flight)")
        reply = ErrorReply(field="service", message=f"{BUSY}{gate.limit} {waiting}; retry in a moment",
                           client_ref=client_ref(payload))
        try:
            reply_and_drop(query, str(query.key_expr), encode(reply))  # the query's key: a user's own
        except zenoh.ZError:  # the client went away meanwhile: nothing to answer
            pass

    def publish(self, message: Status | Plan | Event | UserPlace) -> None:
        """``message`` on its key, chosen by its type: status, plan, events, or a user's own
        ``users/{user_id}`` (under access control only that user may subscribe to it)."""
        if isinstance(message, UserPlace):
            if self.session is not None:
                self.session.put(self.keys.user(message.user_id), encode(message))
            return
        pub = self._pubs.get(PUBLICATIONS[type(message)])
        if pub is not None:
            pub.put(encode(message))

    def withdraw_liveliness(self) -> None:
        """Undeclare the liveliness token: clients that wait for the service see it gone
        (a degraded service still answers, with the reason it takes nothing)."""
        if self._token is not None:
            try:
                self._token.undeclare()
            except zenoh.ZError:
                pass
            self._token = None

    def stop_intake(self) -> None:
        """Undeclare the request queryables: no new request reaches the service."""
        for q in (self._request_q, self._user_request_q, *self._fleet_request_qs):
            if q is not None:
                q.undeclare()
        self._request_q = self._user_request_q = None
        self._fleet_request_qs = []

    def close(self) -> None:
        self.stop_intake()
        for item in (self._token, self._state_q, self._operator_q, *self._pubs.values()):
            if item is not None:
                try:
                    item.undeclare()
                except zenoh.ZError:
                    pass
        self._token, self._state_q, self._operator_q, self._pubs = None, None, None, {}
        if self.fleet is not None:
            self.fleet.leave()
        if self.session is not None:
            self.session.close()
            self.session = None
