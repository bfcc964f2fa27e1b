"""A small zenoh client of the planner service: submit a task request and await the ack,
follow status, plans, events and a user's place, read the public state snapshot, send the
operator's commands (with the operator key's proof).

``submit`` sends on the user's own request key (``{prefix}/{vehicle}/request/{user_id}``,
which access control can give to that user's certificate alone) with a ``client_ref`` (one is
made when the caller gives none), and takes as its answer only a reply that answers this
request: the same ``client_ref`` and, for an ack, the same user. A reply that does not (a
queryable that is not the service, a misrouted answer) is refused with ``ClientError("reply",
...)``, as are two answers that disagree. A rogue queryable that reads the request can still
echo both: only access control (no user may declare a queryable on the request keys) stops
it (docs/PROTOCOL.md, "Who may do what"). ``operator`` judges the operator queryable's
replies the same way (its command's random ``client_ref`` and the command echoed; two
answers that disagree are refused). Given ``served_seen`` (what the user knows was
served to it in its sortie, from its last ack or ``user_place``), the request carries it,
and the service never counts tasks already served in it (docs/PROTOCOL.md, "Requests").

zenoh-python's API is synchronous (callbacks on zenoh's threads); so is this client. An
asyncio program can run ``submit`` in a thread (``asyncio.to_thread``).
"""

from __future__ import annotations

import secrets
import time
from pathlib import Path
from typing import Any, Callable

import msgspec
import zenoh

from .errors import ProtocolError
from .fleet_places import FleetPlaces
from .keys import FleetKeys, Keys
from .messages import (ErrorReply, Event, OperatorCommand, OperatorReply, Plan, State, Status, TaskAck, TaskRequest,
                       UserPlace, decode, decode_operator_reply, decode_reply, encode)
from .operator_proof import reply_proved, sign
from .text import printable
from .zenoh_config import error_text, session_config


MATCH_POLL_S = 0.005
"""How often a client looks whether a queryable became reachable (zenoh's matching status)."""
MIN_ASK_S = 0.05
"""The least time a query is given once a queryable is reachable (the wait may take it all)."""
MAX_QUERIERS = 256
"""Queriers a client keeps (one per key asked: a simulator of many users asks many keys)."""


class ClientError(ProtocolError):
    """The service refused a request (``field`` names why), did not answer (``field`` is
    ``service``), or what answered is not an answer to this request (``field`` is ``reply``)."""

    @property
    def busy(self) -> bool:
        """The service was too busy to take it: the same request may succeed later."""
        return self.field == "service" and self.message.startswith("busy:")


def new_client_ref() -> str:
    """A fresh correlation id: 16 random hex digits."""
    return secrets.token_hex(8)


def client_config(connect: list[str] | tuple[str, ...], mode: str = "peer", multicast_scouting: bool = False,
                  config_file: str | Path | None = None) -> zenoh.Config:
    """A zenoh Config that reaches the service through explicit endpoints, listening on
    none; ``config_file`` (JSON5: TLS certificates, ...) is the base under them.

    ``mode``: ``peer`` (the default) opens whether or not an endpoint answers yet and keeps
    trying, and links to the peers it hears of (a service in peer mode: its queries then go
    straight to it); ``client`` is routed by the router or service it connects to, whose
    routes do not change under it, and refuses to open when no endpoint answers. A one-shot
    command through a router wants ``client`` (docs/PROTOCOL.md, "Commands that arrive")."""
    return session_config(mode, (), connect, multicast_scouting, config_file)


