"""What the simulated aircraft reports to its link: one frozen dataclass per kind of event.

``Flight.step`` and the commands return these; the runner turns each into MAVLink
(``match`` on the type), so a new event that the runner does not handle is a type error a
checker finds, not a string compare that silently does nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union


@dataclass(frozen=True)
class ItemComplete:
    """Mission item ``seq`` is complete (its hold over): MISSION_ITEM_REACHED; ``command`` is
    the command that was flown (the mission may have changed under it since)."""

    seq: int
    command: int = 0


@dataclass(frozen=True)
class CurrentChanged:
    """The mission's current item is now ``seq`` (MISSION_CURRENT)."""

    seq: int


@dataclass(frozen=True)
class CurrentUnnamed:
    """A new mission marking no item current replaced the active one: PX4's mission manager
    names no item (MISSION_CURRENT seq UINT16_MAX, its ``_current_seq`` -1 from the
    upload) until the navigator settles on an index. PX4 sends that report only when its
    1 Hz stream falls in between; the stub always does, so what reads it meets it."""


@dataclass(frozen=True)
class MissionDone:
    """The last item, ``seq``, is complete: the mission is over."""

    seq: int


@dataclass(frozen=True)
class CommandStarted:
    """The mission started item ``seq`` (ArduPilot says ``Mission: 3 WP``)."""

    seq: int
    name: str


@dataclass(frozen=True)
class MissionRestarted:
    """A mission changed in flight restarted the command at ``seq`` (ArduPilot's
    ``Auto mission changed, restarted command``)."""

    seq: int


@dataclass(frozen=True)
class MissionRestartFailed:
    """A mission changed in flight no longer has item ``seq``: the command in progress
    goes on (``Auto mission changed but failed to restart command``)."""

    seq: int


@dataclass(frozen=True)
class ModeChangedItself:
    """The flight mode changed by itself (takeoff done, failsafe, mission end)."""


@dataclass(frozen=True)
class TouchedDown:
    """Touchdown."""


@dataclass(frozen=True)
class Armed:
    """The motors were armed."""


@dataclass(frozen=True)
class Disarmed:
    """The motors stopped; ``why`` is ``landed``, ``command`` or ``auto`` (ArduPilot's
    DISARM_DELAY: armed on the ground too long without taking off)."""

    why: str


@dataclass(frozen=True)
class BatteryLow:
    """The battery reached the return threshold in the air: returning home."""

    text: str


@dataclass(frozen=True)
class BatterySwapped:
    """A full battery again after ``recharge_s`` on the ground."""

    text: str


@dataclass(frozen=True)
class GpsFix:
    """The GPS has a 3-D fix (``GPS 1: detected u-blox`` on ArduPilot SITL)."""


@dataclass(frozen=True)
class OriginSet:
    """The estimator has a global origin; home is set (``EKF3 IMU0 origin set``)."""


@dataclass(frozen=True)
class UsingGps:
    """The estimator navigates with GPS: a position is valid (``EKF3 IMU0 is using GPS``)."""


@dataclass(frozen=True)
class HomeSet:
    """Home moved (set again at arming, as ArduPilot and PX4 do)."""


FlightEvent = Union[
    ItemComplete, CurrentChanged, CurrentUnnamed, MissionDone, CommandStarted, MissionRestarted, MissionRestartFailed,
    ModeChangedItself, TouchedDown, Armed, Disarmed, BatteryLow, BatterySwapped, GpsFix, OriginSet, UsingGps,
    HomeSet,
]
"""Every event the flight reports."""
