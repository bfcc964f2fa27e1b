"""The long-running service: the loops and the effects around the pure sortie logic.

Everything that decides is pure and elsewhere: the sortie logic (``sortie/machine.py``:
one frozen state, ``step(state, input) -> (state, effects)``), the intake, the planner, the
link's protocol state machines. This module only feeds the sortie logic what happens (the
vehicle's telemetry and reports, the planner's results, requests, operator commands) and
carries out the effects it returns: journal writes, uploads, commands, publications. The
planner runs in a worker thread (numba, nogil) so that acks, heartbeats and status go on
while it searches.

The service is given its parts (``Parts``: journal, link factory, zenoh I/O, clocks);
``run_service`` builds them from the configuration.

Shutdown: SIGINT/SIGTERM -> ``stopping`` -> intake closed (queryable undeclared, late
requests refused, no new operation started) -> bounded wait for an upload or a read-back in
progress (``GRACE_S``; its outcome is journalled, as the mission the vehicle then holds must be; an
abandoned upload is cancelled with MISSION_ACK CANCELLED and the autopilot keeps the
complete mission it held) -> tasks cancelled -> link, zenoh and journal closed (WAL
checkpointed) -> "stopped" logged, and the ``serve`` process ends at once
(``commands/serve.py``, ``end_now``: not waiting for the planner's thread to finish a
warm-up or a search, nor for Python to collect the heap).
"""

from __future__ import annotations

import asyncio
import logging
import math
import signal
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any, Awaitable, Callable, assert_never

import msgspec
import numpy as np

from protocol import ErrorReply, FleetKeys, OperatorReply, PendingRequest, Plan, PlanPoint, SigningError, State, Status, encode
from protocol.fleet_signing import FleetSigner, FleetVerifier, load_private_key, read_roster
from protocol.messages import FleetMember
from protocol.operator_proof import ProofCheck, load_or_create_key
from protocol.text import printable

from ..mcts import MctsConfig
from ..model import hover_points
from .allocator import ARENAS, cap_arenas
from .config import ServiceConfig
from .errors import ConfigError, JournalError, LinkError, PlanningError
from .event_loop import run_to_end
from .fleet.airspace import layer_gap_m
from .fleet.presence import FleetPresence
from .fleet.settle import ClaimSettling
from . import events as ev
from .intake import Accepted, Intake, fairness_rule
from .journal import Journal
from .link import LinkEvent, LinkSettings, VehicleLink, open_link
from .link.base import RETURNING_MODES
from .operator import OperatorGate, hello_reply, read_command, reply_for
from .places import Place, plan_places, user_places
from .rows import UserRow
from .planning import Planner, VehicleFix, after_hold, assemble, not_served_reason, planning_battery_j
from .sortie import HeldMission, Rules, Sortie, SortieLogic, VehicleSnapshot, item_dict, new_sortie
from .sortie import effects as fx
from .sortie import inputs as ins
from .sortie.fleet import Claims, FleetView, coarse
from .supervisor import Supervisor
from .throttle import RateLimit
from .vehicle_view import VehicleView
from .world import FleetWorld, JournalWorld
from .zenoh_io import ZenohIO, reply_and_drop

log = logging.getLogger("planner_service")

GRACE_S = 5.0
"""Bounded wait for an upload in progress at shutdown."""
OPERATIONS = (fx.MakePlan, fx.Upload, fx.ReadBack, fx.Command)
"""The effects that start an operation on the planner or the vehicle (``Service._job``):
none is carried out once the service is stopping."""
CONNECT_TIMEOUT_S = 10.0
TICK_S = 0.05
"""Period of the sortie logic's look at the telemetry (every position report counts for a
hold: the link reports a few to a few tens a second)."""
FLOWN_KEY = "flown_sortie"
"""Journal meta key: the number of the last sortie in which the vehicle was airborne."""
AUTHORITY_KEY = "authority"
"""Journal meta key: the authority of the current sortie (state|detail), so a restart of the
service never regains an authority the pilot had ended."""
REFUSAL_EVENTS_PER_S = 5.0
"""At most this many ``request_rejected`` events a second for refused requests (a flood of
bad requests must not become a flood of events); the rest are counted in the next one."""
BUSY_LOG_EVERY_S = 10.0
"""Period of the warning that counts queries answered busy."""
UPLOAD_SLACK_S = 0.5
"""Wall time allowed for an upload, at least (more when uploads have been taking longer)."""
UPLOAD_HISTORY = 5


@dataclass
class Parts:
    """What the service is given: its I/O, built by ``run_service`` (or a test)."""

    journal: Journal
    open_link: Callable[[Callable[[LinkEvent], None]], VehicleLink]
    zio: ZenohIO
    operator_gate: OperatorGate
    """Who may send the operator's commands (the key's proof, or zenoh's access control)."""
    wall: Callable[[], float] = time.time
    """Timestamps in the journal and the publications."""
    mono: Callable[[], float] = time.monotonic
    """Every wait and timeout."""


