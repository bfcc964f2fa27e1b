"""The sortie logic: one frozen state value and ``step(state, input) -> (state, effects)``.
Pure: no event loop, no sockets, no journal writes; ``app.py`` feeds it the vehicle's
telemetry and reports, the planner's results and the operator's commands, and carries out
the effects it returns.

What it decides, in the order a sortie goes:
- **Plan** on the ground once enough requests wait; upload the whole line, complete and
  ending in return to launch, and start it when the service has authority.
- **Truth from the vehicle**: every position report feeds a ``HoldWatch`` over the point
  the vehicle flies to. A service is recorded when the vehicle leaves a point it was seen
  holding at, for the tasks the observed hold carried; never from a mission index alone.
- **One decision per interval**: when the vehicle arrives at a point, the request in force
  for that point's user is bound, and the next point is decided from there (that service
  counted as done) and uploaded as a replacement that keeps every item up to the one held
  (``mission.replacement``): the hold goes on, the point after it is the new decision.
  A hold longer than the bound request needs is ended early (``set_current``).
- **Doubt**: after a link gap, a vehicle restart or our own restart, the vehicle may hold
  another mission: read it back before anything else, the reports seen meanwhile (and
  during an upload) judged once the mission it holds is known; a lost mission in the air is
  re-planned from where the vehicle is and resumed (with authority) or left to the operator
  (``resume_needed``).
- **Authority** (``authority.py``): modes and arming only when granted; any change the
  service did not command ends it.
- **Bounded retries**: a failed plan or upload is retried with a growing wait, and given up
  after ``max_failures`` in a row until something changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import assert_never

import numpy as np

from protocol import Area, GeoOrigin, HoverPoint, MissionItem, encode_path, replacement_items, same_mission, validate_mission
from protocol.errors import MissionError
from protocol.autopilot import Autopilot, autopilot_for
from protocol.mission import MAX_HOLD_S, Flavour, encoded_hold_s

from ...model import Scenario, hover_points, pack
from ...model.reward import interval_reward
from ..errors import PlanningError
from ..link.base import HOLDING_MODES, MISSION_MODES, RETURNING_MODES
from ...model.fleet.claims import lost_points
from ...model.interval import NO_USER, return_energy_j, served_user
from ..planning import PlannedPath, PlannedPoint, check_path, first_steps, hold_time_s, planning_battery_j
from ..rows import RequestRow
from .. import events as ev
from . import effects as fx
from . import inputs as ins
from .authority import Authority, next_sortie
from .evidence import Evidence, Settled, judge
from .fleet import Claims, FleetView, answer_rank, claims_now
from .hold import HoldWatch, Sample
from .holds import Binding, Holds, Judged
from .life import Life
from .mission import HeldMission
from .onboard import OnBoard
from .schedule import Backoff, Schedule

CONTROL_LATENCY_S = 0.1
"""Wall seconds from a hold's position report to the vehicle obeying the command that ends
it (a tick of the loop and a command's round trip): that much more hovering, in vehicle time,
is planned at each point."""
RETURN_ITEM_S = 2.0
"""Wall seconds a switch to the return item's mode (PX4's AUTO.RTL), seen while the vehicle
flies the item before its mission's return, waits for MISSION_CURRENT to show the return
item (PX4 sends the two in either order: on SITL at x10 the heartbeat came 80 ms first in
one sortie of three) before it is taken as nobody's."""
DISARM_LANDING_S = 2.0
"""Wall seconds a disarming on the service's own return waits for the landing's report (it
may follow the heartbeat showing the disarming) before it is taken as nobody's."""


@dataclass(frozen=True)
class Rules:
    """What the sortie logic needs of the configuration."""

    scenario: Scenario
    origin: GeoOrigin
    area: Area
    flavour: Flavour = "ardupilot"
    start_mission: bool = False
    min_requests: int = 1
    replan_min_interval_s: float = 1.0
    hold_radius_m: float = 5.0
    rtl_battery_fraction: float = 0.1
    repeat: bool = True
    next_battery_fraction: float = 0.95
    max_mission_items: int = 512
    hold_margin_s: float = 1.0
    energy_margin_j: float = 0.0
    max_failures: int = 8
    retry_s: float = 1.0
    max_retry_s: float = 30.0
    readback_interval_s: float = 30.0
    """Wall seconds between read-backs of the mission flown under authority (``evidence.judge``):
    what no report shows (ArduPilot names no mission) is found within this; 0: never."""
    leg_tolerance_m: float = 30.0
    """How far (horizontally) the vehicle may be off the leg it flies to a point of ours
    before the mission is read back (``evidence.judge``); 0: not checked."""
    vehicle: str = ""
    """This fleet member's vehicle id (ties in ``fleet.answer_rank`` go to the id sorting first)."""
    answer_step_s: float = 2.0
    """Wall seconds a member on its way home waits, after new requests came in, for each
    member on its way home that answers them first (``fleet.answer_rank``)."""
    answer_tie_m: float = 50.0
    """Members whose distances to the pending users differ by at most this answer in the
    order of their ids."""
    max_answer_rank: int = 3
    """At most this many steps are waited (the nearer members may be unable to answer)."""
    settle_max_s: float = 0.0
    """A fleet member flies to a decision's first point once its claim has settled
    (``FleetView.settled``), waiting at most this long (wall seconds); 0: at once (a lone UAV)."""
    autopilot: Autopilot = field(init=False, repr=False, compare=False)
    """The configured autopilot's profile (``protocol.autopilot``), derived from ``flavour``
    once, when the rules are made (read at every step; not a constructor argument): an
    unknown flavour is refused then (``MissionError("flavour")``), not at the first use."""

    def __post_init__(self) -> None:
        # frozen: the derived field is set as the dataclass's own __init__ sets fields
        object.__setattr__(self, "autopilot", autopilot_for(self.flavour))

    def __reduce__(self) -> tuple[type, tuple[object, ...]]:
        # copied or pickled as its arguments: the profile is derived again (it holds
        # mapping proxies, which neither pickle nor deepcopy take)
        return type(self), tuple(getattr(self, f.name) for f in fields(self) if f.init)

    @property
    def backoff(self) -> Backoff:
        """How failed plans, uploads and commands are retried (``schedule.Backoff``)."""
        return Backoff(self.max_failures, self.retry_s, self.max_retry_s)

    @property
    def mode_names(self) -> dict[str, str]:
        a = self.autopilot
        return {"start": a.mission_mode, "resume": a.mission_mode, "return": a.return_mode, "hold": a.hold_mode}


def first_point(up: fx.Upload) -> PlannedPoint | None:
    """The point ``up``'s mission flies to first (after the items it keeps), or None (home)."""
    after = up.mission.points_after(-1 if up.keep_through is None else up.keep_through)
    return after[0][1] if after else None


@dataclass(frozen=True)
class Sortie:
    """Everything the sortie logic knows, as records that change apart; a new sortie is a new
    value."""

    life: Life = field(default_factory=Life)
    """Where the sortie is in its life (``life.py``)."""
    authority: Authority = field(default_factory=Authority)
    """Who may command the vehicle (``authority.py``)."""
    onboard: OnBoard = field(default_factory=OnBoard)
    """The mission on board as far as the service knows (``onboard.py``)."""
    holds: Holds = field(default_factory=Holds)
    """The hold watched and the points judged (``holds.py``)."""
    schedule: Schedule = field(default_factory=Schedule)
    """What is in flight and when the next may go (``schedule.py``)."""
    evidence: Evidence = field(default_factory=Evidence)
    """What the vehicle's reports say of whose mission it flies (``evidence.py``)."""
    fleet: FleetView = field(default_factory=FleetView)
    """What the other members of a fleet own and claim, as last heard (``fleet.py``)."""
    claims: Claims = field(default_factory=Claims)
    """What this member last told the fleet it claims (``fleet.py``)."""


Step = tuple[Sortie, list[fx.Effect]]


