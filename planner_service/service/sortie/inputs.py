"""What the sortie logic is told: one frozen record per input, and the view of the vehicle
and of the journal it decides on. Nothing here does I/O.

The link's events (``link/events.py``) are inputs as they are, one class each, re-exported
here: what the autopilot reported reaches the logic without being renamed on the way."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, Protocol

from protocol import MissionItem

from ..link.events import (ArmedChanged, Connected, Current, OnGround, LinkEvent, Lost, ModeChanged, PositionChanged,
                           Reached, Restarted, Restored, StatusText, TelemetryMissing)
from ..planning import PlannedPath
from ..rows import RequestRow
from .effects import Command, PlanBasis, Upload
from .fleet import FleetView


@dataclass(frozen=True)
class VehicleSnapshot:
    """The vehicle as its telemetry shows it, in local metres (from the link's snapshot)."""

    connected: bool = False
    position_ok: bool = False
    """The autopilot has a position estimate (fix, EKF, home): never lat/lon 0/0."""
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    boot_s: float = math.nan
    """The vehicle's own clock when it reported the position."""
    armed: bool = False
    airborne: bool = False
    landed_known: bool = False
    mode: str = ""
    seq: int = -1
    """The mission item it flies (MISSION_CURRENT)."""
    mission_total: int = -1
    """The items of the mission it holds, as MISSION_CURRENT counts them (ArduPilot: less
    home); 0: none; -1: not said."""
    mission_id: int = 0
    """MISSION_CURRENT's ``mission_id``: the autopilot's id of the mission it holds (PX4: a
    CRC32 of its items, the ``opaque_id`` of the upload's MISSION_ACK); 0: not said
    (ArduPilot)."""
    battery_fraction: float | None = None
    """The best estimate: the autopilot's reading, else the model's fallback; None: unknown."""
    battery_source: Literal["autopilot", "model", "unknown"] = "unknown"
    time_rate: float | None = None
    """Vehicle seconds per wall second (a simulator may run faster); None: not measured yet."""



class JournalView(Protocol):
    """What the sortie logic reads of the journal (the current sortie)."""

    def request_for(self, user_id: str) -> RequestRow | None:
        """The user's request in force (pending), or None."""

    def services_of(self, user_id: str) -> int:
        """Services the user has had this sortie."""

    def service_counts(self) -> dict[str, int]:
        """Services each user has had this sortie (users with none are absent): one
        reading for every pending user."""

    def pending_count(self) -> int:
        """Requests waiting."""

    def pending(self) -> list[RequestRow]:
        """The requests waiting (one per user: its request in force)."""

    def served_elsewhere(self, user_id: str) -> str | None:
        """Why a hold that served ``user_id`` records nothing (in a fleet: another member
        serves it), or None."""


@dataclass(frozen=True)
class Tick:
    now: float


@dataclass(frozen=True)
class Planned:
    basis: PlanBasis
    path: PlannedPath
    planner_ms: float = 0.0
    newest_request: int = 0
    """The newest request id the decision saw (a client can tell whether its request is in)."""


@dataclass(frozen=True)
class PlanFailed:
    basis: PlanBasis
    error: str


@dataclass(frozen=True)
class Uploaded:
    upload: Upload
    upload_ms: float = 0.0
    mission_id: int = 0
    """The ``opaque_id`` of the MISSION_ACK that accepted it: the id MISSION_CURRENT names
    it by (PX4); 0: not said."""


@dataclass(frozen=True)
class NotUploaded:
    """The upload failed (``outcome_unknown``: no answer, the vehicle may hold it); the
    service's ``upload_failed`` event is what the logic makes of it."""

    upload: Upload
    error: str
    outcome_unknown: bool = False


@dataclass(frozen=True)
class ReadBackDone:
    items: tuple[MissionItem, ...]
    mission_id: int = 0
    """The ``opaque_id`` of the vehicle's MISSION_COUNT (PX4): the id of the mission read; 0:
    not said."""


@dataclass(frozen=True)
class ReadBackFailed:
    error: str


@dataclass(frozen=True)
class CommandDone:
    command: Command


@dataclass(frozen=True)
class CommandNotDone:
    """The autopilot refused the command, or never answered."""

    command: Command
    error: str


@dataclass(frozen=True)
class RequestIn:
    """A request was accepted (a user's backlog changed)."""

    user_id: str
    tasks: int


@dataclass(frozen=True)
class OperatorAsked:
    """The operator's command, read and checked at the edge (the wire's ``OperatorCommand``)."""

    command: Literal["start", "hold", "status"]
    reason: str = ""


@dataclass(frozen=True)
class SortieBegun:
    number: int


@dataclass(frozen=True)
class PartFailed:
    """A part the service needs (the journal) failed: the service degrades (its
    ``degraded`` event)."""

    why: str


@dataclass(frozen=True)
class WarmedUp:
    """The planner's kernels are compiled (or loaded from numba's cache): plans may begin."""


@dataclass(frozen=True)
class FleetHeard:
    """What the other members of a fleet own and claim changed (their signed intentions, a
    member come or gone): the users this member may not plan nor bind, the points it plans
    without."""

    view: FleetView


Input = (Tick | LinkEvent | Planned | PlanFailed | Uploaded | NotUploaded | ReadBackDone | ReadBackFailed | CommandDone
         | CommandNotDone | RequestIn | OperatorAsked | SortieBegun | PartFailed | WarmedUp | FleetHeard)

__all__ = ["ArmedChanged", "CommandDone", "CommandNotDone", "Connected", "Current", "FleetHeard", "Input", "JournalView",
           "LinkEvent", "Lost", "ModeChanged", "NotUploaded", "OnGround", "OperatorAsked", "PartFailed", "PlanFailed",
           "Planned", "PositionChanged", "Reached", "ReadBackDone", "ReadBackFailed", "RequestIn", "Restarted",
           "Restored", "SortieBegun", "StatusText", "TelemetryMissing", "Tick", "Uploaded", "VehicleSnapshot"]
