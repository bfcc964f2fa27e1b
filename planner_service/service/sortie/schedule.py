"""The sortie's schedule: what the service has in flight (a plan, an upload, a read-back, a
command), when the next may go, and what the decisions are counted by. Pure.

Its fields change together: a plan or an upload sent, returned or failed moves ``busy``,
``failures`` and ``retry_at`` in one step, whatever the mission on board. Failures wait as
``Backoff`` says: doubling from ``retry_s`` up to ``max_retry_s``, given up after
``max_failures`` in a row until something changes (a request, the link, the operator)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

from .. import events as ev
from . import effects as fx

Busy = Literal["", "plan", "settle", "upload", "readback"]
"""What is in flight: a plan in search, a plan waiting for its first point's claim to settle
among a fleet's members (``settling``), an upload, a read-back."""


@dataclass(frozen=True)
class Backoff:
    """How failed plans, uploads and commands are retried (from ``Rules``)."""

    max_failures: int = 8
    retry_s: float = 1.0
    max_retry_s: float = 30.0

    def wait_s(self, failures: int) -> float:
        """The wait after the ``failures``-th failure in a row: doubling, capped."""
        return min(self.retry_s * 2 ** (failures - 1), self.max_retry_s)


@dataclass(frozen=True)
class Schedule:
    """What is in flight and when the next plan, read-back or command may go."""

    plan_id: int = 0
    """The last plan id given (a plan uploaded, or refused before its upload)."""
    version: int = 0
    """Bumped when a plan being searched is stale (doubt, restart, sortie over)."""
    busy: Busy = ""
    commanding: str = ""
    """The command sent and not yet answered ('' for none)."""
    failures: int = 0
    retry_at: float = 0.0
    readback_at: float = 0.0
    """The next read-back, apart from ``retry_at``: a doubt is resolved at once, whatever
    the plans' back-off (holds flown meanwhile are not judged), and only a failed read-back
    waits."""
    dirty: bool = True
    """Requests came in since the last plan."""
    dirty_at: float = -math.inf
    """When the first of them came in (a fleet member on its way home answers in its turn
    from then: ``fleet.answer_rank``)."""
    last_plan_at: float = -math.inf
    decided_at: int | None = None
    """The seq from whose hold the last decision was made (one decision per interval)."""
    last_hover_index: int = -1
    """The hover point the vehicle last arrived at (where the way home's decisions start)."""
    settling: fx.Upload | None = None
    """The upload of a plan made away from a hold (before the takeoff, on the way home),
    sent once its first point's claim has settled (``busy`` "settle"), kept until that
    upload is answered (its first point claimed all along)."""
    claimed_at: float = -math.inf
    """When the point this member flies to next was first claimed (a plan's first point,
    settling or uploaded): its settling is waited for from then."""
    pause_ended: tuple[int, int] | None = None
    """The pause (plan id, seq) whose end was commanded (``HeldMission.is_pause``): not
    commanded again while the vehicle's reports still show it."""
    outbid: bool = False
    """A plan before the takeoff was given up because another member claimed its first point
    first: the next plan does not wait for ``planner.min_requests`` again. The member had
    decided to fly on the requests it saw; the claim rule changed only what it serves, and
    the others now own some of those requests, so the count of the rest may never reach the
    minimum again (a fleet SITL run: uav2 lost three plans at the start to uav1 and uav3 and
    stayed on the ground for 45 s until uav3's service died)."""

    # --- what goes out and comes back ---------------------------------------------------------
    def planning(self) -> Schedule:
        """A plan asked of the planner: the requests so far are in it (and it is the one plan
        an ``outbid`` member makes without waiting for the minimum)."""
        return replace(self, busy="plan", dirty=False, outbid=False)

    def plan_returned(self, now: float) -> Schedule:
        """The planner answered (a plan or a failure)."""
        return replace(self, busy="", last_plan_at=now)

    def uploading(self, plan_id: int) -> Schedule:
        """Plan ``plan_id``'s upload sent (a settled one stays ``settling`` until it is
        answered: its first point stays claimed until the mission there is on board)."""
        return replace(self, busy="upload", plan_id=plan_id)

    def settle(self, upload: fx.Upload) -> Schedule:
        """``upload`` waits for its first point's claim to settle."""
        return replace(self, busy="settle", plan_id=upload.plan_id, settling=upload)

    def unsettled(self, outbid: bool = False) -> Schedule:
        """The plan waiting to settle is not flown (stale, or its point claimed first by
        another member: ``outbid``, on the ground): plan again."""
        if self.busy != "settle":
            return self
        return replace(self, busy="", settling=None, dirty=True, outbid=outbid)

    def uploaded(self, plan_id: int) -> Schedule:
        """The vehicle accepted plan ``plan_id``: the failures in a row end."""
        return replace(self, failures=0, plan_id=plan_id)

    def answered(self) -> Schedule:
        """What was in flight (an upload, a read-back) was answered."""
        return replace(self, busy="", settling=None)

    def reading_back(self) -> Schedule:
        return replace(self, busy="readback")

    def read_back_failed(self, now: float, retry_s: float) -> Schedule:
        """Only the read-back waits: the plans' back-off is not touched."""
        return replace(self, busy="", readback_at=now + retry_s)

    def command_sent(self, kind: str) -> Schedule:
        return replace(self, commanding=kind)

    def command_answered(self) -> Schedule:
        return replace(self, commanding="")

    def command_failed(self, now: float, backoff: Backoff) -> Schedule:
        """A refused command waits like a failed plan, counted with them (the abandonment
        is the plans' alone: ``failed``)."""
        n = self.failures + 1
        return replace(self, failures=n, retry_at=now + backoff.wait_s(n))

    def failed(self, why: str, now: float, backoff: Backoff) -> tuple[Schedule, list[fx.Effect]]:
        """A plan or upload failed: try again after a growing wait, give up after a bound."""
        n = self.failures + 1
        out: list[fx.Effect] = [fx.Emit(ev.UploadFailed(why[:256])), fx.Log("error", why)]
        if n >= backoff.max_failures:
            out.append(fx.Emit(ev.UploadAbandoned(f"{n} failures in a row; no more plans until the link, a "
                                                   f"request or the operator changes something"[:256])))
            return replace(self, failures=n, retry_at=math.inf, dirty=True), out
        return replace(self, failures=n, retry_at=now + backoff.wait_s(n), dirty=True), out

    # --- what changes the schedule from outside -----------------------------------------------
    def stale(self) -> Schedule:
        """What is being searched (or settling) now is made on a state that is gone (degraded)."""
        return replace(self.unsettled(), version=self.version + 1)

    def in_doubt(self) -> Schedule:
        """The vehicle may hold another mission: plans in search are stale, and the read-back
        goes at once, whatever the back-off."""
        return replace(self.unsettled(), version=self.version + 1, retry_at=0.0, readback_at=0.0)

    def link_restored(self, now: float) -> Schedule:
        """A new link is a change: the failures in a row are forgiven."""
        return replace(self, retry_at=min(self.retry_at, now), failures=0)

    def request_in(self, backoff: Backoff, now: float) -> Schedule:
        """A request is a change: plans given up on are tried again."""
        s = replace(self, failures=0, retry_at=0.0) if self.failures >= backoff.max_failures else self
        return replace(s, dirty=True, dirty_at=self.dirty_at if self.dirty else now)

    def granted(self) -> Schedule:
        """The operator gave the authority: whatever waited goes now."""
        return replace(self, failures=0, retry_at=0.0)

    def ended(self) -> Schedule:
        """The sortie is over: a plan in search or settling is stale (an upload or a read-back
        in flight is still answered)."""
        s = self.unsettled()
        return replace(s, version=s.version + 1, busy="" if s.busy == "plan" else s.busy)

    def next_sortie(self) -> Schedule:
        """The schedule a new sortie begins with: plan ids run on, anything in search is stale."""
        return Schedule(plan_id=self.plan_id, version=self.version + 1)
