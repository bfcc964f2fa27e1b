"""The JSON messages on the zenoh keys, validated at decode.

msgspec decodes and type-checks in one pass straight into frozen Structs, rejects unknown
fields (``forbid_unknown_fields``) and reports the JSON path of the first bad value; it is
several times faster than pydantic and has no compiled-model step, which matters on a
companion computer answering every request inline. What JSON types cannot say (a position
inside the area, finite numbers) is checked after the decode, so every refusal, whatever
its cause, is one ``ProtocolError`` naming the field.

Every message carries ``kind`` (its type tag) and ``schema`` (the version of its layout).
Layouts are versioned one message type at a time (``LAYOUT``): a type whose fields change
in a way an older decoder refuses (a new field, as every decoder forbids unknown ones) gets
the next number, the others keep theirs. A decoder takes only its own version, so an old
client refuses a new ``status`` naming ``schema`` instead of misreading it.

One exception, for the one message the service decodes from clients it does not update:
``task_request`` gained two optional fields (``served_seen``, ``sortie``) in layout 1.
They are left out of the payload when not given, so a request that does not use them is
the same bytes as before; the service reads requests with and without them (old clients
keep working), and an older service refuses one that carries them, naming the field.
"""

from __future__ import annotations

import json
import math
import re
from typing import Annotated, Any, ClassVar, Literal, Union

import msgspec

from .area import Area
from .duplicate_keys import refuse_duplicate_keys
from .errors import ProtocolError

SCHEMA_VERSION = 1
"""The layout version of every message type that has not changed since the first
(``task_request``, ``task_ack``, ``error``, ``plan``, ``event``); ``STATUS_SCHEMA_VERSION``
for ``status`` and ``state``, ``OPERATOR_SCHEMA_VERSION`` for the operator's messages."""
STATUS_SCHEMA_VERSION = 2
"""``status`` (and ``state``, which holds one) at version 2: authority, battery source and
unknown battery, position check, what the service waits for, the degraded state."""
OPERATOR_SCHEMA_VERSION = 3
"""``operator_command`` and ``operator_reply``: 2 added the command's proof (``sent_at_ms``,
``proof``) and the fleet-wide ``state`` in the reply to ``status``; 3 the ``hello`` command
and the service's ``nonce`` that a proof covers."""
EVENT_SCHEMA_VERSION = 2
"""``event``'s layout: 2 added the kinds of the sortie logic (waypoint_skipped,
upload_abandoned, command_failed, authority_*, degraded)."""
MAX_PAYLOAD_BYTES = 4096
"""A request is a few hundred bytes; anything larger is refused before parsing. The bound
of every message but the two with lists (``MAX_BYTES`` of each type)."""
MAX_PLAN_BYTES = 64 * 1024
"""A plan of ``MAX_PLAN_POINTS`` points with the longest user ids: 34 123 bytes."""
MAX_STATE_BYTES = 4 * 1024 * 1024
"""A state of 10 000 pending requests (its list's bound) and the longest plan: 1.85 MB."""
MAX_TASKS = 1000
"""Upper bound of a request's task count (the model's u_max is 20; this is a sanity cap)."""
MAX_PLAN_POINTS = 200
MAX_COUNTER = 2 ** 31 - 1
"""Upper bound of a request's ``sortie`` and ``served_seen``: far beyond any real count,
and an integer every JSON reader and SQLite hold exactly."""

# \A...\Z, not ^...$: msgspec matches with re.search, where "$" also matches before a
# trailing newline, so "u-1\n" would pass as a user id.
UserId = Annotated[str, msgspec.Meta(min_length=1, max_length=64, pattern=r"\A[A-Za-z0-9_.:\-]+\Z")]
ShortText = Annotated[str, msgspec.Meta(max_length=256)]
Tasks = Annotated[int, msgspec.Meta(ge=0, le=MAX_TASKS)]
Count = Annotated[int, msgspec.Meta(ge=0)]
Fraction = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]

EventKind = Literal[
    "request_accepted", "request_rejected", "plan_updated", "mission_uploaded",
    "upload_failed", "user_served", "waypoint_reached", "returning", "landed", "link_lost",
    "link_restored", "vehicle_restarted", "mission_resumed", "resume_needed", "sortie_started",
    "waypoint_skipped", "upload_abandoned", "command_failed", "authority_granted", "authority_revoked",
    "authority_released", "degraded",
]


