"""What the sortie logic asks the service to do: one frozen record per effect. The logic
returns them; ``app.py`` carries them out (journal, link, planner, zenoh) and feeds the
outcome back as an input. Nothing here does I/O."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from protocol import MissionItem

from ..events import ServiceEvent
from ..planning import PlannedPath, PlannedPoint
from .fleet import Claims
from .mission import HeldMission


@dataclass(frozen=True)
class PlanBasis:
    """Where the next decision starts from."""

    reason: str
    version: int
    """The sortie logic's version when it asked: a result of an older one is stale."""
    keep_through: int | None
    """A replacement keeps the held mission's items up to this seq; None: a fresh mission."""
    at_point: PlannedPoint | None = None
    """Plan from this point, the vehicle holding there (its hold counted as done)."""
    serving: str | None = None
    """The user served at ``at_point``: counted as served, its tasks consumed."""
    serving_reward: float = 0.0
    """That service's q as the hold's end will record it (a whole hold): the sortie's
    average reward, which ``mcts`` maximises, counts it with the interval it takes."""
    settles: bool = False
    """The plan's first point is flown to once its claim has settled among the fleet's
    members (the vehicle meanwhile flies on as it was: on the ground, on its way home); not
    for a vehicle holding (the hold waits instead), nor one flying to a point lost (``pauses``)."""
    pauses: bool = False
    """The vehicle flies to a point lost to another member: the replacement goes up at once,
    its first item a pause where the vehicle is, ended once the first point's claim has
    settled (``SortieLogic._maybe_end_pause``): flying on to the lost point must end, and
    flying to the new one before its claim settles met a member that chose it too."""


@dataclass(frozen=True)
class MakePlan:
    """Search the next plan from ``basis`` (answered by ``Planned`` or ``PlanFailed``)."""

    basis: PlanBasis


@dataclass(frozen=True)
class Upload:
    plan_id: int
    items: tuple[MissionItem, ...]
    mission: HeldMission
    """What the vehicle holds once the upload is accepted."""
    path: PlannedPath
    current_seq: int | None
    """The item the vehicle must fly after the upload (set when it differs); None: the
    autopilot's own (an index it keeps)."""
    keep_through: int | None
    restart_current: bool = False
    """Start ``current_seq`` again even if the vehicle flies it (its content changed, and the
    autopilot restarts no return-to-launch item by itself)."""
    planner_ms: float = 0.0
    newest_request: int = 0


@dataclass(frozen=True)
class ReadBack:
    why: str


CommandKind = Literal["start", "resume", "return", "hold", "set_current"]


@dataclass(frozen=True)
class Command:
    kind: CommandKind
    seq: int = -1
    """For set_current: the item to fly now."""
    why: str = ""


@dataclass(frozen=True)
class RecordService:
    request_id: int
    user_id: str
    hover_index: int
    xyz: tuple[float, float, float]
    tasks: int
    bits: float
    reward: float
    held_s: float
    planned_request: bool
    """The request served is the one the plan was made for."""
    bound_tasks: int
    """The backlog the hold was bound to (``tasks`` or more: a hold cut short carries less)."""


@dataclass(frozen=True)
class RecordMission:
    plan_id: int
    mission: HeldMission
    result: str


@dataclass(frozen=True)
class Emit:
    """An event for the events publication."""

    event: ServiceEvent


@dataclass(frozen=True)
class PublishPlan:
    mission: HeldMission
    predicted_energy_j: float = 0.0


@dataclass(frozen=True)
class Intend:
    """Tell the fleet what this member claims now (its points and their users): the service
    of a fleet member puts it in its signed intentions; a lone UAV's does nothing."""

    claims: Claims


@dataclass(frozen=True)
class Log:
    level: Literal["info", "warning", "error"]
    text: str


@dataclass(frozen=True)
class Unsettled:
    """Plan ``plan_id`` is flown though the claim of its first point ``point`` has not settled
    within ``waited_s`` (``fleet.settle_max_s``): the service warns, naming the members whose
    intentions signed since the claim it has not heard (only it knows whom it waited on)."""

    plan_id: int
    point: int
    waited_s: float


@dataclass(frozen=True)
class EndSortie:
    why: str


@dataclass(frozen=True)
class BeginSortie:
    battery_fraction: float


@dataclass(frozen=True)
class MarkFlown:
    """Note in the journal that this sortie has flown (a landing while the service is down
    still ends it)."""


Effect = (MakePlan | Upload | ReadBack | Command | RecordService | RecordMission | Emit | PublishPlan | Intend | Log
          | Unsettled | EndSortie | BeginSortie | MarkFlown)
