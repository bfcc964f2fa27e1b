"""Which telemetry the link asks the autopilot for, at what rates, and whether it arrives.

ArduPilot streams nothing on a link until a ground station asks (its ``MAVn_*`` / older
``SRn_*`` stream rates default to 0 for Copter), and sends EXTENDED_SYS_STATE only when
asked with MAV_CMD_SET_MESSAGE_INTERVAL (it is in no stream group). PX4 streams a set on
its own but honours the same command. So on connect, after every reconnect and after a
vehicle restart the link asks for each message it needs with SET_MESSAGE_INTERVAL; a
refusal (or no answer) falls back to REQUEST_DATA_STREAM for the ArduPilot stream group
that carries the message, or to MAV_CMD_REQUEST_MESSAGE for a message in no group. What
does not arrive is "missing"; a refused message that does not arrive by the fallback
either is "unavailable" (the autopilot will not send it, and the judgement that needs it
does without: ``telemetry.assess_position``, the derived landed state). A message refused
by an autopilot that accepted others is unavailable at once (it knows the command and does
not have that message); one refused by an autopilot that accepted nothing (it may not know
the command) is given ``UNAVAILABLE_AFTER_S`` to come by the fallback.

What an autopilot streams unasked that the service does not read (the profile's
``unused_streams``: PX4's onboard link, hundreds of messages a second) is stopped first, with
SET_MESSAGE_INTERVAL -1 (a "quiet" request, its answer not waited on twice): under that
flood the link lost mission replies and COMMAND_ACKs on PX4 SITL at speed 10.

``Streams`` is the bookkeeping only (no I/O): it returns the requests to send and is told
of acknowledgements and arrivals.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

from pymavlink.dialects.v20 import ardupilotmega as M

from protocol.autopilot import Autopilot, autopilot_for

INTERVAL_CMD = M.MAV_CMD_SET_MESSAGE_INTERVAL
MISSING_AFTER_S = 2.0
"""Wall seconds after a request (or the last arrival, with 3 intervals) before a message is missing."""
UNAVAILABLE_AFTER_S = 2.0
"""Wall seconds after a refusal and its fallback before the message is taken as unavailable."""
REFUSALS = frozenset({"MAV_RESULT_DENIED", "MAV_RESULT_UNSUPPORTED", "MAV_RESULT_FAILED"})
QUIET_INTERVAL_US = -1.0
"""SET_MESSAGE_INTERVAL's interval that stops a message."""
REREQUEST_S = 5.0
"""Missing messages are asked for again this often (a lost request or a reset autopilot)."""


@dataclass(frozen=True)
class StreamSpec:
    """One message the link asks for: ``interval_s`` in vehicle seconds, ``group`` the
    MAV_DATA_STREAM that carries it on ArduPilot (None: no group; requested by message)."""

    name: str
    msg_id: int
    interval_s: float
    group: int | None = None


def quiet_plan(flavour: str | Autopilot) -> tuple[StreamSpec, ...]:
    """The messages the link stops: streamed unasked, of no use to the service."""
    return tuple(StreamSpec(name, msg_id, QUIET_INTERVAL_US / 1e6)
                 for name, msg_id in autopilot_for(flavour).unused_streams.items())


def stream_plan(flavour: str | Autopilot) -> tuple[StreamSpec, ...]:
    """The messages the service needs and their intervals, per autopilot."""
    autopilot = autopilot_for(flavour)
    estimator = StreamSpec(autopilot.estimator_message, autopilot.estimator_msg_id, 1.0, autopilot.estimator_stream)
    return (
        # 10 Hz: holds are judged from these reports (a gap is the tolerance of a hold's length)
        StreamSpec("GLOBAL_POSITION_INT", M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 0.1, M.MAV_DATA_STREAM_POSITION),
        StreamSpec("SYS_STATUS", M.MAVLINK_MSG_ID_SYS_STATUS, 1.0, M.MAV_DATA_STREAM_EXTENDED_STATUS),
        StreamSpec("BATTERY_STATUS", M.MAVLINK_MSG_ID_BATTERY_STATUS, 1.0, M.MAV_DATA_STREAM_EXTRA3),
        StreamSpec("EXTENDED_SYS_STATE", M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 0.5),
        StreamSpec("MISSION_CURRENT", M.MAVLINK_MSG_ID_MISSION_CURRENT, 0.5, M.MAV_DATA_STREAM_EXTENDED_STATUS),
        StreamSpec("GPS_RAW_INT", M.MAVLINK_MSG_ID_GPS_RAW_INT, 1.0, M.MAV_DATA_STREAM_EXTENDED_STATUS),
        StreamSpec("HOME_POSITION", M.MAVLINK_MSG_ID_HOME_POSITION, 2.0),
        estimator,
    )