Phase = Literal["idle", "planning", "flying", "returning", "landed", "lost", "degraded"]
"""What the service is doing (``status.phase``); ``degraded``: it failed in a way that stops
it taking requests (``status.degraded`` says how) and only keeps the vehicle safe."""
Authority = Literal["none", "operator", "revoked"]
"""May the service command modes and arming? ``none``: not given (or handed back by the
operator's ``hold``); ``operator``: given by the operator (``start``); ``revoked``: taken
away by a change the service did not command (a pilot's mode, a failsafe, a landing)."""
OperatorCommandName = Literal["start", "hold", "status", "hello"]
Nonce = Annotated[str, msgspec.Meta(pattern=r"\A[0-9a-f]{32}\Z")]
"""A service's nonce for one run (``protocol.operator_proof``): 32 lowercase hex digits."""


class _Message(
    msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, tag_field="kind"
):
    LAYOUT: ClassVar[int] = SCHEMA_VERSION
    """The layout version this type writes and reads."""
    MAX_BYTES: ClassVar[int] = MAX_PAYLOAD_BYTES
    """The largest payload ``decode`` reads as this type (refused before parsing)."""
    schema: int = SCHEMA_VERSION
    """Layout version; a payload without it is read as the receiver's version of its type."""


class TaskRequest(_Message, tag="task_request"):
    """A ground user's data waiting to be offloaded: ``tasks`` is its whole backlog now (not
    an increment), ``x_m``/``y_m``/``z_m`` where it stands. Its newest request is the one in
    force; ``tasks`` 0 means nothing (more) to offload (docs/PROTOCOL.md, "Requests").

    ``served_seen`` says which services ``tasks`` already reflects: the tasks served to this
    user in ``sortie`` that it has taken off its count (its last news of ``served_tasks``,
    from an ack or its ``user_place``). The service then takes off ``tasks`` whatever it
    served beyond that (``counted_backlog``), so a request that crossed a service on the
    wire never asks for tasks already served. Both are optional and left out of the payload
    when not given (``UNSET``; ``null`` is read as not given): a request without
    ``served_seen`` (an older client's) is taken as it is."""

    user_id: UserId
    x_m: float
    y_m: float
    tasks: Tasks
    z_m: float = 0.0
    client_ref: Annotated[str, msgspec.Meta(max_length=64)] | None = None
    """The client's own correlation id, echoed in the reply."""
    served_seen: Annotated[int, msgspec.Meta(ge=0, le=MAX_COUNTER)] | None | msgspec.UnsetType = msgspec.UNSET
    """Tasks served to this user in ``sortie`` that ``tasks`` has already taken off."""
    sortie: Annotated[int, msgspec.Meta(ge=1, le=MAX_COUNTER)] | None | msgspec.UnsetType = msgspec.UNSET
    """The sortie ``served_seen`` counts in (the ``sortie`` of the news it came from); not
    given: the service's current sortie."""

    def seen_in(self, sortie: int) -> int | None:
        """The tasks served to this user in ``sortie`` that ``tasks`` has taken off: its
        ``served_seen`` if that counts in ``sortie``, 0 if it counts in another sortie (the
        user has heard of none of this one's services), None if it did not say."""
        if not isinstance(self.served_seen, int):
            return None
        return self.served_seen if self.sortie in (msgspec.UNSET, None, sortie) else 0

    def counted_backlog(self, sortie: int, served_tasks: int) -> int:
        """The backlog the service counts for this request when it arrives in ``sortie``,
        with ``served_tasks`` of this user served there: ``tasks`` less what was served that
        the user had not taken off (``served_tasks - served_seen``, never below 0); ``tasks``
        as it is without ``served_seen``. A client can hold it against the ack's ``sortie``
        and ``served_tasks``: it is the service's count of its backlog."""
        seen = self.seen_in(sortie)
        unseen = 0 if seen is None else max(served_tasks - seen, 0)
        return max(self.tasks - unseen, 0)