class Service:
    def __init__(self, config: ServiceConfig, parts: Parts) -> None:
        self.cfg = config
        self.parts = parts
        self.wall, self.mono = parts.wall, parts.mono
        self.scenario = config.scenario()
        self._hover_xy = [(float(x), float(y)) for x, y, *_ in hover_points(self.scenario)]
        self.area = config.area()
        self.origin = config.origin_point()
        self.keys = config.keys()
        self.flavour = config.mavlink.flavour
        self.journal = parts.journal
        self.zio = parts.zio
        self.fleet = parts.zio.fleet
        """This UAV's fleet membership (``[fleet] enabled``), None for a lone UAV."""
        self._settling = None if self.fleet is None else ClaimSettling(
            self.fleet.roster, self.fleet.ledger, config.fleet.settle_max_s, config.fleet.settle_margin_s, self.wall)
        """The judge of this member's claims' settling."""
        self.intake = Intake(self.journal, self.area, self.wall, config.intake, keys=self.keys, monotonic=self.mono,
                             unservable=fairness_rule(self.scenario), vehicle=self.keys.vehicle,
                             fleet_keys=None if self.fleet is None else self.fleet.keys)
        self._refusal_events = RateLimit(REFUSAL_EVENTS_PER_S, self.mono())
        self._refusals_unreported = 0
        self._busy_logged = (self.mono(), 0)
        self.planner = Planner(self.scenario, MctsConfig(iterations=config.planner.iterations or None,
                                                         budget_ms=config.planner.budget_ms),
                               config.planner.seed, _max_points(config), config.planner.algo)
        self.link = parts.open_link(self._on_link_event)
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner")
        self.stopping = asyncio.Event()
        self.supervisor = Supervisor(self._on_failure, self.stopping)
        self._jobs: set[asyncio.Task[Any]] = set()
        self._upload_times_s: list[float] = []
        self.view = VehicleView(self.scenario, self.origin, self.area)
        self._waiting_for = ""
        s = config.safety
        self.world = JournalWorld(self.journal) if self.fleet is None else FleetWorld(self.journal)
        self.logic = SortieLogic(Rules(
            scenario=self.scenario, origin=self.origin, area=self.area, flavour=self.flavour,
            start_mission=config.mavlink.start_mission, min_requests=config.planner.min_requests,
            replan_min_interval_s=config.planner.replan_min_interval_s, hold_radius_m=s.hold_radius_m,
            rtl_battery_fraction=s.rtl_battery_fraction, repeat=config.sortie.repeat,
            next_battery_fraction=config.sortie.next_battery_fraction,
            readback_interval_s=config.sortie.readback_interval_s, leg_tolerance_m=config.sortie.leg_tolerance_m,
            max_mission_items=config.mavlink.max_mission_items, max_failures=config.planner.max_failures,
            hold_margin_s=s.hold_margin_s, energy_margin_j=s.energy_margin_j, vehicle=config.zenoh.vehicle,
            answer_step_s=config.fleet.answer_step_s, answer_tie_m=config.fleet.answer_tie_m,
            max_answer_rank=config.fleet.max_answer_rank,
            settle_max_s=config.fleet.settle_max_s if self.fleet is not None else 0.0,
        ), self.world)
        self.state = self._restore()
        self._plan_dues: dict[str, float] = {}
        """When this UAV's last plan means to serve each of its users (wall clock)."""
        self._bound_at: tuple[str, float] | None = None
        """The user a hold of this UAV is bound to, and since when (wall clock)."""
        self._points_at: dict[int, float] = {}
        """The hovering points this UAV claims, each since when (wall clock): of members that
        claimed one point before hearing each other, the first keeps it."""
        self._route: tuple[int, ...] = ()
        """The hovering points of the mission on board still to fly (its airspace if this
        service is lost while the vehicle flies)."""
        self.plan_msg: Plan | None = None
        if self.state.life.over:
            self.intake.closed_reason = self._closed_reason()

    # --- the sortie as the journal left it ------------------------------------------------------
    def _restore(self) -> Sortie:
        j = self.journal
        sortie = j.current_sortie()
        state = new_sortie(sortie.number, self.logic.rules, j.last_plan_id())
        saved = j.get_meta(AUTHORITY_KEY)
        if saved and saved.startswith(f"{sortie.number}|"):
            _, kind, detail = saved.split("|", 2)
            state = replace(state, authority=replace(state.authority, state=kind, detail=detail))  # type: ignore[arg-type]
        services = j.services()
        last = j.last_mission()
        held = None
        judged: frozenset[int] = frozenset()
        if last is not None:
            held = HeldMission.from_journal(last.plan_id, last.items, last.points, self.flavour)
            judged = held.served_since(last.time_s, [(s.user_id, s.time_s) for s in services])
        life = replace(state.life, just_started=True, warming=True, services=len(services),
                       over=(sortie.why or "ended") if sortie.over else None,
                       flown=j.get_meta(FLOWN_KEY) == str(sortie.number))
        return replace(state, life=life, onboard=replace(state.onboard, held=held),
                       holds=replace(state.holds, judged=judged),
                       schedule=replace(state.schedule, last_hover_index=services[-1].hover_index if services else -1))

    # --- lifecycle ----------------------------------------------------------------------------
    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                loop.add_signal_handler(sig, self.stopping.set)
            except (NotImplementedError, RuntimeError):  # not the main thread (tests)
                pass
        log.info("%s", self.parts.operator_gate.why)
        self.supervisor.start("connect", self._connect_loop())
        self.supervisor.start("tick", self._tick_loop(), forever=True)
        self.supervisor.start("status", self._status_loop(), forever=True)
        self.supervisor.start("warm-up", self._warm_up())
        z = self.cfg.zenoh
        try:
            opened = await self.zio.open(loop, self._on_request, self._on_state, self.stopping,
                                         on_operator=self._on_operator)
        except BaseException:
            await self._cancel_all()
            await self.link.close()
            self.journal.close()
            raise
        if opened:
            log.info("zenoh %s session on %s (connect %s%s); keys %s/**", z.mode, list(z.listen), list(z.connect),
                     f"; base {z.config_file}" if z.config_file else "", f"{self.keys.prefix}/{self.keys.vehicle}")
            log.info("ready: sortie %d (%s): %d pending requests, %d services in the journal %s",
                     self.state.life.number, f"over: {self.state.life.over}" if self.state.life.over else "running",
                     self.journal.pending_count(), len(self.journal.services()), self.cfg.journal.path)
        await self.stopping.wait()
        await self._shutdown()
        return 0

    async def _cancel_all(self) -> None:
        for task in self._jobs:
            task.cancel()
        await asyncio.gather(*self._jobs, return_exceptions=True)
        await self.supervisor.stop(0.0)

    async def _shutdown(self) -> None:
        log.info("stopping: intake closed")
        self.intake.closed_reason = "the service is shutting down"
        self.zio.stop_intake()
        mission_ops = [t for t in self._jobs if t.get_name() in ("upload", "readback")]
        if mission_ops:
            done, pending = await asyncio.wait(mission_ops, timeout=GRACE_S)
            if pending:
                log.warning("an upload or read-back was still running after %.0f s: abandoned (the vehicle keeps "
                            "its mission)", GRACE_S)
        await self._cancel_all()
        await self.link.close()
        self.zio.close()
        self.executor.shutdown(wait=False, cancel_futures=True)
        try:
            self.journal.close()
        except JournalError as err:
            log.error("stopped: journal NOT flushed: %s", err)
            return
        if self.journal.failed:
            log.error("stopped: journal NOT flushed: %s", self.journal.failed)
        else:
            log.info("stopped: journal flushed")

    async def _warm_up(self) -> None:
        """Compile every kernel the planner uses before the first request needs them; until
        then the service plans and starts nothing (its status says it waits for this)."""
        start = time.monotonic()
        log.info("planner warming up: compiling its kernels or loading them from numba's cache")
        try:
            await asyncio.get_running_loop().run_in_executor(self.executor, self.planner.warm_up)
        except Exception as err:  # noqa: BLE001 - the first plan compiles what is missing
            log.error("planner warm-up failed (%s): the first plan compiles what it needs", err)
        else:
            log.info("planner warmed up: its kernels compiled or loaded from numba's cache in %.1f s",
                     time.monotonic() - start)
        self._feed(ins.WarmedUp())

    async def _connect_loop(self) -> None:
        while True:
            try:
                await self.link.connect(CONNECT_TIMEOUT_S)
                return
            except LinkError as err:
                log.warning("waiting for the autopilot: %s", err)
                await self.link.close()
                self.link = self.parts.open_link(self._on_link_event)

    # --- feeding the sortie logic -------------------------------------------------------------------
    def _feed(self, event: ins.Input) -> None:
        before = self.state
        self.state, effects = self.logic.step(before, event, self._vehicle(), self.mono())
        self._carry_out(before, effects)

    def _carry_out(self, before: Sortie, effects: list[fx.Effect]) -> None:
        """Carry out the logic's effects; once the service is stopping, only those that
        record (journal, events, logs): no plan, upload, read-back or command starts."""
        if self.state.authority != before.authority:
            self._save_meta(AUTHORITY_KEY, f"{self.state.life.number}|{self.state.authority.state}|"
                                           f"{self.state.authority.detail}")
        stopping = self.stopping.is_set()
        for effect in effects:
            if not (stopping and isinstance(effect, OPERATIONS)):
                self._do(effect)

    def _do(self, e: fx.Effect) -> None:
        match e:
            case fx.MakePlan(basis=basis):
                self._job("plan", self._plan(basis))
            case fx.Upload():
                self._job("upload", self._upload(e))
            case fx.ReadBack():
                self._job("readback", self._read_back())
            case fx.Command():
                self._job("command", self._command(e))
            case fx.RecordService():
                self._record_service(e)
            case fx.RecordMission(plan_id=plan_id, mission=mission, result=result):
                try:
                    self.journal.record_mission(plan_id, [item_dict(i) for i in mission.items],
                                                mission.journal_points(), result, self.wall())
                except JournalError as err:
                    log.error("could not record plan %d's mission: %s", plan_id, err)
            case fx.Emit(event=event):
                self._event(event)
            case fx.PublishPlan(mission=mission, predicted_energy_j=energy):
                self._publish_plan(mission, energy)
            case fx.Intend(claims=claims):
                self._tell_claims(claims)
            case fx.Log(level=level, text=text):
                getattr(log, level)("%s", text)
            case fx.Unsettled(plan_id=plan_id, point=point, waited_s=waited_s):
                log.warning("plan %d: the claim of point %d has not settled in %g s (not heard since: %s): flown as "
                            "decided", plan_id, point, waited_s, ", ".join(self._unheard(point)) or "none now")
            case fx.EndSortie(why=why):
                self._end_sortie(why)
            case fx.BeginSortie(battery_fraction=fraction):
                self._begin_sortie(fraction)
            case fx.MarkFlown():
                self._save_meta(FLOWN_KEY, str(self.state.life.number))
            case _:
                assert_never(e)

    def _job(self, name: str, coro: Awaitable[ins.Input | None]) -> None:
        """Run an operation off the logic and feed its outcome back when it ends. Once the
        service is stopping only an upload's or a read-back's outcome is fed: the shutdown
        waits for them so that the journal records the mission the vehicle now holds."""
        async def run() -> None:
            outcome = await coro
            if outcome is not None and (not self.stopping.is_set() or isinstance(
                    outcome, (ins.Uploaded, ins.NotUploaded, ins.ReadBackDone, ins.ReadBackFailed))):
                self._feed(outcome)
        task = asyncio.ensure_future(run())
        task.set_name(name)
        self._jobs.add(task)
        task.add_done_callback(self._job_done)

    def _job_done(self, task: asyncio.Task[Any]) -> None:
        self._jobs.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("%s failed", task.get_name(), exc_info=task.exception())

    # --- operations ---------------------------------------------------------------------------------
    async def _plan(self, basis: fx.PlanBasis) -> ins.Input:
        fix = self._planning_fix(basis)
        try:
            pending = [r for r in self.world.pending() if self.state.fleet.owner(r.user_id) is None]
            assembled = assemble(self.scenario, self._users(), pending, self.journal.services(), fix,
                                 self.state.schedule.last_hover_index)
        except JournalError as err:
            return ins.PlanFailed(basis, f"journal: {err}")
        if basis.at_point is not None:
            assembled = after_hold(assembled, basis.at_point, basis.serving, basis.serving_reward)
        newest = max((r.request_id for r in pending), default=0)
        t0 = time.perf_counter()
        try:
            blocked = self.state.fleet.blocked
            _, path = await asyncio.get_running_loop().run_in_executor(self.executor, self.planner.decide, assembled,
                                                                       blocked)
        except Exception as err:  # noqa: BLE001 - a planner bug must not stop the sortie
            log.exception("the planner failed")
            return ins.PlanFailed(basis, f"planner: {err}")
        planner_ms = (time.perf_counter() - t0) * 1e3
        log.info("decision (%s): %s in %.0f ms", basis.reason, [p.hover_index for p in path.points], planner_ms)
        return ins.Planned(basis, path, planner_ms, newest)

    def _users(self) -> list[UserRow]:
        """Every user heard from, with its services as the world counts them (in a fleet,
        the other members' too: the fairness rule spans the fleet)."""
        counts = self.world.service_counts()
        return [replace(u, services=counts.get(u.user_id, 0)) for u in self.journal.users()]

    async def _upload(self, up: fx.Upload) -> ins.Input:
        t0 = self.mono()
        try:
            await self.link.upload(list(up.items), current_seq=up.current_seq, restart_current=up.restart_current)
        except LinkError as err:
            if err.operation != "set_current()":
                return ins.NotUploaded(up, err.result, err.outcome_unknown)
            # The mission is held; only the item flown could not be confirmed (an autopilot
            # that does not report MISSION_CURRENT): its own index stands.
            log.warning("plan %d is held, but the item the vehicle flies could not be set: %s", up.plan_id, err)
        self._upload_times_s = [*self._upload_times_s, self.mono() - t0][-UPLOAD_HISTORY:]
        log.info("plan %d: %s uploaded (%d items, %.0f ms; %s)", up.plan_id,
                 [p.hover_index for p in up.path.points], len(up.items), (self.mono() - t0) * 1e3,
                 up.path.stop_reason)
        return ins.Uploaded(up, upload_ms=(self.mono() - t0) * 1e3, mission_id=self.link.mission_id)

    async def _read_back(self) -> ins.Input:
        try:
            items = await self.link.download()
        except LinkError as err:
            return ins.ReadBackFailed(err.result)
        return ins.ReadBackDone(tuple(items), mission_id=self.link.mission_id)

    async def _command(self, cmd: fx.Command) -> ins.Input:
        try:
            match cmd.kind:
                case "start":
                    await self.link.start(self._may_go_on)
                case "resume":
                    await self.link.resume(self._may_go_on)
                case "return":
                    await self.link.return_to_launch()
                case "hold":
                    await self.link.hold()
                case "set_current":
                    await self.link.set_current(cmd.seq)
                case _:
                    assert_never(cmd.kind)
        except LinkError as err:
            return ins.CommandNotDone(cmd, str(err))
        return ins.CommandDone(cmd)

    def _may_go_on(self) -> str | None:
        """Asked between a command's steps: the authority may have ended meanwhile (the pilot,
        the autopilot's own disarming), and then nothing more is sent."""
        authority = self.state.authority
        return None if authority.granted else f"the authority ended ({authority.detail})"

    def _record_service(self, e: fx.RecordService) -> None:
        self._tell_fleet_served(e)  # flown, whatever the journal says
        battery_j = (self._vehicle().battery_fraction or 0.0) * self.scenario.battery_j
        try:
            self.world.record_service(e.request_id, e.user_id, e.tasks, e.hover_index, e.xyz, e.bits, e.reward,
                                      battery_j, self.wall(), e.bound_tasks)
        except JournalError as err:
            # kept by the world view (counted as served for the rest of the sortie) and here
            # whole, so that what the journal lacks is on record
            log.error("could not record the service of request %d: %s; kept in memory: user %s, %d tasks "
                      "(bound to %s) at point %d (%.1f, %.1f, %.1f), %.0f bits, reward %.6g, held %.1f s, "
                      "battery %.0f J, at %.3f", e.request_id, err, e.user_id, e.tasks, e.bound_tasks,
                      e.hover_index, *e.xyz, e.bits, e.reward, e.held_s, battery_j, self.wall())
            self._check_journal()

    def _tell_fleet_served(self, e: fx.RecordService) -> None:
        if self.fleet is not None and self.fleet.joined:
            self.fleet.ledger.served(e.user_id, e.tasks, self.wall())

    def _hear_fleet(self) -> None:
        """What the other members own and claim, fed to the sortie logic when it changed, and
        the services they flew, counted (docs/OPERATIONS.md, "A fleet")."""
        if self.fleet is None or not isinstance(self.world, FleetWorld):
            return
        ledger = self.fleet.ledger
        if not ledger.told:  # the others settle their claims on this member's intentions: said from the start
            self._tell_claims(self.state.claims)
        ledger.beat(self.cfg.fleet.intentions_every_s)
        answering = coarse(self.fleet.whereabouts(ledger.answering()))
        heard = FleetView(ledger.owners(), ledger.blocked_points() | self._others_over(), ledger.yield_points(),
                          answering, self._settled(), self._bound_settled())
        if heard != self.state.fleet:
            self._feed(ins.FleetHeard(heard))
        for done in self.fleet.ledger.take_served():
            held = self.world.count_remote(done.user_id, done.tasks)
            log.info("fleet: %s served %s %d tasks%s", done.vehicle, done.user_id, done.tasks,
                     "" if held else " (no request of that user in force here)")
            self._event(ev.UserServed(f"by {done.vehicle}: {done.tasks} tasks", user_id=done.user_id))

    def _settled(self) -> frozenset[int]:
        """The points this member claims whose claims have settled (``ClaimSettling``)."""
        assert self._settling is not None
        return frozenset(k for k, at in self._points_at.items() if self._settling.settled(at))

    def _bound_settled(self) -> str | None:
        """The user this member claims as bound once its binding has settled (as a point's)."""
        if self._bound_at is None:
            return None
        assert self._settling is not None
        user, at = self._bound_at
        return user if self._settling.settled(at) else None

    def _unheard(self, point: int) -> list[str]:
        """The vehicles a claim of ``point`` settles on whose intentions signed
        ``fleet.settle_margin_s`` after the claim this member has not heard."""
        claimed_at = self._points_at.get(point)
        if self._settling is None or claimed_at is None:
            return []
        return self._settling.unheard(claimed_at)

    def _others_over(self) -> frozenset[int]:
        """The hovering points another member's vehicle is over now (``fleet.occupied_m``),
        but those this member claims: planned without, whatever was heard of the others'
        claims. Over the radios a claim came 13-20 s late now and then (a dropped sample
        recovered by the advanced subscriber) while the positions kept coming: a member on
        its way home planned a point another had held for 11 s, and held it beside it. A
        point this member claims stays the claim rule's (the later claimant yields: were
        both to leave on seeing the other, neither would serve it)."""
        radius = self.cfg.fleet.occupied_m
        if self.fleet is None or radius <= 0:
            return frozenset()
        return self.fleet.others_over(self._hover_xy, radius) - self.state.claims.points

    # --- the vehicle as the logic sees it ----------------------------------------------------------
    def _vehicle(self) -> VehicleSnapshot:
        vehicle, self._waiting_for = self.view.see(self.link.telemetry, self.mono())
        return vehicle

    def _upload_s(self) -> float:
        return max([UPLOAD_SLACK_S, *self._upload_times_s])

    def _fix(self) -> VehicleFix:
        v = self._vehicle()
        battery = (v.battery_fraction or 0.0) * self.scenario.battery_j
        return VehicleFix(*v.xyz, battery, v.airborne)

    def _planning_fix(self, basis: fx.PlanBasis) -> VehicleFix:
        """The vehicle as the planner should see it: a conservative battery, less what it
        spends until the plan is flown (the reading's age, the search, the upload)."""
        fix = self._fix()
        t = self.link.telemetry
        stale_wall = max(self.mono() - t.battery_at, 0.0) if t.battery_at else 0.0
        # (the logic plans only once the rate is known: unknown, the time waited could be any flight)
        rate = t.time_rate if t.time_rate is not None else math.inf
        stale_vehicle = rate * (stale_wall + self.cfg.planner.budget_ms / 1e3 + self._upload_s())
        battery = planning_battery_j(self.scenario, fix.battery_j, stale_vehicle, self.cfg.safety.energy_margin_j)
        if basis.at_point is not None:  # the hold there is still to be paid
            pt = basis.at_point
            battery -= self.scenario.hover_power_w * pt.hold_s
            fix = replace(fix, x_m=pt.x_m, y_m=pt.y_m, z_m=pt.z_m)
        return replace(fix, battery_j=battery)

    # --- loops ---------------------------------------------------------------------------------------
    async def _tick_loop(self) -> None:
        while True:
            self._hear_fleet()
            self._feed(ins.Tick(self.mono()))
            await asyncio.sleep(TICK_S)

    async def _status_loop(self) -> None:
        period = 1.0 / self.cfg.zenoh.status_hz
        while True:
            self._check_journal()
            status = self._status()
            self.zio.publish(status)
            self._log_busy()
            if self.zio.fleet is not None and self.zio.fleet.joined:
                self.zio.fleet.publish_position(status)  # signed: the others judge separation on it
                self.zio.fleet.check_separation()
            await asyncio.sleep(period)

    def _log_busy(self) -> None:
        """Say how many queries were answered busy (they never reach the loop otherwise)."""
        since, seen = self._busy_logged
        now, refused = self.mono(), self.zio.in_flight.refused
        if refused > seen and now - since >= BUSY_LOG_EVERY_S:
            log.warning("%d queries answered busy in the last %.0f s (zenoh.max_queries_in_flight = %d)",
                        refused - seen, now - since, self.zio.in_flight.limit)
            self._busy_logged = (now, refused)
        elif refused == seen:
            self._busy_logged = (now, refused)

    # --- zenoh handlers (on the loop's thread) -------------------------------------------------
    def _on_request(self, query: Any) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else None
        key = str(query.key_expr)  # the plain request key or a user's own (which binds its user id)
        outcome = self.intake.handle(payload, key)
        reply_and_drop(query, key, encode(outcome.reply))
        if isinstance(outcome, Accepted):
            self._event(ev.RequestAccepted(outcome.describe(), outcome.user_id, outcome.request_id))
            self._feed(ins.RequestIn(outcome.user_id, 0 if outcome.done else outcome.tasks))
        elif self._refusal_events.take(self.mono()):
            unreported = f"[{self._refusals_unreported} more refused, not reported] " if self._refusals_unreported else ""
            self._refusals_unreported = 0
            self._event(ev.RequestRejected(f"{unreported}{outcome.describe()}"))
        else:
            self._refusals_unreported += 1
        self._check_journal()

    def _on_operator(self, query: Any) -> None:
        """An operator's command: read at the edge (an error naming the field changes
        nothing), decided by the sortie logic, answered with what the service did."""
        payload = query.payload.to_bytes() if query.payload is not None else None
        gate = self.parts.operator_gate

        def answer(reply: OperatorReply | ErrorReply) -> None:
            data = encode(reply)  # proved as sent: the client checks these very bytes
            reply_and_drop(query, self.keys.operator, data, gate.prove(data, payload))
        cmd = read_command(payload, gate, self.wall())
        if isinstance(cmd, ErrorReply):
            log.warning("operator command refused: %s: %s", printable(cmd.field, 64), printable(cmd.message, 300))
            answer(cmd)
            return
        if cmd.command == "hello":
            answer(hello_reply(cmd, gate, self._status()))
            return
        before = self.state
        self.state, effects, accepted, message = self.logic.operator(
            before, ins.OperatorAsked(cmd.command, cmd.reason), self._vehicle(), self.mono())
        self._carry_out(before, effects)
        if self.state.authority != before.authority:
            log.info("operator: authority %s -> %s (%s)", before.authority.state, self.state.authority.state,
                     self.state.authority.detail)
        fleet = self._fleet_state() if cmd.command == "status" else None
        answer(reply_for(cmd, accepted, message, self._status(), fleet))

    def _fleet_state(self) -> State:
        """Everything: the status, the plan with its users, every pending request (each
        user's position and backlog). The operator's alone: in the reply to ``status``."""
        pending = [PendingRequest(request_id=r.request_id, user_id=r.user_id, x_m=r.x_m, y_m=r.y_m, z_m=r.z_m,
                                  tasks=r.backlog) for r in self.journal.pending()]
        return State(status=self._status(), plan=self.plan_msg, pending=pending)

    def _on_state(self, query: Any) -> None:
        """Anyone's: nothing personal (docs/PROTOCOL.md, "Who may do what"): the status (the
        vehicle's, and counts) and the plan's points without whom they serve; no pending list."""
        state = State(status=self._status(), plan=public_plan(self.plan_msg))
        reply_and_drop(query, self.keys.state, encode(state))

    def _on_link_event(self, event: LinkEvent) -> None:
        """What the link reports is an input of the sortie logic as it is."""
        self._feed(event)

    def _event(self, event: ev.ServiceEvent) -> None:
        self.zio.publish(ev.to_wire(event, self.wall()))

    # --- publications --------------------------------------------------------------------------------
    def _phase(self) -> str:
        t, s = self.link.telemetry, self.state
        if s.life.degraded:
            return "degraded"
        if not t.connected:
            return "lost"
        if s.life.over:
            return "landed"
        if t.airborne and t.mode in RETURNING_MODES:
            return "returning"
        if t.airborne:
            return "flying"
        return "planning" if s.schedule.busy == "plan" else "idle"

    def _status(self) -> Status:
        t, s = self.link.telemetry, self.state
        v = self._vehicle()
        x, y, z = v.xyz
        fraction = None if v.battery_fraction is None else min(max(v.battery_fraction, 0.0), 1.0)
        return Status(
            vehicle=self.keys.vehicle, time_s=self.wall(), phase=self._phase(), armed=t.armed, mode=t.mode[:256],
            x_m=x, y_m=y, z_m=z, battery_fraction=fraction, battery_source=v.battery_source,
            mission_seq=max(t.mission_seq, 0), mission_total=max(t.mission_total, 0),
            pending_requests=self.journal.pending_count(), served_users=len(self.journal.service_counts()),
            authority=s.authority.state, authority_detail=s.authority.detail[:256], position_ok=v.position_ok,
            waiting_for=self._waiting()[:256], degraded=(s.life.degraded or "")[:256],
        )

    def _waiting(self) -> str:
        warming = "the planner warming up (compiling its kernels)" if self.state.life.warming else ""
        return "; ".join(w for w in (warming, self._waiting_for) if w)

    def _publish_plan(self, held: HeldMission, predicted_energy_j: float = 0.0) -> None:
        """The plan's points still to fly, and every user's place in it (for the acks and
        on each user's key, docs/PROTOCOL.md)."""
        v = self._vehicle()
        ahead = [p for _, p in held.points_after(v.seq - 1)]
        self.plan_msg = Plan(plan_id=held.plan_id, time_s=self.wall(), predicted_energy_j=max(predicted_energy_j, 0.0),
                             points=[PlanPoint(p.x_m, p.y_m, p.z_m, p.hold_s, p.user_id) for p in ahead])
        self.zio.publish(self.plan_msg)
        self._event(ev.PlanUpdated(f"plan {held.plan_id}: {len(ahead)} points ahead"))
        try:
            places = plan_places(ahead, v.xyz, self.scenario.speed_mps)
            messages = user_places(self.journal.user_backlogs(), places, sortie=self.state.life.number,
                                   plan_id=held.plan_id, time_s=self.wall())
        except (JournalError, PlanningError) as err:
            log.error("plan %d: users' places not published: %s", held.plan_id, err)
            return
        self.intake.set_places(places)
        self._plan_dues = self._dues(places, v.time_rate)
        self._route = tuple(p.hover_index for p in ahead)
        self._tell_claims(self.state.claims)  # the dues and route are the plan's
        for message in messages:
            self.zio.publish(message)

    def _dues(self, places: dict[str, Place], time_rate: float | None) -> dict[str, float]:
        """When this plan means to serve each of its users (wall clock)."""
        now, rate = self.wall(), time_rate if time_rate and time_rate > 0 else 1.0
        return {u: now + p.eta_s / rate for u, p in places.items()}

    def _tell_claims(self, claims: Claims) -> None:
        """Put what the sortie logic claims (``fx.Intend``) in this member's signed intentions,
        with the plan's dues and route; the moment a hold was bound, and a point claimed, is
        this computer's clock when it was first told (docs/OPERATIONS.md, "A fleet")."""
        if self.fleet is None or not self.fleet.joined:
            return
        if claims.bound is None:
            self._bound_at = None
        elif self._bound_at is None or self._bound_at[0] != claims.bound:
            self._bound_at = (claims.bound, self.wall())
        users = {claims.next_user} - {None, claims.bound}
        now = self.wall()
        self._points_at = {k: self._points_at.get(k, now) for k in claims.points}
        self.fleet.ledger.intend(dict(self._plan_dues), now, users, claims.points, self._route,
                                 self._bound_at, claims.holding, claims.answering, self._points_at)
        if log.isEnabledFor(logging.DEBUG):  # the others' owners are worked out for the line alone
            log.debug("fleet: claims %s; others own %s", claims, sorted(self.fleet.ledger.taken()))

    # --- failing loud -------------------------------------------------------------------------------
    def _on_failure(self, name: str, error: BaseException) -> None:
        self._degrade(f"the {name} task failed: {type(error).__name__}: {printable(error, 150)}")

    def _check_journal(self) -> None:
        why = self.journal.check()
        if why is not None:
            self._degrade(why)

    def _degrade(self, why: str) -> None:
        """Something the service needs failed: it takes no more requests, says why (status,
        an event, the log), withdraws its liveliness and commands nothing more; the vehicle
        flies on the complete mission it holds (it ends in return to launch)."""
        if self.state.life.degraded is not None:
            return
        self.intake.closed_reason = f"the service is degraded: {why}"[:256]
        self.zio.withdraw_liveliness()
        self._feed(ins.PartFailed(why))

    # --- sortie end and begin --------------------------------------------------------------------
    def _end_sortie(self, why: str) -> None:
        """Close the sortie: every pending request is reported not served, with its reason;
        the intake refuses requests until the next sortie begins."""
        counts = self.world.service_counts()  # in a fleet, the other members' services too
        reasons = {r.request_id: not_served_reason(self.scenario, r.backlog, counts.get(r.user_id, 0),
                                                   f"sortie ended before its turn ({why})")
                   for r in self.journal.pending()}
        try:
            self.journal.end_sortie(why, reasons, self.wall())
        except JournalError as err:
            log.error("could not close sortie %d in the journal: %s", self.state.life.number, err)
        for rid, reason in reasons.items():
            self._event(ev.RequestRejected(f"not served: {reason}", request_id=rid))
        self.intake.closed_reason = self._closed_reason()
        self._plan_dues, self._route = {}, ()  # nothing more this sortie: the users are the others' to serve
        self._tell_claims(self.state.claims)
        self._event(ev.Landed(f"sortie {self.state.life.number}: {why}"))
        log.info("sortie %d over: %s; %d services, %d requests not served", self.state.life.number, why,
                 len(self.journal.services()), len(reasons))

    def _closed_reason(self) -> str:
        """What a request hears between sorties."""
        if not self.cfg.sortie.repeat:
            return f"sortie over: {self.state.life.over}; this service flies one sortie (sortie.repeat = false)"
        return (f"sortie over: waiting for the battery (at least {self.cfg.sortie.next_battery_fraction:.0%}) "
                f"with the vehicle on the ground and disarmed before sortie {self.state.life.number + 1}")

    def _begin_sortie(self, battery_fraction: float) -> None:
        try:
            number = self.journal.begin_sortie(self.wall())
        except JournalError as err:
            log.error("could not begin the next sortie: %s", err)
            self.state = replace(self.state, life=replace(self.state.life, beginning=False))
            return
        self.plan_msg = None
        self.planner.new_sortie()
        self.intake.new_sortie()
        log.info("sortie %d begins: battery at %.0f%%", number, 100 * battery_fraction)
        asyncio.get_running_loop().call_soon(self._feed, ins.SortieBegun(number))

    def _save_meta(self, key: str, value: str) -> None:
        try:
            self.journal.set_meta(key, value)
        except JournalError as err:
            log.error("could not note %s in the journal: %s", key, err)