class SortieLogic:
    """``step`` with the rules and the journal view it needs (both fixed for its life)."""

    def __init__(self, rules: Rules, world: ins.JournalView) -> None:
        self.rules = rules
        self.world = world
        self.p = pack(rules.scenario)
        self.points = hover_points(rules.scenario)

    # --- entry ------------------------------------------------------------------------------
    def step(self, s: Sortie, event: ins.Input, v: ins.VehicleSnapshot, now: float) -> Step:
        out: list[fx.Effect] = []
        match event:
            case ins.Tick():
                s = self._tick(s, v, now, out)
            case ins.Connected(mode=mode):
                s = self._connected(s, v, mode, out)
            case ins.Lost(detail=why):
                out += [fx.Emit(ev.LinkLost(why)), fx.Log("warning", f"link lost: {why}")]
            case ins.Restored(mode=mode):
                out += [fx.Emit(ev.LinkRestored(mode)), fx.Log("info", f"link restored ({mode})")]
                if s.onboard.held is not None or s.life.flown:
                    s = self._doubt(s, "the link was lost", out)
                s = replace(s, schedule=s.schedule.link_restored(now))
            case ins.Restarted(detail=why):
                # A restart only ever ends the authority: nothing the service commanded holds
                # across it, and a restart is what an unsigned link can forge.
                s = self._revoke(replace(s, onboard=replace(s.onboard, restarted=True)),
                                 f"the autopilot restarted ({why})", out)
                out.append(fx.Emit(ev.VehicleRestarted(why[:256])))
                s = self._doubt(s, f"the vehicle restarted: {why}", out, hold_interrupted=True)
            case ins.ModeChanged(mode=mode, commanded=commanded):
                s = self._mode(s, v, mode, commanded, now, out)
            case ins.ArmedChanged(armed=armed, commanded=commanded):
                s = self._arming(s, v, armed, commanded, now, out)
            case ins.OnGround():
                if s.life.flown and not (s.life.homing or self._on_return(s, v)):
                    s = self._revoke(s, f"the vehicle landed away from its mission's return (item {v.seq}, "
                                        f"{v.mode or 'mode unknown'}): not the service's landing", out)
                if s.life.flown:
                    s = self._end(s, "the vehicle landed", v, out)
            case ins.Planned():
                s = self._planned(replace(s, schedule=s.schedule.plan_returned(now)), event, v, now, out)
            case ins.PlanFailed(error=error):
                s = self._failed(replace(s, schedule=s.schedule.plan_returned(now)),
                                 f"plan {s.schedule.plan_id + 1} not flown: {error}", now, out)
            case ins.Uploaded():
                s = self._uploaded(replace(s, schedule=s.schedule.answered()), event, v, out)
                s = self._known(s, now, event.mission_id)
            case ins.NotUploaded(upload=up, error=error, outcome_unknown=unknown):
                s = self._upload_failed(replace(s, schedule=s.schedule.answered()), up, error, unknown, v, now, out)
            case ins.ReadBackDone(items=items):
                s = self._read_back(replace(s, schedule=s.schedule.answered()), items, v, out)
                s = self._known(s, now, event.mission_id, read_back=True)
            case ins.ReadBackFailed(error=error):
                out.append(fx.Log("warning", f"could not read back the vehicle's mission ({s.onboard.doubt}): {error}; "
                                             f"trying again"))
                s = replace(s, schedule=s.schedule.read_back_failed(now, self.rules.retry_s))
            case ins.CommandDone(command=cmd):
                s = self._command_done(replace(s, evidence=s.evidence.commanded(),
                                               schedule=s.schedule.command_answered()), cmd, now, out)
            case ins.CommandNotDone(command=cmd, error=error):
                s = self._command_failed(replace(s, schedule=s.schedule.command_answered()), cmd, error, now, out)
            case ins.RequestIn(user_id=user, tasks=tasks):
                s = self._request(s, user, tasks, now, out)
            case ins.OperatorAsked():
                raise TypeError("operator commands go through SortieLogic.operator")
            case ins.SortieBegun(number=number):
                s = self._begun(s, number, out)
            case ins.PartFailed(why=why):
                life, said = s.life.degrade(why)
                if said:  # the first reason stays; plans in search are stale
                    s = replace(s, life=life, schedule=s.schedule.stale())
                    out += said
            case ins.WarmedUp():
                s = replace(s, life=replace(s.life, warming=False))
            case ins.Reached() | ins.Current() | ins.PositionChanged():
                # Progress and position are read from the telemetry at each tick: holds are
                # judged from where the vehicle is, never from a mission index alone.
                return s, out
            case ins.StatusText() | ins.TelemetryMissing():
                return s, out  # the link logs them; what they change shows in its telemetry
            case ins.FleetHeard(view=view):
                s = self._heard(s, view, now)
            case _:
                assert_never(event)
        if not isinstance(event, ins.Tick):
            s = self._next(s, v, now, out)
        return self._intend(s, v, now, out), out

    # --- the fleet ------------------------------------------------------------------------------
    def _heard(self, s: Sortie, view: FleetView, now: float) -> Sortie:
        """The other members' claims changed: users another member no longer owns are this
        member's to plan again (a member gone, a plan changed), a point this member flies to
        that another now claims is given up at the next decision (``_plan_wanted``), and a
        hold whose user another member owns (it bound the user first) will record nothing,
        even if that member's claim is gone by the end of the hold."""
        freed = set(s.fleet.owners) - set(view.owners)
        s = replace(s, fleet=view)
        b = s.holds.binding
        if b is not None and b.request_id is not None and b.lost_to is None and view.owner(b.user_id) is not None:
            s = replace(s, holds=replace(s.holds, binding=replace(b, lost_to=view.owner(b.user_id))))
        if freed:
            s = replace(s, schedule=s.schedule.request_in(self.rules.backoff, now))
        return s

    def _intend(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        """Tell the fleet what this member claims whenever it changes (``_claims``), the way
        home judged first on the mission held now (a decision on the way home, accepted,
        flies a point: claimed from then, not from the next report's tick)."""
        s = self._homing(s, v)
        claims = self._claims(s, v)
        if claims == s.claims:
            return s
        out.append(fx.Intend(claims))
        if claims.flying_to is not None and claims.flying_to != s.claims.flying_to:
            s = replace(s, schedule=replace(s.schedule, claimed_at=now))
        return replace(s, claims=claims)

    def _claims(self, s: Sortie, v: ins.VehicleSnapshot) -> Claims:
        """What this member claims now (``fleet.claims_now``): the point it flies to from the
        moment its mission there is on board, or its plan there settles, the point it holds.
        While its mission is read back (a doubt, the periodic check) what it claimed stands:
        its vehicle flies on meanwhile, and claims given up for the read-back were planned by
        the others, then claimed again by a later time and lost to them."""
        if s.onboard.doubt is not None and s.onboard.held is not None and not s.life.homing and s.life.over is None:
            return s.claims
        held = s.onboard.held if s.onboard.known else None
        claims = claims_now(held, s.holds, v.seq, s.life.homing or s.life.over is not None)
        up = s.schedule.settling
        first = first_point(up) if up is not None else None
        if first is not None:
            claims = replace(claims, flying_to=first.hover_index, next_user=first.user_id)
        return replace(claims, answering=True) if self._answers(s, v) else claims

    def _pending(self, s: Sortie) -> list[RequestRow]:
        """The requests pending here that no other member owns (nor this member's last hold
        served, its record waiting: ``_record_due``)."""
        unrecorded = s.holds.unrecorded_user
        return [r for r in self.world.pending() if s.fleet.owner(r.user_id) is None and r.user_id != unrecorded]

    def _pending_count(self, s: Sortie) -> int:
        """How many requests are pending here that no other member owns (read at every tick:
        the journal's count for a lone UAV)."""
        return len(self._pending(s)) if s.fleet.owners else self.world.pending_count()

    def _request_for(self, s: Sortie, user_id: str) -> RequestRow | None:
        """``user_id``'s request in force here, unless another member owns the user."""
        return None if s.fleet.owner(user_id) is not None else self.world.request_for(user_id)

    # --- the periodic look at the vehicle --------------------------------------------------------
    def _tick(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        if s.life.just_started and v.connected and v.landed_known:
            s = replace(s, life=replace(s.life, just_started=False))
            if v.airborne or (v.armed and not s.life.started and s.schedule.commanding != "start"):
                # The service (re)started with the vehicle in the air, or armed by someone:
                # what was done to the vehicle while it was away (a pilot's switch and back)
                # cannot be known.
                where = "in the air" if v.airborne else "armed on the ground"
                s = self._revoke(s, f"the service started with the vehicle {where} (in {v.mode}): what "
                                    f"happened to it meanwhile is not known", out)
        life, said = s.life.airborne(v)
        s = replace(s, life=life)
        out += said
        if (s.life.flown and s.life.over is None and v.connected and v.landed_known and not v.airborne and not v.armed):
            s = self._end(s, "the vehicle was found landed", v, out)
        life, begin = s.life.next_wanted(v, repeat=self.rules.repeat,
                                         next_battery_fraction=self.rules.next_battery_fraction)
        life, lapsed = life.start_lapsed(v, now, s.authority.granted)
        s = replace(s, life=life)
        out += begin + lapsed
        s = self._watch(s, v, now, out)
        s = self._maybe_end_pause(s, v, now, out)
        s = self._record_due(s, v, now, out)
        s = self._return_check(s, v, now, out)
        s = self._homing(s, v)
        s = self._disarm_check(s, v, now, out)
        s = self._check_mission(s, v, now, out)
        s = self._safety(s, v, out)
        return self._next(s, v, now, out)

    def _next(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        """Start whatever is due and not running: a read-back, a plan, a command (none while a
        switch of mode awaits its judgement: whose it is decides whether the service may)."""
        if s.schedule.busy == "settle":
            s = self._settle(s, now, out)
        if s.life.over is not None or s.life.degraded is not None or s.life.return_seen_at is not None:
            return s
        if s.schedule.busy == "" and s.onboard.doubt is not None and v.connected and now >= s.schedule.readback_at:
            out.append(fx.ReadBack(s.onboard.doubt))
            return replace(s, schedule=s.schedule.reading_back())
        if s.schedule.busy == "" and s.onboard.doubt is None and now >= s.schedule.retry_at:
            basis = self._plan_wanted(s, v, now)
            if basis is not None:
                out.append(fx.MakePlan(basis))
                s = replace(s, schedule=s.schedule.planning())
        if s.schedule.commanding == "" and now >= s.schedule.retry_at:
            s = self._command_due(s, v, out)
        return self._resume_needed(s, v, out)

    # --- holds: truth from the vehicle's position ---------------------------------------------
    def _watch(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        if s.onboard.held is None or not (v.connected and v.position_ok) or math.isnan(v.boot_s):
            return s
        sample = Sample(v.boot_s, v.xyz, v.seq)
        if not s.onboard.known or s.schedule.busy == "upload":
            # In doubt, or an upload in flight (the vehicle may fly the new mission before its
            # ACK reaches us: on a lossy link seconds, minutes of flight at x40): kept, and
            # judged once the mission the vehicle flies is known.
            return replace(s, onboard=s.onboard.keep(sample, uploading=s.schedule.busy == "upload"))
        return self._maybe_end_hold(self._seen(s, sample, v, out), now, out)

    def _seen(self, s: Sortie, sample: Sample, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        """One report of the vehicle flying ``held``: the watch fed, or begun at its item."""
        held = s.onboard.held
        assert held is not None
        if s.holds.watch is not None:
            s = self._feed(s, s.holds.watch, sample, v, out)
        if s.holds.watch is None:
            holds, said = s.holds.skipped_unseen(held, sample.seq)
            s = replace(s, holds=holds)
            out += said
            point = held.point_at(sample.seq)
            if point is not None and sample.seq not in s.holds.judged:
                watch = HoldWatch(sample.seq, (point.x_m, point.y_m, point.z_m), self.rules.hold_radius_m)
                s = self._feed(s, watch, sample, v, out)
        return s

    def _check_mission(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        """The vehicle's latest report against the mission held (``evidence.judge``), while
        it is known to hold it and nothing the service does now changes it: a disagreement
        reads the mission back."""
        held = s.onboard.held
        if (held is None or not s.onboard.known or s.schedule.busy not in ("", "settle") or s.onboard.doubt is not None
                or not v.connected):
            return s  # (a plan settling changes nothing on board)
        settled = Settled(over=s.life.over is not None, commanding=bool(s.schedule.commanding),
                          granted=s.authority.granted)
        evidence, doubt = judge(s.evidence, held, v, now, settled, leg_tolerance_m=self.rules.leg_tolerance_m,
                                readback_interval_s=self.rules.readback_interval_s)
        s = replace(s, evidence=evidence)
        if doubt is None:
            return s
        if doubt.periodic:  # no disagreement: nothing planned is stale
            out.append(fx.Log("info", f"{doubt.why}: reading the mission back"))
            return replace(s, onboard=s.onboard.rechecking(doubt.why), schedule=replace(s.schedule, readback_at=0.0))
        return self._doubt(s, doubt.why, out)

    def _known(self, s: Sortie, now: float, mission_id: int, *, read_back: bool = False) -> Sortie:
        """The vehicle was just seen to hold ``held`` (an upload accepted, a read-back)."""
        if s.onboard.held is None:
            return replace(s, evidence=s.evidence.no_mission())
        if not s.onboard.known:
            return s
        return replace(s, evidence=s.evidence.known(now, mission_id, read_back=read_back))

    def _replay(self, s: Sortie, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        """The reports kept during a doubt or an upload, judged now that the vehicle is known
        to hold ``s.onboard.held``: a hold flown meanwhile (on a lossy link a read-back or an upload
        takes seconds, tens of seconds of flight at x40, in which whole holds were flown) is
        recorded as the reports show it. Reports of the mission before, flown at the same
        item before the switch to this one, are judged against this one's point: the
        position decides, so at worst a hold there goes unrecorded, never a hold recorded
        where the vehicle was not. A hold that arrived meanwhile is bound to the request in
        force now, as its arrival is seen now."""
        onboard, kept = s.onboard.replayed()
        s = replace(s, onboard=onboard)
        if s.onboard.held is None:
            return s
        for sample in kept:
            s = self._seen(s, sample, v, out)
        return s

    def _feed(self, s: Sortie, watch: HoldWatch, sample: Sample, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        before = watch
        watch = watch.feed(sample)
        s = replace(s, holds=replace(s.holds, watch=watch))
        if watch.arrived and not before.arrived:
            s = self._arrived(s, v, out)
        return self._judge(s, out) if watch.over else s

    def _arrived(self, s: Sortie, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        """The vehicle is at the point: bind the request in force of the user the model's
        rule serves from here now (the nearest eligible, ties to the larger backlog: the rule
        the planner's futures follow), the planned user or, if its backlog or place changed,
        another."""
        assert s.holds.watch is not None and s.onboard.held is not None
        s = self._record_now(s, v, out)  # one binding claimed at a time
        seq = s.holds.watch.seq
        point = s.onboard.held.point_at(seq)
        assert point is not None
        recorded = [e for e in out if isinstance(e, fx.RecordService)]
        request = self._served_here(s, point, recorded)
        if request is None:
            planned = self._request_for(s, point.user_id)
            services = self._service_counts(recorded).get(point.user_id, 0)
            backlog = planned.backlog if planned is not None else 0
            why = "nobody eligible near" + (": the planned user has no request" if planned is None else (
                " (the planned user has nothing to offload)" if backlog <= 0 else
                f" (the planned user has {backlog} tasks after {services} services)"))
            binding = Binding(seq, point.user_id, None, why_not=why)
            out.append(fx.Emit(ev.WaypointReached(f"point {point.hover_index}: {why}", user_id=point.user_id)))
        else:
            backlog = request.backlog
            xyz = np.array([point.x_m, point.y_m, point.z_m])
            user = np.array([request.x_m, request.y_m, request.z_m])
            needed = hold_time_s(self.p, xyz, user, backlog * self.rules.scenario.bits_per_task)
            binding = Binding(seq, request.user_id, request.request_id, backlog, needed,
                              planned=request.request_id == point.request_id)
            out.append(fx.Emit(ev.WaypointReached(f"point {point.hover_index}: serving {backlog} tasks, "
                                                   f"{needed:.1f} s", user_id=request.user_id,
                               request_id=request.request_id)))
        return replace(s, holds=replace(s.holds, binding=binding),
                       schedule=replace(s.schedule, last_hover_index=point.hover_index))

    def _served_here(self, s: Sortie, point: PlannedPoint, recorded: list[fx.RecordService]) -> RequestRow | None:
        """The request the model's rule serves from ``point`` now (``model.served_user``).
        ``recorded``: the services this step records, which the journal holds only once the
        step's effects are done (the last hold, recorded at this arrival or judged earlier in
        the same replay of kept reports): counted as the journal will count them."""
        rows = [c for c in (r.with_served(recorded) for r in self._pending(s)) if c is not None]
        if not rows:
            return None
        users = np.array([[r.x_m, r.y_m, r.z_m] for r in rows], dtype=np.float64)
        tasks = np.array([r.backlog for r in rows], dtype=np.int64)
        counts = self._service_counts(recorded)
        served = np.array([counts.get(r.user_id, 0) for r in rows], dtype=np.int64)
        i = served_user(self.p, np.array([point.x_m, point.y_m, point.z_m]), users, tasks, served)
        return None if i == NO_USER else rows[i]

    def _service_counts(self, recorded: list[fx.RecordService]) -> dict[str, int]:
        """The users' services this sortie, with ``recorded`` (this step's, not yet in the
        journal) counted in."""
        counts = self.world.service_counts()
        for e in recorded:
            counts[e.user_id] = counts.get(e.user_id, 0) + 1
        return counts

    def _maybe_end_hold(self, s: Sortie, now: float, out: list[fx.Effect]) -> Sortie:
        """End the hold once the bound request is served, or once another member holding the
        point too keeps it (``_yield_why``): the replacement uploaded at the
        arrival restarted the autopilot's hold timer (ArduPilot restarts the current item
        when the items after it change; PX4 flies the item marked current), so the service,
        not the timer, ends it, as soon as the next item is the decision made from this
        point (uploaded) and the reports show the hold the request needs, and the next
        point's claim has settled (``_settled``: a member that claimed it first would be met
        there; yielding this point to another member does not wait). Only under its
        authority, not degraded: without, it commands nothing and the timer ends the hold."""
        w, held = s.holds.watch, s.onboard.held
        yielding = self._yield_why(s)
        why = s.holds.served_why() or yielding
        if why is None or w is None or held is None:
            return s
        if not s.authority.granted or s.life.degraded is not None:
            return s
        if s.schedule.decided_at != w.seq or s.schedule.busy in ("upload", "settle") or s.schedule.commanding:
            return s
        k = s.claims.flying_to
        if yielding is None and k is not None and not self._settled(s, k, s.schedule.claimed_at, now):
            return s  # the next point's claim has not settled: the vehicle stays on a point it holds
        point = held.point_at(w.seq)
        assert point is not None
        out.append(fx.Command("set_current", w.seq + 1, f"hold at point {point.hover_index} ended: {why}"))
        return replace(s, holds=replace(s.holds, early_end=w.seq), schedule=s.schedule.command_sent("set_current"))

    @staticmethod
    def _yield_why(s: Sortie) -> str | None:
        """Why the hold watched ends now for another member's (it claims the point too, holds
        it or flies to it, and keeps it: it claimed it first, ``claims.keeper``), or None."""
        w, k = s.holds.watch, s.claims.holding
        if w is None or w.phase != "holding" or s.holds.early_end == w.seq or k is None:
            return None
        other = s.fleet.yield_to.get(k)
        return None if other is None else f"{other} claims point {k} too and keeps it (it claimed it first)"

    def _abandon(self, s: Sortie, why: str, out: list[fx.Effect]) -> Sortie:
        """The hold watched, if any, ended from outside (``why``) and judged as it stands."""
        if s.holds.watch is None:
            return s
        return self._judge(replace(s, holds=s.holds.abandoned(why)), out)

    def _judge(self, s: Sortie, out: list[fx.Effect]) -> Sortie:
        """The vehicle left the point (or passed it): record what the hold carried, a fleet's
        member once the binding has settled (``_record_due``)."""
        w, b, held = s.holds.watch, s.holds.binding, s.onboard.held
        assert w is not None and held is not None
        point = held.point_at(w.seq)
        s = replace(s, holds=s.holds.closed(w.seq))
        if point is None:
            return s
        if not w.arrived:
            out.append(fx.Emit(ev.WaypointSkipped(f"point {point.hover_index}: {w.why_left}", user_id=point.user_id)))
            return s
        if b is None or b.request_id is None:
            return s
        judged = Judged(point, b, w.covered_s, w.held_s, w.why_left, w.last_in_s)
        if self.rules.settle_max_s > 0 and s.fleet.bound_settled != b.user_id and self._carried(judged) > 0:
            # (a hold that carried nothing is said at once: claiming its user on would bar
            # the others' holds of it, for nothing)
            return replace(s, holds=replace(s.holds, judged_unrecorded=judged))
        return self._record(s, judged, None, out)

    def _record_due(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        """Record the last hold's service once its binding has settled, or ``settle_max_s``
        after the judgement: of two members that bound one user within a hearing delay (each
        hold shorter than it: 20 UAVs over radios, two members at two points near a user with
        one task), the one that bound it first records it, the other nothing."""
        j = s.holds.judged_unrecorded
        if j is None:
            return s
        if j.since is None:
            return replace(s, holds=replace(s.holds, judged_unrecorded=replace(j, since=now)))
        settled = s.fleet.bound_settled == j.binding.user_id
        if not settled and now - j.since < self.rules.settle_max_s:
            return s
        if not settled:
            out.append(fx.Log("warning", f"point {j.point.hover_index}: the binding of {j.binding.user_id} has not "
                                         f"settled in {self.rules.settle_max_s:g} s: recorded as judged"))
        return self._record_now(s, v, out)

    def _record_now(self, s: Sortie, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        """The last hold's service recorded as it stands (a new hold binds, the sortie ends)."""
        j = s.holds.judged_unrecorded
        return s if j is None else self._record(replace(s, holds=replace(s.holds, judged_unrecorded=None)), j, v, out)

    def _record(self, s: Sortie, j: Judged, v: ins.VehicleSnapshot | None, out: list[fx.Effect]) -> Sortie:
        """Record what the hold ``j`` carried, unless another member serves its user; ``v``:
        the vehicle now, when the record waited (its event says how long after the hold)."""
        point, b = j.point, j.binding
        assert b.request_id is not None
        owner = s.fleet.owner(b.user_id)
        other = owner or b.lost_to
        how = "owns it now" if owner else "claimed it during the hold"
        elsewhere = (f"{other} serves {b.user_id} ({how})" if other is not None
                     else self.world.served_elsewhere(b.user_id))
        if elsewhere is not None:  # two members bound one user at once: the first keeps it
            out += [fx.Emit(ev.WaypointReached(f"point {point.hover_index}: nothing recorded: {elsewhere}",
                                               user_id=b.user_id, request_id=b.request_id)),
                    fx.Log("info", f"point {point.hover_index}: held {j.held_s:.1f} s for {b.user_id}, nothing "
                                   f"recorded: {elsewhere}")]
            return s
        tasks = self._carried(j)
        if tasks <= 0:
            out.append(fx.Emit(ev.WaypointReached(f"point {point.hover_index}: held {j.held_s:.1f} s of "
                                                   f"{b.needed_s:.1f} s needed ({j.why_left}): nothing served",
                               user_id=b.user_id, request_id=b.request_id)))
            return s
        bits = tasks * self.rules.scenario.bits_per_task
        reward = self._service_reward(point, tasks)
        out.append(fx.RecordService(b.request_id, b.user_id, point.hover_index, (point.x_m, point.y_m, point.z_m),
                                    tasks, bits, reward, j.held_s, b.planned, b.tasks))
        detail = f"{tasks} tasks at point {point.hover_index}" + ("" if tasks == b.tasks else f" of {b.tasks}")
        late_s = self._since_s(j.ended_s, v)
        detail += f"; held {j.held_s:.1f} s" + (f"; recorded {late_s:.1f} s after the hold" if late_s >= 0.05 else "")
        out.append(fx.Emit(ev.UserServed(detail, user_id=b.user_id,
                           request_id=b.request_id)))
        return replace(s, life=s.life.served())

    @staticmethod
    def _carried(j: Judged) -> int:
        """The tasks the hold ``j`` carried, whatever the user said: a user whose upload is
        done ended the hold early (``_maybe_end_hold``), but no more is recorded than the time
        held carries."""
        b = j.binding
        if j.covered_s >= b.needed_s - 0.5:
            return b.tasks
        return int(b.tasks * j.covered_s / b.needed_s) if b.needed_s > 0 else 0

    @staticmethod
    def _since_s(vehicle_s: float, v: ins.VehicleSnapshot | None) -> float:
        """Wall seconds from the vehicle's time ``vehicle_s`` to its latest report (0 unknown)."""
        if v is None or not v.time_rate or math.isnan(v.boot_s) or math.isnan(vehicle_s):
            return 0.0
        return max(v.boot_s - vehicle_s, 0.0) / v.time_rate

    def _service_reward(self, point: PlannedPoint, tasks: int) -> float:
        """q of ``tasks`` served at ``point``, as the journal records it: the plan's own
        when they are the tasks planned, else (11) with the point's planned energy."""
        return point.reward if tasks == point.tasks else interval_reward(self.p, tasks, point.energy_j)

    # --- deciding ------------------------------------------------------------------------------
    def _plan_wanted(self, s: Sortie, v: ins.VehicleSnapshot, now: float) -> fx.PlanBasis | None:
        r = self.rules
        if s.life.warming:
            return None  # a plan now would wait for the compiler (minutes on a cold cache)
        if not (v.connected and v.position_ok) or v.battery_fraction is None:
            return None
        if v.time_rate is None:
            return None  # how much flight a second of waiting costs is not known yet
        if s.life.flown and not v.landed_known:
            return None  # in the air or landed meanwhile? know first
        if not v.airborne:
            if s.life.started or s.life.flown or s.schedule.commanding == "start":
                return None  # starting or taking off (a new mission now would restart it), or landed
            if self._pending_count(s) < (1 if s.schedule.outbid else r.min_requests):
                return None  # (a member outbid at its first point has decided to fly already)
            if s.onboard.held is not None and (s.authority.granted or not s.schedule.dirty
                                       or now - s.schedule.last_plan_at < r.replan_min_interval_s):
                return None  # held and about to be started (a new one now would delay it), or nothing new
            return fx.PlanBasis("requests before takeoff", s.schedule.version, None, settles=True)
        if v.mode in RETURNING_MODES:
            return None  # returning: the safety, the pilot or the mission decided
        if s.onboard.must_upload:
            return fx.PlanBasis("the vehicle lost its mission", s.schedule.version, None)
        if s.onboard.held is None or v.mode not in MISSION_MODES:
            return None  # not flying a mission of ours: the operator has the vehicle
        w = s.holds.watch
        claims = self._claims(s, v)  # (as they stand now: an upload answered since the last were told)
        lost = lost_points(claims.points - {claims.holding}, s.fleet.blocked)
        holding = w is not None and w.phase == "holding"
        if w is not None and holding and w.approached and (s.schedule.decided_at != w.seq or lost):
            # (a hold found already under way, its start unseen, is left to the autopilot's
            # own timer: a replacement now would start it again; the next arrival decides)
            # Decided here already, the next point claimed first by another member (both
            # claimed it at once): decided again, the vehicle still holding.
            point = s.onboard.held.point_at(w.seq)
            assert point is not None
            b = s.holds.binding
            serving = b.user_id if b is not None and b.request_id is not None else None
            # the hold the bound request needs, so that the planner pays for all of it
            bound = replace(point, hold_s=self._bound_hold_s(s, w.seq, point.hold_s, self._margin_s(v)))
            reward = self._service_reward(point, b.tasks) if serving and b else 0.0
            why = (f"arrived at point {point.hover_index}" if s.schedule.decided_at != w.seq else
                   f"point {min(lost)} claimed by another member, holding point {point.hover_index}")
            return fx.PlanBasis(why, s.schedule.version, w.seq, at_point=bound, serving=serving, serving_reward=reward)
        if lost and not holding and v.seq > r.autopilot.first_item:
            # flying to a point another member claims now (both claimed it at once): given up
            return fx.PlanBasis(f"point {min(lost)} claimed by another member", s.schedule.version, v.seq - 1,
                                pauses=True)
        if (s.schedule.dirty and self._answers(s, v) and now - s.schedule.last_plan_at >= r.replan_min_interval_s
                and self._pending_count(s) > 0 and v.xyz[2] >= r.area.min_flight_altitude_m
                and now >= self._answer_at(s, v) and self._could_turn_back(s, v)):
            return fx.PlanBasis("new requests on the way home", s.schedule.version, s.onboard.held.rtl_seq - 1,
                                settles=True)
        return None

    def _answers(self, s: Sortie, v: ins.VehicleSnapshot) -> bool:
        """Whether new requests are decided on now, on the way home: the vehicle flies the
        return item of a mission of ours in a mission mode, the sortie on (on PX4 the return
        item is flown in AUTO.RTL, where a new mission would not be flown)."""
        held = s.onboard.held
        return (held is not None and s.life.over is None and v.airborne
                and v.mode in MISSION_MODES and v.seq == held.rtl_seq and self.rules.autopilot.return_item_mode is None)

    def _answer_at(self, s: Sortie, v: ins.VehicleSnapshot) -> float:
        """When this member, on its way home, may answer the requests that came in (``fleet.
        answer_rank``): a step after them for each member on its way home that answers first,
        up to ``max_answer_rank`` steps (it may be unable to: its battery, its plan)."""
        if not s.fleet.answering:
            return s.schedule.dirty_at
        users = [(r.x_m, r.y_m) for r in self._pending(s)]
        rank = answer_rank(self.rules.vehicle, (v.xyz[0], v.xyz[1]), s.fleet.answering, users,
                           self.rules.answer_tie_m)
        return s.schedule.dirty_at + min(rank, self.rules.max_answer_rank) * self.rules.answer_step_s

    def _could_turn_back(self, s: Sortie, v: ins.VehicleSnapshot) -> bool:
        """Whether a decision on the way home could find a point to fly to: the model's first
        step on the pending requests, with the battery the vehicle reports less the landing
        and the margin (the planner counts less still: what is spent while it searches), so
        a decision is skipped only where it would find nothing whatever it searched."""
        rows = self._pending(s)
        sc = self.rules.scenario
        battery = planning_battery_j(sc, (v.battery_fraction or 0.0) * sc.battery_j, 0.0, self.rules.energy_margin_j)
        counts = self.world.service_counts()
        served = [counts.get(row.user_id, 0) for row in rows]
        return first_steps(sc, self.points, rows, served, v.xyz, s.schedule.last_hover_index, battery) > 0

    def _planned(self, s: Sortie, planned: ins.Planned, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        basis, path = planned.basis, planned.path
        if (basis.version != s.schedule.version or s.life.over is not None or s.onboard.doubt is not None
                or s.life.degraded is not None
                or v.time_rate is None):
            # stale: the state it was made on is gone (or its clock)
            return replace(s, schedule=replace(s.schedule, dirty=True))
        if basis.at_point is not None:
            s = replace(s, schedule=replace(s.schedule, decided_at=basis.keep_through))
        held = s.onboard.held
        airborne = v.airborne
        if not path.points and not airborne and not s.onboard.must_upload:
            return s  # nothing to fly yet
        pause = self._pause(s, basis, path, v, now)
        flown = self._with_margins(path, self._margin_s(v))
        if pause is not None:
            paused = self._with_margins(path, self._margin_s(v), pause.hold_s)
            if len(paused.points) == len(flown.points):
                flown = paused
            else:
                pause = None  # the battery has no room for it: a point is worth more; flown at once
        path = flown
        try:
            check_path(path, self.rules.area, self.rules.scenario, path.battery_after_j + path.predicted_energy_j)
            hover = [HoverPoint(p.x_m, p.y_m, p.z_m, p.hold_s) for p in path.points]
            plan_id = s.schedule.plan_id + 1
            if basis.keep_through is None or held is None:
                pause = None  # (a fresh mission: nothing flown to replace)
                items = encode_path(hover, self.rules.origin, self.rules.flavour)  # type: ignore[arg-type]
                mission = HeldMission.fresh(plan_id, items, path.points, self.rules.flavour)
                # The autopilot keeps its index across an upload, also from the last sortie's
                # mission: in the air fly the first point, on the ground start at the takeoff.
                takeoff = self.rules.autopilot.first_item
                if not mission.points:
                    current = None
                elif airborne:
                    current = mission.points[0][0]
                else:
                    current = takeoff if v.seq > takeoff else None  # (already there: nothing to wait for)
            else:
                items, _ = replacement_items(held.items, basis.keep_through, ([pause] if pause else []) + hover,
                                             self.rules.origin, self.rules.flavour)  # type: ignore[arg-type]
                if basis.at_point is not None:  # holding there: that item stays the one flown
                    items = marked_current(items, basis.keep_through)
                    hold = self._affordable_hold_s(basis.at_point, path)
                    held, items = self._hold_at(held, items, basis.keep_through, hold)
                mission = HeldMission.replacement(plan_id, items, held, basis.keep_through, path.points,
                                                  pause=pause is not None)
                # Replacing the item flown (the return to launch, on the way home): start it
                # again, or ArduPilot flies on home; a hold at the item kept goes on.
                current = None if basis.at_point is not None else basis.keep_through + 1
                if held is not None and len(items) == len(held.items) and same_mission(items, held.items,
                                                                                      self.rules.flavour):  # type: ignore[arg-type]
                    return s  # the vehicle flies this already
            validate_mission(items, self.rules.origin, self.rules.area, self.rules.flavour,  # type: ignore[arg-type]
                             max_items=self.rules.max_mission_items)
        except (PlanningError, MissionError) as err:
            return self._failed(replace(s, schedule=replace(s.schedule, plan_id=s.schedule.plan_id + 1)),
                                f"plan {s.schedule.plan_id + 1} not flown: {err}", now, out)
        upload = fx.Upload(plan_id, tuple(items), mission, path, current, basis.keep_through,
                           restart_current=current is not None and basis.keep_through is not None,
                           planner_ms=planned.planner_ms, newest_request=planned.newest_request)
        first = first_point(upload)
        if basis.settles and first is not None and not self._settled(s, first.hover_index, now, now):
            # away from a hold nothing keeps the vehicle off the point: the upload waits (not
            # for a vehicle flying to a point lost: flying on to it is what must end; it pauses)
            out.append(fx.Log("info", f"plan {plan_id}: flown once the claim of point {first.hover_index} has "
                                      f"settled"))
            return replace(s, schedule=replace(s.schedule.settle(upload), claimed_at=now))
        if pause is not None and first is not None:
            out.append(fx.Log("info", f"plan {plan_id}: the vehicle holds where it is until the claim of point "
                                      f"{first.hover_index} has settled"))
        out.append(upload)
        return replace(s, schedule=s.schedule.uploading(plan_id))

    # --- settling: a point flown to once every claim made before its own is known ----------------
    def _settled(self, s: Sortie, point: int, since: float, now: float) -> bool:
        """Whether this member may fly to ``point``, claimed at ``since``: its claim has settled
        (``FleetView.settled``), it has waited ``settle_max_s`` for it, or it is no fleet's."""
        r = self.rules
        return r.settle_max_s <= 0 or point in s.fleet.settled or now - since >= r.settle_max_s

    def _settle(self, s: Sortie, now: float, out: list[fx.Effect]) -> Sortie:
        """The plan waiting for its first point's claim to settle: uploaded once it has, given
        up when another member claimed the point first (plan again), or when the state it was
        made on is gone."""
        up = s.schedule.settling
        assert up is not None
        point = first_point(up)
        assert point is not None
        k = point.hover_index
        if s.life.over is not None or s.life.degraded is not None or s.life.return_seen_at is not None:
            return replace(s, schedule=s.schedule.unsettled())
        if k in s.fleet.blocked:  # another member claimed it first: it keeps it
            out.append(fx.Log("info", f"plan {up.plan_id} not flown: point {k} was claimed first by another member"))
            return replace(s, schedule=s.schedule.unsettled(outbid=not s.life.started))
        if not self._settled(s, k, s.schedule.claimed_at, now):
            return s
        if k not in s.fleet.settled:
            out.append(fx.Unsettled(up.plan_id, k, self.rules.settle_max_s))
        out.append(up)
        return replace(s, schedule=s.schedule.uploading(up.plan_id))

    def _pause(self, s: Sortie, basis: fx.PlanBasis, path: PlannedPath, v: ins.VehicleSnapshot,
               now: float) -> HoverPoint | None:
        """The pause a replacement of a point lost begins with (``PlanBasis.pauses``): where the
        vehicle is, at the first point's height, held as long as its claim may take to settle
        (``settle_max_s``, in vehicle time: the service ends it earlier). None when the claim
        has settled already, or when the vehicle is over a hovering point (its holder would
        hover beside it: it flies on at once)."""
        r = self.rules
        if not basis.pauses or not path.points or self._settled(s, path.points[0].hover_index, now, now):
            return None
        x, y = v.xyz[0], v.xyz[1]
        if len(self.points) and float(np.hypot(self.points[:, 0] - x, self.points[:, 1] - y).min()) <= 2 * r.hold_radius_m:
            return None
        assert v.time_rate is not None
        return HoverPoint(x, y, path.points[0].z_m, r.settle_max_s * v.time_rate + self._margin_s(v))

    def _maybe_end_pause(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        """End the pause the vehicle flies (``HeldMission.is_pause``) once the next point's
        claim has settled, or ``settle_max_s`` after it was claimed; a claim lost meanwhile is
        decided again (``_plan_wanted``) and its replacement pauses anew. Only under authority,
        not degraded: without, it commands nothing and the pause's own timer ends it."""
        held, k = s.onboard.held, s.claims.flying_to
        if (held is None or not s.onboard.known or not v.connected or v.mode not in MISSION_MODES
                or not held.is_pause(v.seq) or k is None or k in s.fleet.blocked):
            return s
        if not s.authority.granted or s.life.degraded is not None or s.schedule.busy != "" or s.schedule.commanding:
            return s
        if s.schedule.pause_ended == (held.plan_id, v.seq) or not self._settled(s, k, s.schedule.claimed_at, now):
            return s
        if k not in s.fleet.settled:
            out.append(fx.Unsettled(held.plan_id, k, self.rules.settle_max_s))
        out.append(fx.Command("set_current", v.seq + 1, f"pause ended: the claim of point {k} has settled"
                              if k in s.fleet.settled else f"pause ended: point {k} flown unsettled"))
        return replace(s, schedule=replace(s.schedule.command_sent("set_current"), pause_ended=(held.plan_id, v.seq)))

    def _with_margins(self, path: PlannedPath, margin_s: float, pause_s: float = 0.0) -> PlannedPath:
        """The path as it will be flown: each hold ``margin_s`` longer than its upload needs
        (the service ends a hold once its position reports show it, a command's latency
        later, in vehicle time; the item's own hold is the ceiling the autopilot keeps to
        when the service cannot end it), after a pause of ``pause_s`` (``_pause``), and cut
        where that hovering breaks the energy reserve the planner kept."""
        sc = self.rules.scenario
        points = [replace(p, hold_s=p.hold_s + margin_s) for p in path.points]
        extra = margin_s * sc.hover_power_w
        battery = path.battery_after_j - pause_s * sc.hover_power_w
        while points and battery - extra * len(points) < sc.energy_floor_j:
            dropped = points.pop()
            home = np.array([points[-1].x_m, points[-1].y_m, points[-1].z_m]) if points else None
            gone = np.array([dropped.x_m, dropped.y_m, dropped.z_m])
            battery += dropped.energy_j + return_energy_j(self.p, gone)
            battery -= return_energy_j(self.p, home) if home is not None else 0.0
        spent = path.predicted_energy_j - (battery - path.battery_after_j) + extra * len(points)
        reason = path.stop_reason if len(points) == len(path.points) else "the energy reserve (with the holds' margins)"
        return replace(path, points=tuple(points), battery_after_j=battery - extra * len(points),
                       predicted_energy_j=spent, stop_reason=reason)

    def _margin_s(self, v: ins.VehicleSnapshot) -> float:
        """How much longer than its upload needs a hold is flown: the configured margin and a
        command's latency in vehicle time (the service ends a hold a command after it sees it;
        planning waits for the clock's rate, ``_plan_wanted``)."""
        assert v.time_rate is not None, "planned before the vehicle's clock rate was measured"
        return self.rules.hold_margin_s + CONTROL_LATENCY_S * v.time_rate

    def _bound_hold_s(self, s: Sortie, seq: int, planned_s: float, margin_s: float) -> float:
        """The hold at ``seq`` as long as the request bound there needs (it was sized on the
        request the plan saw; the user's backlog may have grown since, or the model's rule
        serves another user there now), never shorter than planned."""
        b = s.holds.binding
        if b is None or b.seq != seq or b.request_id is None:
            return planned_s
        return max(planned_s, min(b.needed_s + margin_s, MAX_HOLD_S))

    def _affordable_hold_s(self, at_point: PlannedPoint, path: PlannedPath) -> float:
        """The hold at ``at_point`` cut by what the path from it leaves below the energy
        reserve (``check_path``'s rule): the planner paid for the whole hold before the path,
        so a path that ends below the reserve (an empty one: the way home alone) means the
        hold itself is too long for the battery."""
        sc = self.rules.scenario
        left_j = path.battery_after_j
        if not sc.reserve_return_energy:  # the way home may dip below the floor
            last = path.points[-1] if path.points else at_point
            left_j += return_energy_j(self.p, np.array([last.x_m, last.y_m, last.z_m]))
        short_j = sc.energy_floor_j - left_j
        return max(at_point.hold_s - max(short_j, 0.0) / sc.hover_power_w, 0.0)

    def _hold_at(self, held: HeldMission, items: list[MissionItem], seq: int,
                 hold_s: float) -> tuple[HeldMission, list[MissionItem]]:
        """The held mission with the hold at ``seq`` set to ``hold_s``. The replacement
        restarts that hold anyway (ArduPilot's change detector, PX4's current mark), and the
        service ends it once the request is served: the item's hold is the ceiling, and the
        energy the planner paid for."""
        point = held.point_at(seq)
        if point is None or point.hold_s == hold_s:
            return held, items
        point = replace(point, hold_s=hold_s)
        held = replace(held, points=tuple((q, point if q == seq else p) for q, p in held.points))
        items = [replace(i, param1=encoded_hold_s(hold_s, self.rules.flavour)) if i.seq == seq else i for i in items]  # type: ignore[arg-type]
        return held, items

    def _uploaded(self, s: Sortie, uploaded: ins.Uploaded, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        up, keep = uploaded.upload, uploaded.upload.keep_through
        watch = s.holds.watch
        if watch is not None and (keep is None or watch.seq > keep) and not self._flies_on(s, up, watch.seq):
            # the point watched was replaced: what it held so far is judged now
            s = self._abandon(s, f"replaced by plan {up.plan_id}", out)
        s = replace(s, onboard=s.onboard.accepted(up.mission), schedule=s.schedule.uploaded(up.plan_id),
                    holds=s.holds.kept_through(keep))
        out += [fx.RecordMission(up.plan_id, up.mission, "accepted"),
                fx.PublishPlan(up.mission, up.path.predicted_energy_j),
                fx.Emit(ev.MissionUploaded(f"plan {up.plan_id}: {len(up.path.points)} points"
                                            + (f" after item {keep}" if keep is not None else "")
                                            + f"; planner_ms={up.planner_ms:.1f} upload_ms={uploaded.upload_ms:.1f} "
                                              f"newest_request={up.newest_request}; ends: {up.path.stop_reason}"))]
        if not up.path.points:
            out.append(fx.Emit(ev.Returning(f"nothing more to serve ({up.path.stop_reason}): return to launch")))
        return self._replay(s, v, out)

    def _flies_on(self, s: Sortie, up: fx.Upload, seq: int) -> bool:
        """Whether the new mission flies the point watched at ``seq`` as the old one did: a
        decision that went up while the vehicle reached its next point, which the decision
        also chose. The autopilot restarts the item, at the same place: the hold goes on,
        bound as it was (judging it and watching it afresh would bind a second user at the
        point in the same stay)."""
        if up.keep_through is None or s.onboard.held is None:
            return False  # a mission begun afresh: its items are not the old ones'
        return s.onboard.held.point_at(seq) is not None and _same_point(s.onboard.held, up.mission, seq)

    def _upload_failed(self, s: Sortie, up: fx.Upload, error: str, unknown: bool, v: ins.VehicleSnapshot, now: float,
                       out: list[fx.Effect]) -> Sortie:
        out.append(fx.RecordMission(up.plan_id, up.mission, f"{'unknown' if unknown else 'failed'}: {error}"))
        if unknown:  # the vehicle may hold it: find out before anything else
            s = self._doubt(replace(s, onboard=s.onboard.maybe(up.mission)),
                            f"the outcome of plan {up.plan_id}'s upload is unknown", out)
        elif self.rules.autopilot.writes_items_as_they_arrive and s.onboard.held is not None:
            # ArduPilot writes an upload's items as they arrive: a failed one may leave part of
            # it in the mission held, or all of it if only its ACK was lost (PX4 switches over
            # only when the upload is complete). The read-back tells which.
            s = self._doubt(replace(s, onboard=s.onboard.maybe(up.mission)),
                            f"plan {up.plan_id}'s upload failed part-way", out)
        if s.onboard.doubt is None:  # not taken: the reports kept during it were of the mission held
            s = self._replay(s, v, out)
        return self._failed(s, f"plan {up.plan_id} not flown: {error}", now, out)

    def _failed(self, s: Sortie, why: str, now: float, out: list[fx.Effect]) -> Sortie:
        """A plan or upload failed: try again after a growing wait, give up after a bound."""
        schedule, said = s.schedule.failed(why, now, self.rules.backoff)
        out += said
        return replace(s, schedule=schedule)

    # --- doubt ---------------------------------------------------------------------------------
    def _doubt(self, s: Sortie, why: str, out: list[fx.Effect], *, hold_interrupted: bool = False) -> Sortie:
        """The vehicle may hold another mission: no reports count until it is read back. A
        hold being watched goes on being watched once the read-back shows our mission (a
        radio gap interrupts nothing), unless the vehicle restarted: then it was cut."""
        onboard, said = s.onboard.doubting(why)
        out += said
        s = replace(s, onboard=onboard, schedule=s.schedule.in_doubt())
        return self._abandon(s, why, out) if hold_interrupted else s

    def _read_back(self, s: Sortie, items: tuple, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        candidate = s.onboard.matching(items, self.rules.flavour)  # type: ignore[arg-type]
        if candidate is not None:
            restarted, before = s.onboard.restarted, s.onboard.held
            onboard, said = s.onboard.confirmed(candidate, v.airborne)
            out += said
            # The upload that went through kept the points before its first new one: a hold
            # there already judged is not judged again (recorded twice, found on a lossy link)
            judged = frozenset(q for q in s.holds.judged if _same_point(before, candidate, q))
            s = replace(s, onboard=onboard, evidence=s.evidence.explained(),
                        holds=replace(s.holds, judged=judged) if candidate is not before else s.holds)
            # a restarted vehicle's reports were dropped (its holds were cut); else judged now
            return s if restarted else self._replay(s, v, out)
        before = s.onboard.last_sorties(items, self.rules.flavour)  # type: ignore[arg-type]
        if before is not None:
            out += before[1]
            return replace(s, onboard=before[0])
        s = self._abandon(replace(s, onboard=replace(s.onboard, doubted=())),
                          "the vehicle no longer holds our mission", out)
        foreign = s.onboard.foreign(len(items), self.rules.autopilot.home_slots)
        onboard, said = s.onboard.lost(len(items), v.airborne, foreign)
        out += said
        s = replace(s, onboard=onboard, holds=replace(s.holds, judged=frozenset()), evidence=s.evidence.lost(),
                    schedule=replace(s.schedule, decided_at=None))
        if foreign:  # another station's: not ours to fly, nor to replace
            return self._revoke(s, f"the vehicle holds a mission that is not ours ({len(items)} items, another "
                                   f"station's)", out)
        return s

    # --- link events -------------------------------------------------------------------------------
    def _connected(self, s: Sortie, v: ins.VehicleSnapshot, mode: str, out: list[fx.Effect]) -> Sortie:
        out.append(fx.Log("info", f"autopilot connected ({mode})"))
        if v.airborne:
            s = replace(s, life=replace(s.life, started=True))
        if s.onboard.held is not None:  # from the journal: does the vehicle still fly it?
            s = self._doubt(s, f"the service started with plan {s.onboard.held.plan_id} in its journal", out)
        return s

    def _mode(self, s: Sortie, v: ins.VehicleSnapshot, mode: str, commanded: bool, now: float,
              out: list[fx.Effect]) -> Sortie:
        s = self._return_check(s, v, now, out)  # a change after the one awaiting its item is judged too
        held = s.onboard.held
        if self._return_item_due(s, v, mode, commanded):
            return replace(s, life=replace(s.life, return_seen_at=now))
        mission_return = (held is not None and v.seq == held.rtl_seq and mode in RETURNING_MODES)
        a = self.rules.autopilot
        # PX4 goes back to an earlier mode once the landing of the service's return disarms it
        # (its landed state may come later: a disarming in the air is _disarm_check's)
        after_return = (s.life.homing and not v.armed and mode in a.modes_after_landing
                        and s.authority.expected_mode in RETURNING_MODES)
        authority = s.authority.on_mode(mode, armed=v.armed or v.airborne, mission_return=mission_return,
                                        commanded=commanded, autopilots_own=after_return)
        if authority.state == "revoked" and s.authority.granted:
            out += self._revoked_effects(authority)
        if mode in RETURNING_MODES:
            out.append(fx.Emit(ev.Returning(f"mode {mode}")))
        return replace(s, authority=authority)

    def _return_item_due(self, s: Sortie, v: ins.VehicleSnapshot, mode: str, commanded: bool) -> bool:
        """A switch not commanded to the autopilot's mode for a mission's return item, while the
        vehicle flies the service's mission in the mode expected, at the item before its return:
        the autopilot's own if MISSION_CURRENT shows the return item within ``RETURN_ITEM_S``."""
        held, a = s.onboard.held, self.rules.autopilot
        return (not commanded and s.authority.granted and held is not None and a.return_item_mode == mode
                and v.armed and s.authority.expected_mode in MISSION_MODES and v.seq == held.rtl_seq - 1)

    def _return_check(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        """Judge a switch awaiting its return item (``_return_item_due``): the mission's own
        return once MISSION_CURRENT shows the item in that mode; nobody's if the mode changes
        again, or the item is not shown within ``RETURN_ITEM_S``."""
        since = s.life.return_seen_at
        if since is None:
            return s
        held, mode = s.onboard.held, self.rules.autopilot.return_item_mode
        if held is not None and v.mode == mode and v.seq == held.rtl_seq:
            authority = s.authority.on_mode(v.mode, armed=True, mission_return=True)
            out.append(fx.Emit(ev.Returning(f"mode {v.mode}")))
            return replace(s, authority=authority, life=replace(s.life, return_seen_at=None))
        if v.mode == mode and now - since < RETURN_ITEM_S:
            return s
        s = replace(s, life=replace(s.life, return_seen_at=None))
        return self._revoke(s, f"mode changed to {mode} (not commanded by the service) and the vehicle did not "
                               f"show its mission's return item (item {held.rtl_seq if held else '?'}, it shows "
                               f"{v.seq}, in {v.mode or 'mode unknown'}) within {RETURN_ITEM_S:g} s", out)

    def _on_return(self, s: Sortie, v: ins.VehicleSnapshot) -> bool:
        """The vehicle flies the service's own way home: its mission's return item, or the
        return mode the service expects."""
        held = s.onboard.held
        return ((held is not None and v.seq == held.rtl_seq)
                or (v.mode in RETURNING_MODES and v.mode == s.authority.expected_mode))

    def _homing(self, s: Sortie, v: ins.VehicleSnapshot) -> Sortie:
        """Remember that the vehicle was seen on the service's own way home, until it is seen
        flying to a point again: ArduCopter's disarming on touching down resets its mission
        index to 0, and that MISSION_CURRENT may come before the heartbeat showing the
        disarming (seen on SITL with the MAVSDK backend)."""
        if not v.airborne or s.onboard.held is None:
            return s
        if not s.life.homing and self._on_return(s, v):
            return replace(s, life=replace(s.life, homing=True))
        if s.life.homing and s.onboard.held.point_at(v.seq) is not None and v.mode in MISSION_MODES:
            return replace(s, life=replace(s.life, homing=False))
        return s

    def _arming(self, s: Sortie, v: ins.VehicleSnapshot, armed: bool, commanded: bool, now: float,
                out: list[fx.Effect]) -> Sortie:
        returning = s.life.flown and (s.life.homing or self._on_return(s, v))
        if not armed and not commanded and returning and v.airborne and s.authority.granted:
            # On the service's own return: the landing's disarming if the landing is
            # reported too (its report may come after the disarming's): judged then.
            return replace(s, life=replace(s.life, disarmed_at=now))
        authority = s.authority.on_arming(armed, commanded=commanded, landing=returning)
        if authority is not s.authority:
            out += self._revoked_effects(authority)
        return replace(s, authority=authority, life=replace(s.life, disarmed_at=None))

    def _disarm_check(self, s: Sortie, v: ins.VehicleSnapshot, now: float, out: list[fx.Effect]) -> Sortie:
        """A disarming on the service's own return is its landing's once the vehicle is
        reported on the ground within ``DISARM_LANDING_S``; otherwise nobody's."""
        if s.life.disarmed_at is None:
            return s
        if v.armed or (v.landed_known and not v.airborne):
            return replace(s, life=replace(s.life, disarmed_at=None))
        if now - s.life.disarmed_at < DISARM_LANDING_S:
            return s
        s = replace(s, life=replace(s.life, disarmed_at=None))
        return self._revoke(s, f"the vehicle was disarmed (not commanded by the service) and not reported "
                               f"landed within {DISARM_LANDING_S:g} s", out)

    def _revoke(self, s: Sortie, why: str, out: list[fx.Effect]) -> Sortie:
        """End the authority, if the service has it: only the operator gives it back."""
        if not s.authority.granted:
            return s
        authority = s.authority.revoke(why)
        out += self._revoked_effects(authority)
        return replace(s, authority=authority)

    @staticmethod
    def _revoked_effects(authority: Authority) -> list[fx.Effect]:
        return [fx.Emit(ev.AuthorityRevoked(authority.detail[:256])),
                fx.Log("warning", f"authority ended: {authority.detail}; no more commands until the operator "
                                  f"grants it again")]

    # --- commands ------------------------------------------------------------------------------
    def _command_due(self, s: Sortie, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        """Start or resume the mission when the service may and should (not while the
        planner warms up: the decisions in flight would wait for the compiler)."""
        if not s.authority.granted or s.onboard.held is None or not v.connected or s.life.warming:
            return s
        if (not v.airborne and not s.life.started and s.onboard.held.points and s.schedule.busy == "" and v.position_ok
                and v.battery_fraction is not None and v.battery_source == "autopilot"):
            return self._command(s, fx.Command("start", why=f"plan {s.onboard.held.plan_id}"), out)
        if s.onboard.resume_pending and s.onboard.known and s.schedule.busy == "" and v.airborne:
            if v.mode in MISSION_MODES:  # PX4 flies a new mission's marked item in mission mode by itself
                out.append(fx.Emit(ev.MissionResumed(f"plan {s.onboard.held.plan_id}: the vehicle flies it in "
                                                     f"{v.mode}")))
                return replace(s, onboard=replace(s.onboard, resume_pending=False))
            if v.mode not in HOLDING_MODES:
                # going home, or in the operator's hands
                return replace(s, onboard=replace(s.onboard, resume_pending=False))
            first = s.onboard.held.points[0][0] if s.onboard.held.points else s.onboard.held.rtl_seq
            return self._command(s, fx.Command("resume", first, f"plan {s.onboard.held.plan_id} (was {v.mode})"), out)
        return s

    def _resume_needed(self, s: Sortie, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        """A mission re-planned after the vehicle lost ours in the air (a restart, a link
        gap), on board, the vehicle holding, and no authority to resume it: the operator is
        told once (``resume_needed``); ``operator start`` plans from where the vehicle is then
        and resumes."""
        held = s.onboard.held
        if (not s.onboard.resume_pending or s.authority.granted or held is None or not s.onboard.known
                or s.schedule.busy != ""
                or not v.airborne or v.mode not in HOLDING_MODES):
            return s
        if held.plan_id == s.onboard.resume_told:  # told already: nothing new to resume
            return replace(s, onboard=replace(s.onboard, resume_pending=False))
        out += [fx.Emit(ev.ResumeNeeded(f"plan {held.plan_id} is on board and the vehicle holds in {v.mode}: the "
                                        f"service has no authority ({s.authority.state}); operator start resumes it")),
                fx.Log("warning", f"plan {held.plan_id} is on board, the vehicle holds in {v.mode}: the operator "
                                  f"must resume it (operator start)")]
        return replace(s, onboard=replace(s.onboard, resume_pending=False, resume_told=held.plan_id))

    def _command(self, s: Sortie, cmd: fx.Command, out: list[fx.Effect]) -> Sortie:
        mode = self.rules.mode_names.get(cmd.kind)
        authority = s.authority.commanding(mode) if mode else s.authority
        out.append(cmd)
        return replace(s, authority=authority, schedule=s.schedule.command_sent(cmd.kind))

    def _command_done(self, s: Sortie, cmd: fx.Command, now: float, out: list[fx.Effect]) -> Sortie:
        match cmd.kind:
            case "start":
                out.append(fx.Log("info", "mission started"))
                return replace(s, life=s.life.started_now(now), schedule=replace(s.schedule, failures=0))
            case "resume":
                out.append(fx.Emit(ev.MissionResumed(f"{cmd.why}; from item {cmd.seq}")))
                return replace(s, onboard=replace(s.onboard, resume_pending=False))
            case "return":
                return s
            case "hold":
                return s
            case "set_current":
                out.append(fx.Log("info", cmd.why))
                return s
            case _:
                assert_never(cmd.kind)

    def _command_failed(self, s: Sortie, cmd: fx.Command, error: str, now: float, out: list[fx.Effect]) -> Sortie:
        out += [fx.Emit(ev.CommandFailed(f"{cmd.kind}: {error}"[:256])),
                fx.Log("warning", f"the autopilot refused {cmd.kind} ({error}); trying again later")]
        if cmd.kind == "set_current":  # the hold (or pause) goes on: ended again when next judged due
            return replace(s, holds=replace(s.holds, early_end=None), schedule=replace(s.schedule, pause_ended=None))
        return replace(s, schedule=s.schedule.command_failed(now, self.rules.backoff))

    def _safety(self, s: Sortie, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        """Return to launch when the battery reaches the threshold (the planner should never
        let it: this is the guard if the model and the aircraft disagree)."""
        f = v.battery_fraction
        if (f is None or not v.connected or not v.airborne or v.mode in RETURNING_MODES or s.schedule.commanding
                or not s.authority.granted or f > self.rules.rtl_battery_fraction):
            return s
        out.append(fx.Emit(ev.Returning(f"battery at {f:.0%} ({v.battery_source}): return to launch commanded")))
        return self._command(s, fx.Command("return", why=f"battery at {f:.0%}"), out)

    # --- requests and the operator --------------------------------------------------------------
    def _request(self, s: Sortie, user: str, tasks: int, now: float, out: list[fx.Effect]) -> Sortie:
        return replace(s, holds=s.holds.user_said_done(user, tasks),
                       schedule=s.schedule.request_in(self.rules.backoff, now))

    def operator(self, s: Sortie, cmd: ins.OperatorAsked, v: ins.VehicleSnapshot,
                 now: float) -> tuple[Sortie, list[fx.Effect], bool, str]:
        """An operator command: the new state, its effects, whether it was accepted, and what
        the service did (the reply). ``hold`` is always accepted: taking authority away from
        the service must never fail."""
        out: list[fx.Effect] = []
        because = f" ({cmd.reason})" if cmd.reason else ""
        if cmd.command == "status":
            return s, out, True, self.describe(s, v)
        if cmd.command == "hold":
            if not s.authority.granted:
                return s, out, True, (f"the service has no authority ({s.authority.state}: {s.authority.detail}); "
                                      f"nothing changed")
            did = ""
            if v.airborne and v.mode not in RETURNING_MODES and s.schedule.commanding == "":
                s = self._command(s, fx.Command("hold", why=f"the operator's hold{because}"), out)
                did = f"; {self.rules.mode_names['hold']} commanded"
            authority = s.authority.release(f"handed back by the operator's hold{because}")
            out.append(fx.Emit(ev.AuthorityReleased(authority.detail[:256])))
            return replace(s, authority=authority, onboard=replace(s.onboard, resume_pending=False)), out, True, (
                f"authority withdrawn: the service commands no mode and no arming{did}; the vehicle keeps the "
                f"mission it holds{because}")
        refusal = s.life.start_refusal(v)
        if refusal is not None:
            return s, out, False, refusal
        if s.authority.granted:
            return s, out, True, f"the service already has the authority: {s.authority.detail}"
        authority = Authority.by_operator(cmd.reason)
        said = ("authority given: the service may arm, switch to the mission mode and start or resume the "
                f"mission{because}")
        if s.life.over is not None:
            if not s.life.beginning:
                out.append(fx.BeginSortie(v.battery_fraction or 0.0))
            return replace(s, life=replace(s.life, next_authority=authority, beginning=True)), out, True, \
                f"{said}; sortie {s.life.number + 1} begins"
        if v.airborne and v.mode in MISSION_MODES:  # handed over flying a mission: that mode is expected
            authority = authority.commanding(v.mode)
        s = replace(s, authority=authority, schedule=s.schedule.granted())
        out.append(fx.Emit(ev.AuthorityGranted(authority.detail[:256])))
        if v.airborne and v.mode in HOLDING_MODES:
            s = replace(s, onboard=replace(s.onboard, must_upload=True, resume_pending=True))
            said += "; re-planning from where the vehicle is, then resuming"
        s = self._next(s, v, now, out)
        return s, out, True, said

    def describe(self, s: Sortie, v: ins.VehicleSnapshot) -> str:
        held = f"plan {s.onboard.held.plan_id}" if s.onboard.held is not None else "no mission"
        state = f"over ({s.life.over})" if s.life.over else "running"
        return (f"authority {s.authority.state}: {s.authority.detail}; sortie {s.life.number} {state}; {held}; "
                f"{s.life.services} services; vehicle {v.mode or '?'} {'armed' if v.armed else 'disarmed'}"
                f"{', airborne' if v.airborne else ''}" + (f"; degraded: {s.life.degraded}" if s.life.degraded else ""))

    # --- sortie end and begin -------------------------------------------------------------------
    def _end(self, s: Sortie, why: str, v: ins.VehicleSnapshot, out: list[fx.Effect]) -> Sortie:
        if s.life.over is not None:
            return s
        s = self._record_now(self._abandon(s, why, out), v, out)
        life, said = s.life.ended(why)
        out += said
        return replace(s, life=life, schedule=s.schedule.ended())

    def _begun(self, s: Sortie, number: int, out: list[fx.Effect]) -> Sortie:
        authority = s.life.next_authority or next_sortie(s.authority)
        out.append(fx.Emit(ev.SortieStarted(f"sortie {number}: authority {authority.state} ({authority.detail})")))
        return Sortie(life=s.life.next_sortie(number), authority=authority, schedule=s.schedule.next_sortie(),
                      onboard=s.onboard.next_sortie())


def marked_current(items: list[MissionItem], seq: int) -> list[MissionItem]:
    """``items`` with item ``seq`` the only one marked current (PX4 flies the marked item at
    once after an upload; ArduPilot keeps its own index)."""
    return [replace(i, current=1 if i.seq == seq else 0) for i in items]


def new_sortie(number: int, rules: Rules, plan_id: int = 0) -> Sortie:
    """The state of the sortie the service starts in: the configuration's authority
    (``start_mission``) is for it only, and it ends if the vehicle is found in the air or
    armed (``Life.just_started``)."""
    authority = Authority.by_configuration() if rules.start_mission else Authority()
    return Sortie(life=Life(number=number), authority=authority, schedule=Schedule(plan_id=plan_id))


def _same_point(a: HeldMission | None, b: HeldMission | None, seq: int) -> bool:
    """Item ``seq`` flies to the same planned point (or is the same non-point item) in both."""
    if a is None or b is None:
        return False
    pa, pb = a.point_at(seq), b.point_at(seq)
    if pa is None or pb is None:
        return pa is pb and seq < min(len(a.items), len(b.items)) and a.items[seq] == b.items[seq]
    return (pa.hover_index, pa.x_m, pa.y_m, pa.z_m) == (pb.hover_index, pb.x_m, pb.y_m, pb.z_m)