@dataclass(frozen=True)
class Request:
    """Something to send: ``kind`` "interval" (SET_MESSAGE_INTERVAL for ``spec``, awaiting
    its COMMAND_ACK), "stream" (REQUEST_DATA_STREAM ``spec.group``, no answer) or
    "message" (MAV_CMD_REQUEST_MESSAGE for ``spec``, once)."""

    kind: str
    spec: StreamSpec


@dataclass
class _State:
    requested_at: float = -1.0
    heard_at: float | None = None
    refused: str = ""
    """Why the interval request failed ('' while not refused)."""
    accepted: bool = False
    fallback_at: float | None = None


class Streams:
    def __init__(self, plan: tuple[StreamSpec, ...], clock: Callable[[], float] = time.monotonic,
                 quiet: tuple[StreamSpec, ...] = ()) -> None:
        self.plan = plan
        self.quiet = quiet
        self.clock = clock
        self.by_name = {s.name: s for s in plan}
        self._by_id = {s.msg_id: s for s in plan}
        self._state = {s.name: _State() for s in plan}
        self._last_request = -REREQUEST_S

    def begin(self) -> list[Request]:
        """On (re)connect or a restart: stop what is not used, then ask for everything again,
        forgetting refusals."""
        now = self.clock()
        self._last_request = now
        self._state = {s.name: _State(requested_at=now) for s in self.plan}
        return [Request("quiet", s) for s in self.quiet] + [Request("interval", s) for s in self.plan]

    def on_interval_result(self, name: str, result: str) -> list[Request]:
        """The COMMAND_ACK of a SET_MESSAGE_INTERVAL ("MAV_RESULT_ACCEPTED", another result
        name, or "NO_ANSWER"): a refusal falls back."""
        state, spec = self._state.get(name), self.by_name.get(name)
        if state is None or spec is None or result == "MAV_RESULT_ACCEPTED":
            if state is not None:
                state.refused, state.accepted = "", True
            return []
        state.refused, state.fallback_at = result, self.clock()
        if result in REFUSALS and any(s.accepted for s in self._state.values()):
            # The autopilot knows the command and said no to this message alone (ArduPilot:
            # "No ap_message for mavlink id"): it does not have it. Unavailable at once, so
            # nothing waits for it; the fallback is still asked, and an arrival counts.
            state.fallback_at -= UNAVAILABLE_AFTER_S
        return [Request("stream" if spec.group is not None else "message", spec)]

    def heard(self, msg_id: int) -> bool:
        """A message arrived; True when it is one the link asked for."""
        spec = self._by_id.get(msg_id)
        if spec is None:
            return False
        self._state[spec.name].heard_at = self.clock()
        return True

    def _arriving(self, spec: StreamSpec, state: _State, now: float) -> bool:
        if state.heard_at is None:
            return False
        return now - state.heard_at <= max(3 * spec.interval_s, MISSING_AFTER_S)

    def arriving(self, name: str) -> bool:
        """``name`` came within its last few intervals."""
        state, spec = self._state.get(name), self.by_name.get(name)
        return state is not None and spec is not None and self._arriving(spec, state, self.clock())

    def available(self, name: str) -> bool:
        """False when the autopilot refused the message and it has not come by the fallback
        either: it will not send it (a judgement that needs it must do without)."""
        state, spec = self._state.get(name), self.by_name.get(name)
        if state is None or spec is None:
            return False
        now = self.clock()
        if self._arriving(spec, state, now):
            return True
        return not (state.refused and state.fallback_at is not None and now - state.fallback_at >= UNAVAILABLE_AFTER_S)

    def missing(self) -> tuple[str, ...]:
        """The messages asked for that do not arrive (none during the first
        ``MISSING_AFTER_S`` after asking)."""
        now = self.clock()
        out = []
        for spec in self.plan:
            state = self._state[spec.name]
            if state.requested_at < 0 or now - state.requested_at < MISSING_AFTER_S:
                continue
            if not self._arriving(spec, state, now):
                out.append(spec.name)
        return tuple(out)

    def due(self) -> list[Request]:
        """Requests to repeat now: the missing messages are asked for again (the way that
        worked last, or first the interval) as soon as they are missing, then every
        ``REREQUEST_S`` while they stay missing. At once matters: an autopilot that restarts
        without the link noticing comes back with its rates reset, and its restart is known
        from the clock of the first reports asked for again."""
        now = self.clock()
        missing = self.missing()
        if not missing or now - self._last_request < REREQUEST_S:
            return []
        self._last_request = now
        out = []
        for name in missing:
            spec, state = self.by_name[name], self._state[name]
            if state.refused:
                out.append(Request("stream" if spec.group is not None else "message", spec))
            else:
                out.append(Request("interval", spec))
        return out

    def describe(self, name: str) -> str:
        """Why ``name`` is missing, for the log."""
        state = self._state.get(name)
        if state is None:
            return "not asked for"
        if state.refused:
            how = "its stream group" if self.by_name[name].group is not None else "a single request"
            return f"refused ({state.refused}), asked by {how}: not arriving"
        return "asked for, not arriving"
