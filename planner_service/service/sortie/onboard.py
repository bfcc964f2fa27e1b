"""What the service knows of the mission on board the vehicle: the one it holds, whether
that is known or in doubt, an upload whose outcome is unknown, and the reports kept until
the doubt is resolved. Pure.

Its fields change together: an upload accepted, a read-back or a doubt sets ``held``,
``known``, ``unconfirmed`` and ``doubt`` in one step."""

from __future__ import annotations

from dataclasses import dataclass, replace

from protocol import MissionItem, same_mission
from protocol.mission import Flavour

from .. import events as ev
from . import effects as fx
from .hold import Sample
from .mission import HeldMission

MAX_DOUBTED = 1200
"""Reports kept while in doubt: a minute of the service's ticks (the oldest are dropped)."""


@dataclass(frozen=True)
class OnBoard:
    """The mission on board, as far as the service knows."""

    held: HeldMission | None = None
    known: bool = False
    """The vehicle is known to hold ``held`` (an upload accepted, a read-back); False while
    in doubt or before it is known."""
    unconfirmed: HeldMission | None = None
    """An upload whose outcome is unknown: the vehicle may hold it."""
    doubt: str | None = None
    """Why the vehicle may hold another mission than ``held``: read it back first."""
    must_upload: bool = False
    """The vehicle lost its mission in the air: upload whatever the plan."""
    resume_pending: bool = False
    """A mission re-planned in the air is to be resumed (or the operator told it waits)."""
    resume_told: int = -1
    """The plan the operator was told waits for ``operator start`` (``resume_needed``): a
    restart seen late (the link's clock check can follow the mission's read-back, one
    restart seen twice) does not tell it again."""
    restarted: bool = False
    """The vehicle restarted since the last read-back: the holds it flew were cut."""
    doubted: tuple[Sample, ...] = ()
    """The vehicle's reports while in doubt or an upload is in flight (``_replay``), at most
    ``MAX_DOUBTED``."""
    last: HeldMission | None = None
    """The mission the vehicle held when the sortie before ended: a read-back showing it
    (a restart seen after the next sortie began, as PX4 SITL's is) shows ours, not
    another station's."""

    def next_sortie(self) -> OnBoard:
        """What a new sortie knows of the mission on board: nothing of its own yet, and the
        last sortie's mission, to know it again."""
        return OnBoard(last=self.held or self.last)

    def last_sorties(self, items: tuple[MissionItem, ...], flavour: Flavour) -> tuple[OnBoard, list[fx.Effect]] | None:
        """A read-back that shows the last sortie's mission: nothing is held of this sortie's,
        the doubt is resolved (None: it shows another)."""
        last = self.last
        if self.held is not None or last is None or not same_mission(items, last.items, flavour):  # type: ignore[arg-type]
            return None
        return (replace(self, doubt=None, restarted=False, doubted=()),
                [fx.Log("info", f"{self.doubt}: the vehicle holds plan {last.plan_id} of the sortie before "
                                f"(read back); this sortie's first plan replaces it")])

    def doubting(self, why: str) -> tuple[OnBoard, list[fx.Effect]]:
        """The vehicle may hold another mission: nothing it reports counts until it is read
        back."""
        return (replace(self, doubt=why, known=False),
                [fx.Log("warning", f"{why}: the mission held will be read back before planning")])

    def rechecking(self, why: str) -> OnBoard:
        """A periodic read-back of a mission known (no disagreement, nothing to log as one)."""
        return replace(self, doubt=why, known=False)

    def keep(self, sample: Sample, uploading: bool) -> OnBoard:
        """A report while the mission flown is not known (in doubt, or an upload in flight):
        kept in order, to be judged once it is known (``_replay``)."""
        if self.doubt is None and not uploading:
            return self
        if self.doubted and self.doubted[-1].boot_s >= sample.boot_s:
            return self  # reordered or repeated: the reports are kept in the vehicle's time
        return replace(self, doubted=(*self.doubted, sample)[-MAX_DOUBTED:])

    def replayed(self) -> tuple[OnBoard, tuple[Sample, ...]]:
        """The reports kept, taken out to be judged."""
        return replace(self, doubted=()), self.doubted

    def accepted(self, mission: HeldMission) -> OnBoard:
        """The vehicle accepted ``mission``'s upload: it holds it."""
        return replace(self, held=mission, known=True, unconfirmed=None, must_upload=False)

    def maybe(self, mission: HeldMission) -> OnBoard:
        """An upload whose outcome is unknown (or that failed part-way): the vehicle may hold it."""
        return replace(self, unconfirmed=mission)

    def matching(self, items: tuple[MissionItem, ...], flavour: Flavour) -> HeldMission | None:
        """Which mission of ours a read-back shows: the one held or the unconfirmed upload."""
        for candidate in (self.held, self.unconfirmed):
            if candidate is not None and same_mission(items, candidate.items, flavour):  # type: ignore[arg-type]
                return candidate
        return None

    def confirmed(self, candidate: HeldMission, airborne: bool) -> tuple[OnBoard, list[fx.Effect]]:
        """The read-back shows ``candidate`` (``matching``). A restarted vehicle may hold our
        mission and still hover where it came back: it is resumed, and what it flew across
        its restart is not judged (its holds were cut): the reports kept are dropped."""
        out: list[fx.Effect] = []
        if candidate is not self.held:  # the upload whose ACK was lost went through
            out += [fx.RecordMission(candidate.plan_id, candidate, "accepted"), fx.PublishPlan(candidate)]
        out.append(fx.Log("info", f"{self.doubt}: the vehicle holds plan {candidate.plan_id} (read back)"))
        return replace(self, held=candidate, known=True, unconfirmed=None, doubt=None, restarted=False,
                       resume_pending=self.restarted and airborne,
                       doubted=() if self.restarted else self.doubted), out

    def foreign(self, items: int, home_slots: int) -> bool:
        """A read-back of ``items`` items that no upload of ours explains (not one cut short:
        an upload of ours is then unconfirmed): another station's mission."""
        return self.unconfirmed is None and items > home_slots

    def lost(self, items: int, airborne: bool, foreign: bool) -> tuple[OnBoard, list[fx.Effect]]:
        """The read-back shows none of our missions: nothing is held any more. Another
        station's (``foreign``) is not ours to fly nor to replace; otherwise the vehicle lost
        ours (a restart, a link gap) and, in the air, is re-planned from where it is."""
        why = self.doubt
        ours = f"plan {self.held.plan_id}" if self.held is not None else "a mission of ours"
        if foreign:
            return OnBoard(), [fx.Log("warning", f"{why}: the vehicle holds a mission of {items} items that is not "
                                                 f"ours ({ours}): another station's; left to the operator")]
        detail = f"{why}: the vehicle holds {items} items, not {ours}; re-planning from where it is"
        out: list[fx.Effect] = [fx.Log("warning", detail)]
        if not why or "restarted" not in why:
            out.append(fx.Emit(ev.VehicleRestarted(detail[:256])))
        return OnBoard(must_upload=airborne, resume_pending=airborne), out
