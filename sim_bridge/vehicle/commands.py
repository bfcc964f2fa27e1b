"""COMMAND_LONG / COMMAND_INT on the vehicle: what each command does and its MAV_RESULT.

The result codes and texts are each autopilot's (``behaviour.py`` holds them). ArduPilot (checked on ArduCopter SITL
V4.7.0-dev; ``ArduCopter/GCS_MAVLink_Copter.cpp``, ``libraries/GCS_MAVLink/GCS_Common.cpp``,
``ArduCopter/mode.cpp``): a refused arm is MAV_RESULT_FAILED with one STATUSTEXT
``Arm: <check>`` per failing check; a refused mode change is FAILED with
``Mode change to AUTO failed: requires position``; MAV_CMD_MISSION_START with a first or last
item is DENIED; DO_SET_MISSION_CURRENT out of range is DENIED; SET_MESSAGE_INTERVAL for a
message it cannot send is DENIED; REQUEST_MESSAGE for one is FAILED. PX4 refuses arming and
mode changes it cannot run with MAV_RESULT_TEMPORARILY_REJECTED.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable

from pymavlink.dialects.v20 import common as mavlink

from .behaviour import Behaviour
from .flight import Flight, Refusal
from .modes import Mode, mode_from_command, mode_name, requested_name

log = logging.getLogger(__name__)

M = mavlink
ARM_FORCE_MAGIC = 21196
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces disarming in the air."""


@dataclass
class CommandOutcome:
    """The MAV_RESULT, STATUSTEXTs to broadcast (severity, text) and messages to send to the
    requester before and after the ACK."""

    result: int
    reason: str = ""
    texts: list[tuple[int, str]] = field(default_factory=list)
    before: list[Any] = field(default_factory=list)
    follow_up: list[Any] = field(default_factory=list)