class TaskAck(_Message, tag="task_ack"):
    """The service accepted (and journalled) a request; ``request_id`` is the service's id
    of this request, which is now the user's request in force. The optional fields say what
    the service knows of the user at the time: its sortie, the tasks of it served in that
    sortie, its place in the current plan and the vehicle seconds until its service begins
    as estimated when that plan was made (the ``user_place`` publication says when), and a
    ``note`` when the request cannot be served in this sortie (no tasks, the fairness rule)."""

    request_id: Annotated[int, msgspec.Meta(ge=1)]
    user_id: UserId
    accepted_at_s: float = 0.0
    queue_position: Count = 0
    client_ref: Annotated[str, msgspec.Meta(max_length=64)] | None = None
    sortie: Annotated[int, msgspec.Meta(ge=1)] | None = None
    served_tasks: Count | None = None
    place: Annotated[int, msgspec.Meta(ge=1)] | None = None
    eta_s: Annotated[float, msgspec.Meta(ge=0.0)] | None = None
    note: ShortText = ""
    vehicle: Annotated[str, msgspec.Meta(max_length=64)] = ""
    """The vehicle of the service that answers (its own id): in a fleet each member answers
    a fleet request with its own ack, its own place and ETA for the user."""


class UserPlace(_Message, tag="user_place"):
    """One user's standing, published on ``{prefix}/{vehicle}/users/{user_id}`` whenever the
    plan changes: its place in the planned order (1: the next user served, or the one being
    served; None: not in this plan), the estimated vehicle seconds from ``time_s`` until its
    hold begins (None: not in the plan), the request in force (None: none in this sortie),
    the backlog the service counts for it, and what it was served in this sortie."""

    user_id: UserId
    sortie: Annotated[int, msgspec.Meta(ge=1)] = 1
    plan_id: Count = 0
    time_s: float = 0.0
    place: Annotated[int, msgspec.Meta(ge=1)] | None = None
    eta_s: Annotated[float, msgspec.Meta(ge=0.0)] | None = None
    request_id: Annotated[int, msgspec.Meta(ge=1)] | None = None
    backlog: Count = 0
    served_tasks: Count = 0
    services: Count = 0


class ErrorReply(_Message, tag="error"):
    """The request was refused: ``field`` names what was wrong."""

    field: ShortText
    message: ShortText
    client_ref: Annotated[str, msgspec.Meta(max_length=64)] | None = None


class Status(_Message, tag="status"):
    """Periodic snapshot of the vehicle as the service sees it."""

    LAYOUT: ClassVar[int] = STATUS_SCHEMA_VERSION
    schema: int = STATUS_SCHEMA_VERSION
    vehicle: ShortText = ""
    time_s: float = 0.0
    phase: Phase = "idle"
    armed: bool = False
    mode: ShortText = ""
    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    battery_fraction: Fraction | None = None
    """Remaining charge, 0-1; null: unknown (no reading, or an impossible one)."""
    mission_seq: Count = 0
    mission_total: Count = 0
    pending_requests: Count = 0
    served_users: Count = 0
    authority: Authority = "none"
    authority_detail: ShortText = ""
    """Why the authority is what it is (who gave or took it, and when), in words."""
    battery_source: Literal["autopilot", "model", "unknown"] = "unknown"
    """Where ``battery_fraction`` comes from: the autopilot's reading, the model's estimate
    (the energy spent since the last good reading), or nowhere (null)."""
    position_ok: bool = False
    """The position is a fix inside the served area (or near it): planned on; false: no
    fix yet, or a fix far outside, which is never planned on."""
    waiting_for: ShortText = ""
    """What the service waits for before it can go on ("the operator's start", "a position
    fix", ...); "" when it waits for nothing."""
    degraded: ShortText = ""
    """Why the service is degraded (journal, a task that died, ...); "" when healthy."""


