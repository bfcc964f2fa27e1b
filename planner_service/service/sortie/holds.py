"""The holds of the mission held: the one watched, the request bound to it, the points
already judged, the hold the service ended early. Pure.

Its fields change together: a hold judged clears the watch and the binding and adds its
seq to ``judged`` in one step."""

from __future__ import annotations

from dataclasses import dataclass, replace

from .. import events as ev
from . import effects as fx
from .hold import HoldWatch
from ..planning import PlannedPoint
from .mission import HeldMission


@dataclass(frozen=True)
class Binding:
    """The request a hold serves, bound when the vehicle arrives at the point."""

    seq: int
    user_id: str
    request_id: int | None
    """None: nothing to serve there (``why_not``)."""
    tasks: int = 0
    needed_s: float = 0.0
    """The hold the bound tasks need from this point (upload time)."""
    planned: bool = False
    """The request bound is the one the plan was made for."""
    why_not: str = ""
    done: bool = False
    """The user said its upload is done (a newer request with no tasks)."""
    lost_to: str | None = None
    """The member heard owning the user during the hold (it bound the user first): kept once
    heard, since its claim goes when its own hold ends, maybe before this one's."""


@dataclass(frozen=True)
class Judged:
    """A hold judged to have served its bound request, its record waiting for the binding to
    settle among a fleet's members (``FleetView.bound_settled``): of two members that bound
    one user within a hearing delay, the one that bound it first records it."""

    point: PlannedPoint
    binding: Binding
    covered_s: float
    held_s: float
    why_left: str
    ended_s: float
    """The vehicle's time of its last report inside the hold (its end, as far as seen)."""
    since: float | None = None
    """When its wait began (the logic's clock, at the first tick after the judgement):
    recorded ``Rules.settle_max_s`` after at most."""


@dataclass(frozen=True)
class Holds:
    """The watch over the point flown and what was judged of the points before it."""

    watch: HoldWatch | None = None
    binding: Binding | None = None
    judged: frozenset[int] = frozenset()
    """Seqs of the mission held's points already judged (served or not)."""
    early_end: int | None = None
    """The seq whose hold the service ended early."""
    judged_unrecorded: Judged | None = None
    """The last hold's service, recorded once its binding has settled (a fleet's member)."""

    @property
    def unrecorded_user(self) -> str | None:
        """The user of the last hold's service while its record waits (still claimed bound)."""
        return self.judged_unrecorded.binding.user_id if self.judged_unrecorded is not None else None

    def closed(self, seq: int) -> Holds:
        """The hold at ``seq`` was judged: no watch, no binding, not judged again."""
        return replace(self, watch=None, binding=None, judged=self.judged | {seq})

    def abandoned(self, why: str) -> Holds:
        """The watch ended from outside (``HoldWatch.abandon``), to be judged as it stands."""
        return self if self.watch is None else replace(self, watch=self.watch.abandon(why))

    def skipped_unseen(self, held: HeldMission, seq: int) -> tuple[Holds, list[fx.Effect]]:
        """The points of ``held`` before item ``seq`` that no watch ever saw (reports lost, or
        the service was away): flown unseen, so no service is recorded for them."""
        out: list[fx.Effect] = []
        judged = self.judged
        for q, point in held.points:
            if q < seq and q not in judged:
                out.append(fx.Emit(ev.WaypointSkipped(f"point {point.hover_index}: not seen held (the vehicle "
                                                       f"flies item {seq})", user_id=point.user_id)))
                judged = judged | {q}
        return replace(self, judged=judged), out

    def kept_through(self, keep: int | None) -> Holds:
        """After an upload keeping the items up to ``keep`` (None: none): only the points
        kept stay judged."""
        return replace(self, judged=frozenset(q for q in self.judged if keep is not None and q <= keep))

    def user_said_done(self, user_id: str, tasks: int) -> Holds:
        """A newer request with no tasks from the user bound here: its upload is done."""
        b = self.binding
        if b is not None and b.user_id == user_id and tasks <= 0 and b.request_id is not None and not b.done:
            return replace(self, binding=replace(b, done=True))
        return self

    def served_why(self) -> str | None:
        """Why the hold watched may end now (the bound request is served), or None. The
        caller checks that the service may end it (``_maybe_end_hold``)."""
        w, b = self.watch, self.binding
        if w is None or b is None or w.phase != "holding" or self.early_end == w.seq:
            return None
        if b.request_id is None:
            return f"nothing to serve ({b.why_not})"
        if b.lost_to is not None:  # its hold records nothing: held on, it would only cost flight
            return f"{b.lost_to} serves {b.user_id} (it bound the user first)"
        if b.done:
            return "the user's upload is done"
        if w.covered_s >= b.needed_s:
            return f"held {w.covered_s:.1f} s, the {b.needed_s:.1f} s the bound request needs"
        return None