def public_plan(plan: Plan | None) -> Plan | None:
    """``plan`` without the user served at each point."""
    if plan is None:
        return None
    return msgspec.structs.replace(plan, points=[msgspec.structs.replace(p, user_id=None) for p in plan.points])


def operator_gate(config: ServiceConfig) -> OperatorGate:
    """The gate of the operator's commands: the key's proof (the key file loaded, or made
    with mode 0600 if absent), unless zenoh's access control decides. ``ConfigError``
    naming ``operator.key_file`` if the key cannot be read or made."""
    if not config.operator_proof_needed():
        return OperatorGate(None, f"zenoh access control ({config.zenoh.config_file}) decides who may query "
                                  f"{config.keys().operator}; no operator key needed (operator.proof = auto)")
    path = config.operator_key_path()
    try:
        key, made = load_or_create_key(path)
    except SigningError as err:
        raise ConfigError("operator.key_file", str(err)) from None
    check = ProofCheck(key, config.keys(), config.operator.proof_window_s)
    return OperatorGate(check, f"operator commands need the proof of the key in {path}"
                               f"{' (made now, mode 0600)' if made else ''}")


def _max_points(config: ServiceConfig) -> int:
    from protocol.mission import max_points

    return max_points(config.mavlink.max_mission_items, config.mavlink.flavour)  # type: ignore[arg-type]