class PlanPoint(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """A hovering point of the plan and whom it serves there."""

    x_m: float
    y_m: float
    z_m: float
    hold_s: Annotated[float, msgspec.Meta(ge=0.0)] = 0.0
    user_id: UserId | None = None


class Plan(_Message, tag="plan"):
    """The current plan: hovering points in flying order, then return to launch."""

    MAX_BYTES: ClassVar[int] = MAX_PLAN_BYTES

    plan_id: Count = 0
    time_s: float = 0.0
    points: Annotated[list[PlanPoint], msgspec.Meta(max_length=MAX_PLAN_POINTS)] = []
    predicted_energy_j: Annotated[float, msgspec.Meta(ge=0.0)] = 0.0


class Event(_Message, tag="event"):
    """Something happened; ``event`` says what."""

    LAYOUT: ClassVar[int] = EVENT_SCHEMA_VERSION
    schema: int = EVENT_SCHEMA_VERSION

    event: EventKind = "plan_updated"
    time_s: float = 0.0
    user_id: UserId | None = None
    request_id: Annotated[int, msgspec.Meta(ge=1)] | None = None
    detail: ShortText = ""


class PendingRequest(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    """An accepted request not yet served."""

    request_id: Annotated[int, msgspec.Meta(ge=1)]
    user_id: UserId
    x_m: float
    y_m: float
    z_m: float
    tasks: Tasks


class State(_Message, tag="state"):
    """The reply of the state queryable: status, plan and what is still pending."""

    LAYOUT: ClassVar[int] = STATUS_SCHEMA_VERSION
    MAX_BYTES: ClassVar[int] = MAX_STATE_BYTES
    schema: int = STATUS_SCHEMA_VERSION
    status: Status = Status()
    plan: Plan | None = None
    pending: Annotated[list[PendingRequest], msgspec.Meta(max_length=10_000)] = []


class OperatorCommand(_Message, tag="operator_command", kw_only=True):
    """The operator's command on the operator queryable: ``start`` gives the service
    authority over modes and arming for the sortie, ``hold`` takes it back (the service
    commands nothing more; the vehicle keeps the mission it holds), ``status`` asks,
    ``hello`` asks the service's ``nonce`` (anyone may: it needs no proof, changes nothing and
    tells nothing personal). Without zenoh access control every other command carries the
    operator's proof (``protocol.operator_proof``: ``sent_at_ms``, ``proof``, ``nonce`` and
    ``client_ref``)."""

    LAYOUT: ClassVar[int] = OPERATOR_SCHEMA_VERSION
    schema: int = OPERATOR_SCHEMA_VERSION
    command: OperatorCommandName
    reason: ShortText = ""
    """Why, in the operator's words (kept in the log and the authority's detail)."""
    client_ref: Annotated[str, msgspec.Meta(max_length=64)] | None = None
    """The client's own correlation id, echoed in the reply; with a proof, never reused."""
    sent_at_ms: Annotated[int, msgspec.Meta(ge=0, le=2 ** 53)] | None = None
    """When the operator sent it: milliseconds since 1970 (UTC) on the operator's clock."""
    proof: Annotated[str, msgspec.Meta(pattern=r"\A[0-9a-fA-F]{64}\Z")] | None = None
    """HMAC-SHA256 of the command under the operator key, 64 hex digits."""
    nonce: Nonce | None = None
    """The service's nonce (its reply to ``hello``) that the proof covers: no proof made for
    another run of the service passes."""


class OperatorReply(_Message, tag="operator_reply", kw_only=True):
    """What the service did with an operator's command: ``accepted`` or refused (``message``
    says why), the authority and phase that resulted, and for ``status`` the snapshot and
    the fleet-wide ``state`` (every pending request: users' positions and backlogs; the
    operator's alone, docs/PROTOCOL.md, "Who may do what")."""

    LAYOUT: ClassVar[int] = OPERATOR_SCHEMA_VERSION
    MAX_BYTES: ClassVar[int] = MAX_STATE_BYTES + MAX_PAYLOAD_BYTES
    schema: int = OPERATOR_SCHEMA_VERSION
    command: OperatorCommandName
    accepted: bool
    authority: Authority
    phase: Phase
    message: ShortText = ""
    client_ref: Annotated[str, msgspec.Meta(max_length=64)] | None = None
    status: Status | None = None
    state: State | None = None
    """``status`` only: the state with every pending request and the plan's users."""
    nonce: Nonce | None = None
    """``hello`` only: the service's nonce for this run, which a command's proof covers."""


class FleetMember(_Message, tag="fleet_member"):
    """What a fleet member's service says of itself to the others (``FleetKeys.announce``,
    published with a cache so that a member who joins later reads it): the altitude layer its
    UAV flies in, which no other member's may come within ``min_gap_m`` of."""

    vehicle: Annotated[str, msgspec.Meta(min_length=1, max_length=64, pattern=r"\A[A-Za-z0-9_.\-]+\Z")]
    layer_m: Annotated[float, msgspec.Meta(ge=0.0)]
    """The altitude (m above the origin) of its hovering points and legs."""
    min_gap_m: Annotated[float, msgspec.Meta(ge=0.0)]
    """The least vertical gap it keeps to every other member's layer (``fleet.vertical_separation_m`` +
    ``fleet.altitude_margin_m``)."""
    origin_lat_deg: Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]
    origin_lon_deg: Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
    origin_alt_m: float
    """Its local frame's origin (``[origin]``): its status's x, y, z are metres east, north and
    up of this point, which puts every member's position in one frame."""
    autopilot: ShortText = ""
    """The autopilot its service flies (``mavlink.flavour``: ardupilot, px4)."""


VehicleId = Annotated[str, msgspec.Meta(min_length=1, max_length=64, pattern=r"\A[A-Za-z0-9_.\-]+\Z")]


class Intention(msgspec.Struct, frozen=True, array_like=True, forbid_unknown_fields=True):
    """A user a member's plan means to serve, and the wall-clock time its hold should begin."""

    user_id: UserId
    due_s: float


class FleetIntentions(_Message, tag="fleet_intentions", kw_only=True):
    """What a member's plan means to do (``FleetKeys.intentions``), published on every plan
    with a cache of one: each user of the points still to fly and when its service should
    begin, and the users it claims. A user several members claim belongs to the earliest
    (docs/OPERATIONS.md, "A fleet")."""

    LAYOUT: ClassVar[int] = 2
    """2: the typed ``bound`` claim (1 dated a bound user 1e10 s early)."""
    schema: int = 2

    vehicle: VehicleId
    time_s: float
    users: Annotated[list[Intention], msgspec.Meta(max_length=256)] = []
    claims: Annotated[list[UserId], msgspec.Meta(max_length=8)] = []
    """The users of ``users`` it is committed to: the next point's and the one a hold serves.
    Only these keep the others off (the rest of the plan may still change)."""
    points: Annotated[list[Annotated[int, msgspec.Meta(ge=0, le=100_000)]], msgspec.Meta(max_length=8)] = []
    """The hovering points it is committed to (its next point, the point of its hold): the
    others plan without them."""
    route: Annotated[list[Annotated[int, msgspec.Meta(ge=0, le=100_000)]], msgspec.Meta(max_length=512)] = []
    """Every hovering point of the mission it flies, still to fly: if its service is lost with
    its vehicle armed, the vehicle flies them home, and the others plan without them until
    it is back."""
    bound: UserId | None = None
    """The user its hold serves, from the moment the hold is bound (a typed claim that beats
    every plan's estimate; of two, the one bound first), with ``bound_at_s`` (wall clock)."""
    bound_at_s: float | None = None
    holding: Annotated[int, msgspec.Meta(ge=0, le=100_000)] | None = None
    """The hovering point of its hold (arrived, not yet left), one of ``points``. Two members
    that arrived at one point before either heard the other's claim (the claim travels a
    radio) both hold it: the one that claimed it first keeps it (``points_at_s``; at one
    time, the vehicle id that sorts first), the other ends its hold, as does one holding a
    point another flies to and claimed first (``FleetLedger.yield_points``)."""
    points_at_s: Annotated[list[float], msgspec.Meta(max_length=8)] = []
    """When it claimed each of ``points``, in their order (wall clock, its own): of members
    that claimed one point before hearing each other, the first to claim keeps it. A point
    without one counts as claimed at ``time_s``."""
    answering: bool = False
    """It flies its mission's way home with its sortie on and would turn back for a new
    request: of such members the nearest to a new request answers it first, the others a
    step later each (docs/OPERATIONS.md, "A fleet")."""


class FleetServed(_Message, tag="fleet_served"):
    """A service a member flew (``FleetKeys.served``): the other members count it against
    the user's request and services as their own (the fairness rule spans the fleet)."""

    vehicle: VehicleId
    user_id: UserId
    tasks: Annotated[int, msgspec.Meta(ge=1)]
    at_s: float
    """The wall-clock time it was recorded."""


class FleetPosition(_Message, tag="fleet_position"):
    """Where a member's vehicle is, as its autopilot reports it (``FleetKeys.position``, with
    each status): what the other members judge separation on, and nothing more. Every member
    reads every other's at the status rate, so its size is the fleet's traffic: the whole
    status, signed, was 657 bytes and three quarters of what each member received (at 20 UAVs
    over radios of 100 ms and 5 % loss the downlink was the first thing to break); this, signed,
    is about 320. The whole status, signed, goes on ``FleetKeys.signed_status`` for the
    operator's live map alone."""

    MAX_BYTES: ClassVar[int] = 512
    x_m: float
    y_m: float
    z_m: float
    """Metres east, north and up of the member's origin (its announcement names it)."""
    armed: bool


class _NoMessage(_Message, tag="-"):
    """Never valid. Decoding a single type as ``Union[Type, _NoMessage]`` makes msgspec
    require the ``kind`` tag, which it does not for a lone tagged type: without it ``{}``
    would read as a default Status, Plan, Event or State."""


Message = Union[TaskRequest, TaskAck, ErrorReply, Status, Plan, Event, State, UserPlace, OperatorCommand,
                OperatorReply, FleetMember, FleetIntentions, FleetServed, FleetPosition]
Reply = Union[TaskAck, ErrorReply]
"""What the request queryable answers."""
OperatorAnswer = Union[OperatorReply, ErrorReply]
"""What the operator queryable answers (an ``error`` for a command it cannot read)."""


_XY_FIELDS = ("x_m", "y_m")


def encode(message: Message) -> bytes:
    """The message as compact JSON bytes."""
    return msgspec.json.encode(message)


def decode(payload: bytes | bytearray | memoryview | str, kind: Any, area: Area | None = None) -> Any:
    """Decode ``payload`` as ``kind`` (a message type or a Union of them) and validate it.

    With ``area`` every ``x_m``/``y_m`` must lie in the square and every ``z_m`` in
    ``[0, area.max_altitude_m]``. An object that names a key twice, at any depth, is refused
    (``protocol.duplicate_keys``). Raises ``ProtocolError`` naming the first bad field.
    """
    if isinstance(payload, str):
        try:
            payload = payload.encode("utf-8")
        except UnicodeEncodeError:
            raise ProtocolError("payload", "is not valid Unicode (a lone surrogate)") from None
    data = bytes(payload)
    limit = _limit(kind)
    if len(data) > limit:
        raise ProtocolError("payload", f"{len(data)} bytes exceeds the limit of {limit}")
    tagged = Union[kind, _NoMessage] if isinstance(kind, type) and issubclass(kind, _Message) else kind
    try:
        message = msgspec.json.decode(data, type=tagged)
    except msgspec.ValidationError as exc:
        raise ProtocolError(*_explain(str(exc), data)) from None
    except msgspec.DecodeError as exc:
        raise ProtocolError(*_explain_malformed(data, str(exc))) from None
    except UnicodeDecodeError:  # msgspec raises it (not a DecodeError) for some invalid UTF-8
        raise ProtocolError("payload", "is not valid UTF-8") from None
    except RecursionError:  # msgspec skipping a deeply nested value (to find the tag) recurses
        raise ProtocolError("payload", "nested too deeply") from None
    if isinstance(message, _NoMessage):
        raise ProtocolError("kind", "'-' is not a message kind")
    refuse_duplicate_keys(data)  # msgspec kept the last of two equal keys without a word
    _check_values(message, area, "")
    return message


def _limit(kind: Any) -> int:
    """The largest payload read as ``kind``: its ``MAX_BYTES``; a Union's, the largest of its
    members' (``operator_reply`` or ``error``: a reply with the fleet-wide state)."""
    if isinstance(kind, type) and issubclass(kind, _Message):
        return kind.MAX_BYTES
    members = [m for m in getattr(kind, "__args__", ()) if isinstance(m, type) and issubclass(m, _Message)]
    return max((m.MAX_BYTES for m in members), default=MAX_PAYLOAD_BYTES)


def decode_request(payload: bytes | bytearray | memoryview | str, area: Area) -> TaskRequest:
    """Decode a task request; positions are checked against ``area``."""
    return decode(payload, TaskRequest, area)


def decode_reply(payload: bytes | bytearray | memoryview | str) -> TaskAck | ErrorReply:
    """Decode what the request queryable answered (an ack or an error)."""
    return decode(payload, Reply)


def decode_operator_command(payload: bytes | bytearray | memoryview | str) -> OperatorCommand:
    """Decode an operator's command (``ProtocolError`` naming the field)."""
    return decode(payload, OperatorCommand)


def decode_operator_reply(payload: bytes | bytearray | memoryview | str) -> OperatorReply | ErrorReply:
    """Decode what the operator queryable answered (a reply, or an error)."""
    return decode(payload, OperatorAnswer)


_AT = re.compile(r" - at `\$\.?(?P<path>[^`]*)`\Z")
# An unknown field's name is the sender's text and may hold backticks and newlines, and
# even look like the " - at `$.path`" suffix: match it greedily, to the end.
_UNKNOWN = re.compile(r"Object contains unknown field `(?P<name>.*)`\Z", re.S)
_MISSING = re.compile(r"Object missing required field `(?P<name>[^`]+)`\Z")


def _explain(text: str, data: bytes) -> tuple[str, str]:
    """(field path, message) from a msgspec validation message."""
    whole = _UNKNOWN.match(text)
    if whole and whole.group("name") == "" and "" in _top_level_keys(data):
        return "payload", "an object has a field with an empty name"
    if whole and whole.group("name") in _top_level_keys(data):
        # A top-level unknown field, whatever its name looks like.
        return whole.group("name"), text
    at = _AT.search(text)
    prefix = at.group("path") if at else ""
    message = _AT.sub("", text)
    for pattern in (_UNKNOWN, _MISSING):
        named = pattern.match(message)
        if named:
            name = named.group("name")
            return (f"{prefix}.{name}" if prefix else name), message
    return (prefix or "payload"), message


def _top_level_keys(data: bytes) -> set[str]:
    try:
        loose = json.loads(data.decode("utf-8"))
    except (ValueError, RecursionError):
        return set()
    return set(loose) if isinstance(loose, dict) else set()


def _explain_malformed(data: bytes, text: str) -> tuple[str, str]:
    """msgspec refuses NaN, Infinity and lone surrogate escapes (``"\\ud800"``) as malformed
    JSON, which Python's json module reads: name the field that holds one."""
    try:
        # Strict UTF-8 first: json.loads would also guess UTF-16 and UTF-32. Objects as
        # lists of pairs: with a duplicated key a dict would hide the first value.
        loose = json.loads(data.decode("utf-8"), object_pairs_hook=_Pairs)
    except (ValueError, RecursionError):  # UnicodeDecodeError is a ValueError
        return "payload", text
    return _first_unwritable(loose) or ("payload", text)


class _Pairs(list):  # type: ignore[type-arg]
    """A JSON object as its (key, value) pairs, in order, duplicates kept."""


def _first_unwritable(value: Any) -> tuple[str, str] | None:
    """(path, why) of the first non-finite number or lone surrogate, depth first, without
    recursion (the value may be nested as deep as json.loads allows). The root's path is
    None, so that an empty key still shows in the path (``{"": {"a": NaN}}`` -> ``.a``)."""
    stack: list[tuple[str | None, Any]] = [(None, value)]
    while stack:
        path, item = stack.pop()
        if isinstance(item, float) and not math.isfinite(item):
            return path or "payload", "must be a finite number (NaN and Infinity are not allowed)"
        if isinstance(item, str) and not _is_unicode(item):
            return path or "payload", "is not valid Unicode (a lone surrogate escape)"
        if isinstance(item, _Pairs):
            children: list[tuple[str | None, Any]] = []
            for key, child in item:
                child_path = key if path is None else f"{path}.{key}"
                if not _is_unicode(key):
                    return _printable(child_path), "is not valid Unicode (a lone surrogate escape)"
                children.append((child_path, child))
            stack.extend(reversed(children))
        elif isinstance(item, list):
            stack.extend(reversed([(f"{path or ''}[{i}]", child) for i, child in enumerate(item)]))
    return None


def _is_unicode(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _printable(text: str) -> str:
    """``text`` with lone surrogates written as escapes, so that it can be sent back."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _check_values(message: Any, area: Area | None, path: str) -> None:
    if isinstance(message, msgspec.Struct):
        for name in message.__struct_fields__:
            _check_field(getattr(message, name), name, area, f"{path}.{name}" if path else name)
    if isinstance(message, _Message) and message.schema != message.LAYOUT:
        field = f"{path}.schema" if path else "schema"
        raise ProtocolError(field, f"schema {message.schema} is not supported (expected {message.LAYOUT})")


def _check_field(value: Any, name: str, area: Area | None, path: str) -> None:
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ProtocolError(path, "must be a finite number")
        if area is not None and name in _XY_FIELDS and not 0.0 <= value <= area.side_m:
            raise ProtocolError(path, f"{value} lies outside the area [0, {area.side_m}] m")
        if area is not None and name == "z_m" and not 0.0 <= value <= area.max_altitude_m:
            raise ProtocolError(path, f"{value} lies outside [0, {area.max_altitude_m}] m")
    elif isinstance(value, msgspec.Struct):
        _check_values(value, area, path)
    elif isinstance(value, list):
        for i, item in enumerate(value):
            _check_field(item, name, area, f"{path}[{i}]")
