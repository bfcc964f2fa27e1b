"""COMMAND_LONG / COMMAND_INT on the vehicle: what each command does and its MAV_RESULT."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable

from pymavlink.dialects.v20 import common as mavlink

from .flight import Flight
from .modes import Mode, mode_from_command

log = logging.getLogger(__name__)

ARM_FORCE_MAGIC = 21196
"""param2 of MAV_CMD_COMPONENT_ARM_DISARM that forces disarming in the air."""


@dataclass
class CommandOutcome:
    """The MAV_RESULT and the messages to send after the ACK (a requested message)."""

    result: int
    reason: str = ""
    follow_up: list[Any] = field(default_factory=list)


class Commands:
    """Executes commands on a ``Flight``. ``message_for(id)`` builds a message that
    MAV_CMD_REQUEST_MESSAGE may ask for (None if the vehicle does not have it)."""

    def __init__(self, flight: Flight, message_for: Callable[[int], Any | None],
                 set_interval: Callable[[int, float], bool]) -> None:
        self.flight = flight
        self.message_for = message_for
        self.set_interval = set_interval

    def execute(self, msg: Any) -> CommandOutcome:
        """Run a COMMAND_LONG or COMMAND_INT; never raises for bad parameters."""
        command = int(msg.command)
        params = [msg.param1, msg.param2, msg.param3, msg.param4]
        if msg.get_type() == "COMMAND_INT":
            params += [msg.x / 1e7, msg.y / 1e7, msg.z]
        else:
            params += [msg.param5, msg.param6, msg.param7]
        handler = getattr(self, f"_cmd_{command}", None)
        if handler is None:
            return CommandOutcome(mavlink.MAV_RESULT_UNSUPPORTED, f"command {command} is not supported")
        try:
            return handler(params)
        except (ValueError, OverflowError) as exc:
            return CommandOutcome(mavlink.MAV_RESULT_DENIED, f"bad parameters: {exc}")

    @staticmethod
    def _outcome(reason: str | None) -> CommandOutcome:
        if reason is None:
            return CommandOutcome(mavlink.MAV_RESULT_ACCEPTED)
        return CommandOutcome(mavlink.MAV_RESULT_DENIED, reason)

    def _cmd_400(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_COMPONENT_ARM_DISARM
        if p[0] >= 0.5:
            reason = self.flight.arm()
            return self._outcome(reason) if reason is None else CommandOutcome(
                mavlink.MAV_RESULT_TEMPORARILY_REJECTED, reason)
        return self._outcome(self.flight.disarm(force=int(p[1]) == ARM_FORCE_MAGIC))

    def _cmd_176(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_SET_MODE
        if not int(p[0]) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return CommandOutcome(mavlink.MAV_RESULT_UNSUPPORTED, "only custom modes are supported")
        mode = mode_from_command(self.flight.flavour, p[1], p[2])
        if mode is None:
            return CommandOutcome(mavlink.MAV_RESULT_DENIED, f"unknown mode {p[1]:.0f}/{p[2]:.0f}")
        return self._outcome(self.flight.set_mode(mode))

    def _cmd_300(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_MISSION_START
        first = int(p[0])
        if first > 0 and not self.flight.set_current(first):
            return CommandOutcome(mavlink.MAV_RESULT_DENIED, f"no mission item {first}")
        return self._outcome(self.flight.set_mode(Mode.AUTO))

    def _cmd_22(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_TAKEOFF
        alt = p[6]
        if self.flight.flavour == "px4" and math.isfinite(alt):
            alt -= self.flight.origin.alt_m  # PX4 takes the altitude above mean sea level
        elif not math.isfinite(alt):
            alt = 2.5  # PX4's MIS_TAKEOFF_ALT default when no altitude is given
        return self._outcome(self.flight.takeoff(alt))

    def _cmd_20(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_RETURN_TO_LAUNCH
        return self._outcome(self.flight.set_mode(Mode.RTL))

    def _cmd_21(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_LAND
        return self._outcome(self.flight.set_mode(Mode.LAND))

    def _cmd_17(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_NAV_LOITER_UNLIM
        return self._outcome(self.flight.set_mode(Mode.HOLD))

    def _cmd_252(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_PAUSE_CONTINUE
        return self._outcome(self.flight.set_mode(Mode.AUTO if p[0] >= 0.5 else Mode.HOLD))

    def _cmd_178(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_CHANGE_SPEED
        return self._outcome(self.flight.set_speed(p[1]))

    def _cmd_224(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_DO_SET_MISSION_CURRENT
        if self.flight.set_current(int(p[0])):
            return CommandOutcome(mavlink.MAV_RESULT_ACCEPTED)
        return CommandOutcome(mavlink.MAV_RESULT_DENIED, f"no mission item {int(p[0])}")

    def _cmd_512(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_REQUEST_MESSAGE
        message = self.message_for(int(p[0]))
        if message is None:
            return CommandOutcome(mavlink.MAV_RESULT_UNSUPPORTED, f"message {int(p[0])} is not available")
        return CommandOutcome(mavlink.MAV_RESULT_ACCEPTED, follow_up=[message])

    def _cmd_520(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES
        return self._cmd_512([float(mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION)])

    def _cmd_410(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_GET_HOME_POSITION
        return self._cmd_512([float(mavlink.MAVLINK_MSG_ID_HOME_POSITION)])

    def _cmd_511(self, p: list[float]) -> CommandOutcome:  # MAV_CMD_SET_MESSAGE_INTERVAL
        if self.set_interval(int(p[0]), p[1]):
            return CommandOutcome(mavlink.MAV_RESULT_ACCEPTED)
        return CommandOutcome(mavlink.MAV_RESULT_UNSUPPORTED, f"message {int(p[0])} is not streamed")
