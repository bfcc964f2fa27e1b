"""What the service needs of an autopilot link, whichever library speaks MAVLink.

A backend keeps ``telemetry`` (the latest snapshot) current and reports events through the
``on_event`` callable it is given (called on the event loop's thread); the service awaits
``upload``, ``start`` and ``return_to_launch``, each of which raises ``LinkError`` saying
what was attempted and what the autopilot answered.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass, field
from typing import Callable, Sequence

from protocol import MissionItem

# ArduPilot Copter custom modes and PX4 (main, sub) modes, by the names ground stations show.
ARDUPILOT_MODES = {0: "STABILIZE", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL",
                   9: "LAND", 16: "POSHOLD", 17: "BRAKE"}
PX4_MODES = {(1, 0): "MANUAL", (2, 0): "ALTCTL", (3, 0): "POSCTL", (4, 1): "AUTO.READY",
             (4, 2): "AUTO.TAKEOFF", (4, 3): "AUTO.LOITER", (4, 4): "AUTO.MISSION", (4, 5): "AUTO.RTL",
             (4, 6): "AUTO.LAND", (5, 0): "ACRO", (6, 0): "OFFBOARD", (7, 0): "STABILIZED"}
RETURNING_MODES = frozenset({"RTL", "LAND", "AUTO.RTL", "AUTO.LAND", "RETURN_TO_LAUNCH", "LAND"})
MISSION_MODES = frozenset({"AUTO", "AUTO.MISSION", "MISSION"})
HOLDING_MODES = frozenset({"LOITER", "POSHOLD", "BRAKE", "AUTO.LOITER", "HOLD"})
"""Modes in which an airborne vehicle waits where it is (what a restarted autopilot does)."""


def mode_name(flavour: str, custom_mode: int) -> str:
    """The mode a HEARTBEAT's custom_mode names, as a ground station shows it."""
    if flavour == "px4":
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        return PX4_MODES.get((main, sub), PX4_MODES.get((main, 0), f"PX4 {main}/{sub}"))
    return ARDUPILOT_MODES.get(custom_mode, f"MODE {custom_mode}")


@dataclass(frozen=True)
class Telemetry:
    """The vehicle as last reported. ``valid`` is False until a position arrived."""

    valid: bool = False
    lat_deg: float = 0.0
    lon_deg: float = 0.0
    rel_alt_m: float = 0.0
    battery_fraction: float = 1.0
    energy_used_j: float | None = None
    """From BATTERY_STATUS.energy_consumed (hJ) when the autopilot reports it."""
    armed: bool = False
    airborne: bool = False
    landed_known: bool = False
    """The vehicle has said whether it is in the air (``airborne`` is a guess before)."""
    mode: str = ""
    mission_seq: int = 0
    mission_total: int = 0
    connected: bool = False
    position_at: float = 0.0
    """``time.monotonic()`` when the position was last reported."""
    battery_at: float = 0.0
    """``time.monotonic()`` when the battery was last reported."""
    time_rate: float = 1.0
    """Vehicle seconds per wall second (a simulator may run faster), from its timestamps."""


class ClockRate:
    """Vehicle seconds per wall second, measured from the vehicle's own timestamps over a
    window of a few seconds (so the service never assumes the two clocks run alike)."""

    WINDOW_S = 3.0

    def __init__(self) -> None:
        self._anchor: tuple[float, float] | None = None
        self.rate = 1.0

    def update(self, vehicle_s: float, wall_s: float) -> float:
        if self._anchor is None or vehicle_s < self._anchor[0]:
            self._anchor = (vehicle_s, wall_s)
            return self.rate
        dv, dw = vehicle_s - self._anchor[0], wall_s - self._anchor[1]
        if dw >= self.WINDOW_S:
            self.rate = max(dv / dw, 0.0)
            self._anchor = (vehicle_s, wall_s)
        return self.rate


@dataclass(frozen=True)
class LinkEvent:
    """Something the vehicle reported: ``kind`` is connected, lost, restored, restarted
    (the vehicle rebooted: its clock went back), reached (``seq``: a mission item
    completed), current (``seq`` now flown, ``total`` items: 0 none, -1 not said), mode (``text``:
    the new mode),
    landed, text (a STATUSTEXT).

    ``mission`` says which mission a reached or current event is about: the link's
    ``generation`` when the vehicle sent it. The generation grows when an upload is
    accepted, when a download shows what the vehicle holds and when the vehicle restarts,
    so a report sent before one of those (delayed or reordered on the link) is never read
    against the mission that followed."""

    kind: str
    seq: int = -1
    text: str = ""
    total: int = -1
    mission: int = 0


@dataclass
class LinkSettings:
    """What every backend needs (from ``MavlinkConfig``)."""

    url: str
    flavour: str
    item_timeout_s: float = 0.5
    retries: int = 10
    link_timeout_s: float = 3.0
    source_system: int = 255
    source_component: int = 190
    extra: dict = field(default_factory=dict)
    signing_key_file: str = ""
    """Sign with the key in this file (pymavlink backend; empty: no signing)."""
    signing_timestamp_file: str = ""
    """The signing timestamp's file (empty: beside the key)."""


class VehicleLink(abc.ABC):
    """One autopilot, one library."""

    def __init__(self, settings: LinkSettings, on_event: Callable[[LinkEvent], None]) -> None:
        self.settings = settings
        self.on_event = on_event
        self.telemetry = Telemetry()
        self.generation = 0
        """Which mission the vehicle holds, as far as this link knows (see ``LinkEvent``)."""

    @abc.abstractmethod
    async def connect(self, timeout_s: float) -> None:
        """Open the link and wait for the autopilot's first heartbeat (``LinkError`` after
        ``timeout_s``); afterwards the backend keeps reconnecting on its own."""

    @abc.abstractmethod
    async def upload(self, items: Sequence[MissionItem]) -> None:
        """Upload a whole mission with the protocol's retries. When this returns the
        autopilot holds it (``generation`` has grown); when it raises ``LinkError`` the
        autopilot kept its old mission, unless the error's ``outcome_unknown`` says that
        could not be found out."""

    @abc.abstractmethod
    async def download(self) -> list[MissionItem]:
        """The mission the autopilot holds (``generation`` grows: later reports are about
        it)."""

    @abc.abstractmethod
    async def start(self) -> None:
        """Arm and fly the mission (the operator allowed it)."""

    @abc.abstractmethod
    async def resume(self) -> None:
        """Fly the mission held from its start again, already armed and airborne (mode
        AUTO / AUTO.MISSION and MISSION_START): after the autopilot restarted in the air."""

    @abc.abstractmethod
    async def return_to_launch(self) -> None:
        """Command return to launch now."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Stop every thread and socket of the link."""