def build_parts(config: ServiceConfig) -> Parts:
    """The service's I/O from its configuration."""
    m = config.mavlink
    settings = LinkSettings(m.url, m.flavour, m.item_timeout_s, m.retries, m.link_timeout_s, m.source_system,
                            m.source_component, signing_key_file=m.signing_key_file,
                            signing_timestamp_file=m.signing_timestamp_file)
    journal = Journal(config.journal.path, config.journal.synchronous, now_s=time.time())
    try:
        gate = operator_gate(config)
    except ConfigError:
        journal.close()
        raise
    return Parts(journal=journal, open_link=lambda on_event: open_link(m.backend, settings, on_event),
                 zio=ZenohIO(config.zenoh, config.keys(), fleet_presence(config), config.fleet.discovery_s),
                 operator_gate=gate)


def fleet_presence(config: ServiceConfig) -> FleetPresence | None:
    """This UAV's membership of the fleet (``[fleet] enabled``): its layer is the scenario's
    altitude; None for a lone UAV."""
    if not config.fleet.enabled:
        return None
    o = config.origin_point()
    own = FleetMember(vehicle=config.zenoh.vehicle, layer_m=config.scenario().altitude_m,
                      min_gap_m=layer_gap_m(config.fleet.vertical_separation_m, config.fleet.altitude_margin_m),
                      origin_lat_deg=o.lat_deg, origin_lon_deg=o.lon_deg,
                      origin_alt_m=o.alt_m, autopilot=config.mavlink.flavour)
    f = config.fleet
    if f.insecure and config.fleet_transport_open():
        log.warning("fleet: INSECURE (fleet.insecure = true): %s; any peer can read the fleet's keys and flood "
                    "them (the signatures still refuse what the enrolled members did not sign)",
                    config.fleet_transport_open())
    try:
        signer = FleetSigner(config.zenoh.vehicle, load_private_key(f.key_file))
        verifier = FleetVerifier(read_roster(f.roster_file))
    except SigningError as err:
        raise ConfigError("fleet.key_file", str(err)) from None
    if config.zenoh.vehicle not in verifier.roster:
        raise ConfigError("fleet.roster_file", f"{config.zenoh.vehicle} is not enrolled in {f.roster_file}")
    return FleetPresence(FleetKeys(config.zenoh.prefix), own, signer, verifier, f.min_horizontal_m,
                         f.position_stale_s, f.max_layer_gap_m, f.lost_airspace_s,
                         vertical_separation_m=f.vertical_separation_m, max_clock_offset_s=f.max_clock_offset_s)


def run_service(config: ServiceConfig, on_stopped: Callable[[int], None] | None = None) -> int:
    """Run the service until SIGINT or SIGTERM; returns the exit status. ``on_stopped`` is
    told the status as soon as the service has stopped (its last line logged), before the
    event loop is closed (``serve`` arms its exit deadline there)."""
    np.seterr(all="ignore")  # the kernels handle their own infinities
    if cap_arenas():
        log.debug("C allocator capped at %d arenas (MALLOC_ARENA_MAX overrides)", ARENAS)
    service = Service(config, build_parts(config))

    async def main() -> int:
        status = 1
        try:
            status = await service.run()
            return status
        finally:
            if on_stopped is not None:
                on_stopped(status)
    return run_to_end(main())