class PlannerClient:
    """One zenoh session talking to one vehicle's service."""

    def __init__(self, connect: list[str] | tuple[str, ...] = ("tcp/127.0.0.1:7447",), keys: Keys | None = None,
                 *, session: Any = None, mode: str = "peer", timeout_s: float = 5.0,
                 config_file: str | Path | None = None) -> None:
        """``ClientError("service", ...)`` if no session can be opened (nothing listening,
        or a TLS handshake refused); ``ProtocolError("config_file", ...)`` for a bad file."""
        self.keys = keys or Keys()
        self.timeout_s = timeout_s
        self._own = session is None
        if session is None:
            conf = client_config(connect, mode, config_file=config_file)
            try:
                session = zenoh.open(conf)
            except zenoh.ZError as err:
                raise ClientError("service", f"cannot open a zenoh session to {list(connect)}: "
                                  f"{error_text(err)}") from None
        self.session = session
        self._subs: list[Any] = []
        self._nonce: str | None = None
        """The service's nonce for this run (its proved ``hello``), once asked."""
        self._queriers: dict[str, Any] = {}
        """A querier per key asked (``_reachable``), the least recently used first."""

    def close(self) -> None:
        for thing in [*self._subs, *self._queriers.values()]:
            thing.undeclare()
        self._subs, self._queriers = [], {}
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

    def wait_for_fleet(self, timeout_s: float = 10.0) -> bool:
        """True once a fleet member's liveliness token is seen (``{prefix}/fleet/members/*``:
        a member declares its request queryables right after joining)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            replies = self.session.liveliness().get(FleetKeys(self.keys.prefix).members, timeout=0.5)
            if any(reply.ok is not None for reply in replies):
                return True
            time.sleep(0.05)
        return False

    # --- requests ------------------------------------------------------------------------------
    def _query(self, key: str, payload: bytes | None, timeout_s: float | None) -> bytes | None:
        replies = self._replies(key, payload, timeout_s)
        return replies[0] if replies else None

    def _replies(self, key: str, payload: bytes | None, timeout_s: float | None) -> list[bytes]:
        wait_s = timeout_s or self.timeout_s
        return [s.payload.to_bytes() for s in self._samples(key, payload, time.monotonic() + wait_s, wait_s)]

    def _samples(self, key: str, payload: bytes | None, deadline: float, wait_s: float) -> list[Any]:
        """Every reply of every queryable on ``key`` (not only the first nor the nearest: an
        answer from the service is not hidden behind another queryable's), asked once one is
        reachable (``_reachable``), all by ``deadline`` (``wait_s`` after the caller began).
        ``ClientError("service", "no reply on KEY within N s: ...")`` if none became reachable."""
        if not self._reachable(key, deadline):
            raise ClientError("service", f"no reply on {key} within {wait_s:g} s: no queryable on it became "
                                         f"reachable (waited for zenoh's matching status: is the service running, "
                                         f"and reachable through the endpoints given?)")
        replies = self.session.get(key, payload=payload, timeout=max(deadline - time.monotonic(), MIN_ASK_S),
                                   target=zenoh.QueryTarget.ALL, consolidation=zenoh.ConsolidationMode.NONE)
        return [reply.ok for reply in replies if reply.ok is not None]

    def _reachable(self, key: str, deadline: float) -> bool:
        """Whether a queryable on ``key`` became reachable (zenoh's matching status of a
        querier on it) before ``deadline``. A session just opened knows no route yet: a query
        sent at once reaches nobody through a router (issue 34: 27 commands in 30 lost). The
        querier is kept for the key's next queries (its matching status is then known at once,
        and its interest in the key's queryables stays declared while they are asked)."""
        querier = self._queriers.pop(key, None) or self.session.declare_querier(key, target=zenoh.QueryTarget.ALL)
        self._queriers[key] = querier  # the most recent last
        while len(self._queriers) > MAX_QUERIERS:
            self._queriers.pop(next(iter(self._queriers))).undeclare()
        while not querier.matching_status.matching:
            if time.monotonic() >= deadline:
                return False
            time.sleep(MATCH_POLL_S)
        return True

    def submit_raw(self, payload: bytes, timeout_s: float | None = None, key: str | None = None) -> TaskAck | ErrorReply:
        """Send any payload on a request key (default: the plain one); the first reply."""
        key = key or self.keys.request
        data = self._query(key, payload, timeout_s)
        if data is None:
            raise ClientError("service", f"no reply on {key} within {timeout_s or self.timeout_s:g} s")
        return decode_reply(data)

    def submit(self, user_id: str, x_m: float, y_m: float, tasks: int, z_m: float = 0.0,
               client_ref: str | None = None, timeout_s: float | None = None, *,
               served_seen: int | None = None, sortie: int | None = None) -> TaskAck:
        """Submit ``user_id``'s backlog (``tasks``: all it has waiting; 0: nothing more) and
        position on its own request key and await the ack. ``ClientError`` names the field if
        refused, ``ClientError("reply", ...)`` if no reply answers this request.

        ``served_seen``, when the user knows it: the tasks served to it in ``sortie`` (the
        ``sortie`` and ``served_tasks`` of its last ack or ``user_place``) that ``tasks`` has
        already taken off; the service then takes off what it served since, so a request
        that crosses a service never asks for tasks already served. Not given (None): left
        out of the request, which is then taken as it is (docs/PROTOCOL.md, "Requests").
        ``request_for(...).counted_backlog(ack.sortie, ack.served_tasks)`` is the service's
        count of the backlog this request left it."""
        return self.submit_request(request_for(user_id, x_m, y_m, tasks, z_m, client_ref,
                                               served_seen=served_seen, sortie=sortie), timeout_s)

    def submit_request(self, request: TaskRequest, timeout_s: float | None = None) -> TaskAck:
        """``submit`` of a request already made (``request_for``): sent on its user's own
        key with its ``client_ref`` (a fresh one if it has none)."""
        ref = new_client_ref() if request.client_ref is None else request.client_ref
        if request.client_ref is None:
            request = msgspec.structs.replace(request, client_ref=ref)
        key = self.keys.user_request(request.user_id)
        replies = self._replies(key, encode(request), timeout_s)
        if not replies:
            raise ClientError("service", f"no reply on {key} within {timeout_s or self.timeout_s:g} s: the "
                                         f"service was reachable, and did not reply")
        reply = answer(replies, request.user_id, ref)
        if isinstance(reply, ErrorReply):
            raise ClientError(reply.field, reply.message)
        return reply

    def submit_to_fleet(self, request: TaskRequest, timeout_s: float | None = None) -> "FleetAck":
        """Submit ``request`` once to the fleet (``{prefix}/fleet/request/{user_id}``): every
        live member journals it and answers; the answer is one ``FleetAck``: the ack of the
        member that plans to serve the user soonest (none plans it yet: the first member's
        by vehicle id) and every member that holds the request. ``ClientError`` as ``submit``
        when no member answers or every member refuses it (the first refusal's field)."""
        ref = new_client_ref() if request.client_ref is None else request.client_ref
        if request.client_ref is None:
            request = msgspec.structs.replace(request, client_ref=ref)
        key = FleetKeys(self.keys.prefix).user_request(request.user_id)
        replies = self._replies(key, encode(request), timeout_s)
        if not replies:
            raise ClientError("service", f"no reply on {key} within {timeout_s or self.timeout_s:g} s: a member "
                                         f"was reachable, none replied")
        return fleet_answer(replies, request.user_id, ref)

    def state(self, timeout_s: float | None = None) -> State:
        """The service's public snapshot: its status and the plan's points, nothing personal
        (no pending requests, no user ids: the operator's ``status`` has them);
        ``ClientError`` if it did not answer or answered an error (``busy: ...`` under load)."""
        data = self._query(self.keys.state, None, timeout_s)
        if data is None:
            raise ClientError("service", f"no reply on {self.keys.state}")
        try:
            return decode(data, State)
        except ProtocolError:
            error = decode(data, ErrorReply)  # raises the ProtocolError if it is not one either
            raise ClientError(error.field, error.message) from None

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

    # --- the operator ----------------------------------------------------------------------------
    def operator(self, command: str, reason: str = "", timeout_s: float | None = None, *,
                 key: bytes | None = None) -> OperatorReply:
        """Send an operator's command (``start``, ``hold``, ``status``) and return the
        service's reply, accepted or refused (``reply.accepted``); for ``status`` with the
        fleet-wide ``reply.state`` (every pending request). Everything within ``timeout_s``.

        ``key``: the operator key (``protocol.operator_proof``; the service's ``operator.key``
        file), which a service without zenoh access control requires. The client first asks
        the service's nonce for this run (``hello``, once per client; again once if the
        service restarted meanwhile), then sends the command with its proof (an HMAC of the
        command, the time and the nonce, never the key). Only a reply proved with the key
        (the HMAC of its bytes and of the command's proof, the zenoh reply's attachment) is
        believed: a rogue queryable that reads the command can neither answer it nor use it
        (made for this run, and once). Without ``key`` (under access control, where the
        routers decide who may command and who may answer) the replier is judged as
        ``submit`` judges an ack's: only a reply that echoes the command's fresh random
        ``client_ref`` answers it.

        Every queryable on the key is asked (a nearer rogue one cannot hide the service's
        answer) and every reply collected; two answers that disagree are refused
        (``ClientError("reply", ...)``). ``ClientError`` with the error's field if the service
        answered an error, ``("service", "no reply on KEY within N s...")`` if no reply
        answers (under access control a user's certificate gets none)."""
        if command not in ("start", "hold", "status"):
            raise ClientError("command", f"{command!r} is not start, hold or status")
        if len(reason) > 256:
            raise ClientError("reason", f"{len(reason)} characters; at most 256")
        wait_s = timeout_s or self.timeout_s
        deadline = time.monotonic() + wait_s
        if key is None:
            return self._ask_operator(OperatorCommand(command=command, reason=reason, client_ref=new_client_ref()),
                                      None, deadline, wait_s)  # type: ignore[arg-type]
        for attempt in (1, 2):
            nonce = self._nonce or self._hello(key, deadline, wait_s)
            ref, sent_at_ms = new_client_ref(), int(time.time() * 1000)
            proof = sign(key, self.keys, command, reason, ref, sent_at_ms, nonce)
            try:
                return self._ask_operator(OperatorCommand(
                    command=command, reason=reason, client_ref=ref, sent_at_ms=sent_at_ms, proof=proof,  # type: ignore[arg-type]
                    nonce=nonce), key, deadline, wait_s)
            except ClientError as err:
                if err.field != "nonce" or attempt == 2:
                    raise
                self._nonce = None  # the service restarted since its hello: ask its new nonce, once
        raise AssertionError("unreachable")

    def _hello(self, key: bytes, deadline: float, wait_s: float) -> str:
        """The service's nonce for this run, from its proved answer to ``hello``."""
        reply = self._ask_operator(OperatorCommand(command="hello", client_ref=new_client_ref()), key, deadline,
                                   wait_s)
        if reply.nonce is None:
            raise ClientError("operator_key", "the service takes no operator key (zenoh access control decides who may "
                                       "command it): send the command without the key")
        self._nonce = reply.nonce
        return reply.nonce

    def _ask_operator(self, command: OperatorCommand, key: bytes | None, deadline: float,
                      wait_s: float) -> OperatorReply:
        """``command`` sent, and its one answer (proved with ``key`` when given)."""
        samples = self._samples(self.keys.operator, encode(command), deadline, wait_s)
        unproved = 0
        if key is not None:
            proved = [s for s in samples if reply_proved(key, self.keys, command.proof, s.payload.to_bytes(),
                                                         None if s.attachment is None else s.attachment.to_bytes())]
            unproved, samples = len(samples) - len(proved), proved
        replies = [s.payload.to_bytes() for s in samples]
        answers = operator_answers(replies, command.command, command.client_ref or "")
        if len(answers) > 1:
            raise ClientError("reply", printable(
                f"{len(answers)} different replies answer the operator's {command.command} (client_ref "
                f"'{command.client_ref}'): two queryables answer on {self.keys.operator} (a rogue one, or two "
                f"services for one vehicle)"))
        if not answers and unproved:
            raise ClientError("proof", f"no reply on {self.keys.operator} within {wait_s:g} s carries the proof of "
                                       f"this operator key ({unproved} without it: not the service's key, a rogue "
                                       f"replier, or a service that takes no key)")
        if not answers:
            ignored = f" ({len(replies)} replies that did not answer this command ignored)" if replies else ""
            raise ClientError("service", f"no reply on {self.keys.operator} within {wait_s:g} s{ignored}")
        if isinstance(answers[0], ErrorReply):
            raise ClientError(answers[0].field, answers[0].message)
        return answers[0]

    def follow_place(self, user_id: str, callback: Callable[[UserPlace], None]) -> None:
        """``user_id``'s place in the plan, each time the service publishes it."""
        self._follow_places(self.keys.user(user_id), callback)

    def follow_places(self, callback: Callable[[UserPlace], None]) -> None:
        """Every user's place (a simulator of many users; under access control a user may
        follow only its own)."""
        self._follow_places(self.keys.users, callback)

    def follow_fleet_place(self, user_id: str,
                           callback: Callable[[FleetPlaces], None] | None = None) -> FleetPlaces:
        """``user_id``'s place across the fleet (``protocol.fleet_places``): every member's
        ``user_place`` for it (``{prefix}/*/users/{user_id}``), a member forgotten when its
        token goes (``{prefix}/fleet/members/*``). The returned ``FleetPlaces`` is kept up to
        date on zenoh's threads (``where()``: the member whose plan has the user soonest);
        ``callback`` runs after each change, on those threads."""
        places = FleetPlaces(user_id)
        fleet = FleetKeys(self.keys.prefix)

        def on_place(sample: Any) -> None:
            vehicle = fleet.place_vehicle(str(sample.key_expr), user_id)
            try:
                place = decode(sample.payload.to_bytes(), UserPlace)
            except ProtocolError:
                return
            if vehicle is not None and places.update(vehicle, place) and callback is not None:
                callback(places)

        def on_token(sample: Any) -> None:
            vehicle = fleet.vehicle_of(str(sample.key_expr))
            if vehicle is not None and sample.kind == zenoh.SampleKind.DELETE and places.forget(vehicle) \
                    and callback is not None:
                callback(places)
        self._subs.append(self.session.liveliness().declare_subscriber(fleet.members, on_token))
        self._subs.append(self.session.declare_subscriber(fleet.user_places(user_id), on_place))
        return places

    def _follow_places(self, key: str, callback: Callable[[UserPlace], None]) -> None:
        def checked(place: UserPlace, key_user: str | None) -> None:
            if key_user == place.user_id:  # a place published under another user's key is not theirs
                callback(place)

        def handler(sample: Any) -> None:
            try:
                place = decode(sample.payload.to_bytes(), UserPlace)
            except ProtocolError:
                return
            checked(place, self.keys.place_user(str(sample.key_expr)))
        self._subs.append(self.session.declare_subscriber(key, handler))


def command_client(connect: list[str] | tuple[str, ...], keys: Keys | None = None, *, timeout_s: float = 5.0,
                   config_file: str | Path | None = None) -> PlannerClient:
    """The client a one-shot command opens (``operator start|hold|status``, ``submit``): a
    zenoh client session, routed by the router or service it connects to. A peer's routes
    change as it links to the peers it hears of (the service among them), and a query sent
    meanwhile was lost now and then, a queryable reachable or not (issue 34, finding 10: 1 in
    100 operator commands through a router on a loaded machine); a client's do not, and it
    opens faster (120 commands from new sessions in 3.4 s, against 27 s as peers). It refuses
    to open when no endpoint answers: ``ClientError("service", "cannot open a zenoh session
    ...")``, at once."""
    return PlannerClient(connect, keys, timeout_s=timeout_s, config_file=config_file, mode="client")


def request_for(user_id: str, x_m: float, y_m: float, tasks: int, z_m: float = 0.0, client_ref: str | None = None,
                *, served_seen: int | None = None, sortie: int | None = None) -> TaskRequest:
    """The ``TaskRequest`` ``submit`` sends: ``served_seen`` and ``sortie`` only when given
    (a request without them is the same bytes as from a client that knows nothing of them,
    which a service of any version reads); ``sortie`` only with ``served_seen``, which it
    qualifies."""
    extra: dict[str, int] = {}
    if served_seen is not None:
        extra["served_seen"] = served_seen
        if sortie is not None:
            extra["sortie"] = sortie
    return TaskRequest(user_id=user_id, x_m=x_m, y_m=y_m, tasks=tasks, z_m=z_m, client_ref=client_ref, **extra)


def operator_answers(replies: list[bytes], command: str, client_ref: str) -> list[OperatorReply | ErrorReply]:
    """The different replies of ``replies`` that answer the operator's ``command`` sent with
    ``client_ref``: an operator reply to that command with that ref, or an error with that
    ref. One is the answer; none or more than one, and there is none to believe."""
    answers: list[OperatorReply | ErrorReply] = []
    for data in replies:
        try:
            reply = decode_operator_reply(data)
        except ProtocolError:
            continue
        if reply.client_ref != client_ref or (isinstance(reply, OperatorReply) and reply.command != command):
            continue
        if reply not in answers:
            answers.append(reply)
    return answers


def answer(replies: list[bytes], user_id: str, client_ref: str) -> TaskAck | ErrorReply:
    """The one reply of ``replies`` that answers the request of ``user_id`` and
    ``client_ref``: an ack of that user with that ref, or an error with that ref.
    ``ClientError("reply", ...)`` if none does, or if the ones that do disagree."""
    answers: list[TaskAck | ErrorReply] = []
    others: list[str] = []
    for data in replies:
        try:
            reply = decode_reply(data)
        except ProtocolError as err:
            others.append(f"not a reply ({err.field}: {err.message})")
            continue
        if reply.client_ref == client_ref and (isinstance(reply, ErrorReply) or reply.user_id == user_id):
            if reply not in answers:
                answers.append(reply)
            continue
        who = f"user_id '{reply.user_id}', " if isinstance(reply, TaskAck) else ""
        others.append(f"{reply.__struct_config__.tag} for {who}client_ref '{reply.client_ref}'")
    if len(answers) == 1:
        return answers[0]
    wanted = f"user_id '{user_id}', client_ref '{client_ref}'"
    if answers:
        raise ClientError("reply", printable(
            f"{len(answers)} different replies answer the request of {wanted}: two queryables answer on "
            f"the request key (a rogue one, or two services for one vehicle)"))
    raise ClientError("reply", printable(
        f"no reply answers the request of {wanted} (a forged or misrouted reply?): got {'; '.join(others)}", 400))


class FleetAck(msgspec.Struct, frozen=True):
    """The fleet's answer to one request (``PlannerClient.submit_to_fleet``)."""

    ack: TaskAck
    """The ack of the member that plans to serve the user soonest (its ``vehicle``,
    ``place`` and ``eta_s``), else the first member's by vehicle id."""
    holders: tuple[str, ...]
    """Every member that journalled the request: it survives the loss of all but one."""
    refusals: tuple[ErrorReply, ...] = ()
    """Members that refused it (a member between sorties, a full one)."""


def fleet_answer(replies: list[bytes], user_id: str, client_ref: str) -> FleetAck:
    """One ``FleetAck`` of the members' replies that answer the request of ``user_id`` and
    ``client_ref`` (others are ignored: each member answers once; an ack per member).
    ``ClientError`` when none accepted it: the first refusal's, or ``reply``."""
    acks: dict[str, TaskAck] = {}
    refusals: list[ErrorReply] = []
    for data in replies:
        try:
            reply = decode_reply(data)
        except ProtocolError:
            continue
        if reply.client_ref != client_ref:
            continue
        if isinstance(reply, ErrorReply):
            refusals.append(reply)
        elif reply.user_id == user_id and reply.vehicle:
            acks.setdefault(reply.vehicle, reply)
    if not acks:
        if refusals:
            raise ClientError(refusals[0].field, refusals[0].message)
        raise ClientError("reply", f"no member's ack answers the request of user_id '{printable(user_id)}', "
                                   f"client_ref '{printable(client_ref)}'")
    planned = [a for a in acks.values() if a.eta_s is not None]
    best = min(planned, key=lambda a: (a.eta_s, a.vehicle)) if planned else acks[min(acks)]
    return FleetAck(best, tuple(sorted(acks)), tuple(refusals))