class Commands:
    """Executes commands on a ``Flight``. ``message_for(id)`` builds a message that
    MAV_CMD_REQUEST_MESSAGE may ask for (None if the vehicle does not have it now);
    ``set_interval(peer, id, interval_us)`` changes a peer's stream; ``knows(id)`` says
    whether the vehicle can send message ``id`` at all."""

    def __init__(self, flight: Flight, message_for: Callable[[int], Any | None],
                 set_interval: Callable[[Hashable, int, float], bool], knows: Callable[[int], bool]) -> None:
        self.flight = flight
        self.message_for = message_for
        self.set_interval = set_interval
        self.knows = knows
        self._peer: Hashable = None

    @property
    def behaviour(self) -> Behaviour:
        return self.flight.behaviour

    def execute(self, msg: Any, peer: Hashable = None) -> CommandOutcome:
        """Run a COMMAND_LONG or COMMAND_INT; never raises for bad parameters."""
        command = int(msg.command)
        params = [msg.param1, msg.param2, msg.param3, msg.param4]
        if msg.get_type() == "COMMAND_INT":
            params += [msg.x / 1e7, msg.y / 1e7, msg.z]
        else:
            params += [msg.param5, msg.param6, msg.param7]
        handler = getattr(self, f"_cmd_{command}", None)
        if handler is None:
            return CommandOutcome(M.MAV_RESULT_UNSUPPORTED, f"command {command} is not supported")
        self._peer = peer
        try:
            return handler(params)
        except (ValueError, OverflowError) as exc:
            return CommandOutcome(M.MAV_RESULT_DENIED, f"bad parameters: {exc}")

    # --- refusals as each autopilot words them -------------------------------------------------
    def _refused(self, refusal: Refusal | None, asked: str, *, prefix: str = "", result: int | None = None,
                 severity: int = M.MAV_SEVERITY_CRITICAL) -> CommandOutcome:
        """The answer to a command that ``asked`` (a key of ``Behaviour.refusal_results``);
        ``result`` overrides the autopilot's refusal result."""
        if refusal is None:
            return CommandOutcome(M.MAV_RESULT_ACCEPTED)
        texts = [(M.MAV_SEVERITY_CRITICAL, note) for note in refusal.notes]
        texts += [(severity, prefix + reason) for reason in refusal.reasons]
        refused = self.behaviour.refusal_results[asked] if result is None else result
        return CommandOutcome(refused, refusal.text, texts)

    def _mode(self, mode: Mode, number: tuple[int, int] | None = None) -> CommandOutcome:
        refusal = self.flight.set_mode(mode)
        refused_text = self.behaviour.mode_refused_text
        if refusal is not None and refused_text is not None:
            autopilot = self.behaviour.autopilot
            name = (requested_name(autopilot, number[0], mode, number[1]) if number is not None
                    else mode_name(autopilot, mode))
            return self._refused(refusal, "mode", prefix=refused_text.format(name=name),
                                 severity=M.MAV_SEVERITY_WARNING)
        return self._refused(refusal, "mode")

    # --- commands -------------------------------------------------------------------------
    def _cmd_400(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_COMPONENT_ARM_DISARM
        if p[0] >= 0.5:
            return self._refused(self.flight.arm(), "arm", prefix="Arm: ")
        return self._refused(self.flight.disarm(force=int(p[1]) == ARM_FORCE_MAGIC), "disarm")

    def _cmd_176(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_SET_MODE
        if not int(p[0]) & M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return CommandOutcome(M.MAV_RESULT_UNSUPPORTED, "only custom modes are supported")
        mode = mode_from_command(self.flight.flavour, p[1], p[2])
        if mode is None:
            return CommandOutcome(self.behaviour.unknown_mode_result, f"unknown mode {p[1]:.0f}/{p[2]:.0f}")
        return self._mode(mode, (int(p[1]), int(p[2])))

    def _cmd_300(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_MISSION_START
        refusal = self.flight.mission_start(int(p[0]), int(p[1]))
        b = self.behaviour
        if refusal is not None and not b.mission_start_range and (int(p[0]) or int(p[1])):
            return CommandOutcome(M.MAV_RESULT_DENIED, refusal.text)
        if refusal is not None and b.mode_refused_text is not None:
            prefix = b.mode_refused_text.format(name=b.autopilot.mission_mode)
            return self._refused(refusal, "mission_start", prefix=prefix, severity=M.MAV_SEVERITY_WARNING)
        return self._refused(refusal, "mission_start")

    def _cmd_22(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_TAKEOFF
        alt = p[6]
        if not math.isfinite(alt):
            alt = 2.5  # PX4's MIS_TAKEOFF_ALT default when no altitude is given
        elif self.behaviour.takeoff_alt_amsl:
            alt -= self.flight.origin.alt_m
        return self._refused(self.flight.takeoff(alt), "takeoff")

    def _cmd_20(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_RETURN_TO_LAUNCH
        return self._mode(Mode.RTL)

    def _cmd_21(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_LAND
        return self._mode(Mode.LAND)

    def _cmd_17(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_LOITER_UNLIM
        return self._mode(Mode.HOLD)

    def _cmd_252(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_PAUSE_CONTINUE
        if int(p[0]) not in (0, 1):
            return CommandOutcome(M.MAV_RESULT_DENIED, "param1 must be 0 (pause) or 1 (continue)")
        return self._refused(self.flight.pause(int(p[0]) == 0), "pause", severity=M.MAV_SEVERITY_INFO)

    def _cmd_178(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_CHANGE_SPEED
        refusal = self.flight.set_speed(p[1])
        return self._refused(refusal, "speed", result=M.MAV_RESULT_DENIED)  # both autopilots

    def _cmd_224(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_SET_MISSION_CURRENT
        if self.flight.set_current(int(p[0])):
            return CommandOutcome(M.MAV_RESULT_ACCEPTED)
        return CommandOutcome(M.MAV_RESULT_DENIED, f"no mission item {int(p[0])}")

    def _cmd_512(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_REQUEST_MESSAGE
        msg_id = int(p[0])
        if not self.knows(msg_id):
            return CommandOutcome(self.behaviour.unknown_message_result, f"message {msg_id} is not available")
        message = self.message_for(msg_id)
        # A message the vehicle has no data for yet (home before it is set) is accepted and
        # not sent, as ArduPilot does.
        return CommandOutcome(M.MAV_RESULT_ACCEPTED, follow_up=[message] if message is not None else [])

    def _cmd_520(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
        return self._cmd_512([float(M.MAVLINK_MSG_ID_AUTOPILOT_VERSION)])

    def _cmd_410(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_GET_HOME_POSITION
        home = self.message_for(M.MAVLINK_MSG_ID_HOME_POSITION)
        before = [home] if home is not None else []
        if self.behaviour.home_request_sends_origin and home is not None:
            # GCS_MAVLINK::handle_command_get_home_position sends home and origin, then the ACK.
            origin = self.message_for(M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN)
            before += [origin] if origin is not None else []
        return CommandOutcome(M.MAV_RESULT_ACCEPTED, before=before)

    def _cmd_511(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_SET_MESSAGE_INTERVAL
        if self.set_interval(self._peer, int(p[0]), p[1]):
            return CommandOutcome(M.MAV_RESULT_ACCEPTED)
        return CommandOutcome(M.MAV_RESULT_DENIED, f"message {int(p[0])} is not streamed")
