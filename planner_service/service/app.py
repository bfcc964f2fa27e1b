"""The long-running service: asyncio orchestration of intake, planning, the autopilot link
and the zenoh publications, and the one shutdown path.

Everything that decides is elsewhere and pure (``intake``, ``planning``, ``progress``,
``link/upload``); this module wires them to the clock, the event loop and the sockets.
The planner runs in a worker thread (numba, nogil) so that acks, heartbeats and status go
on while it searches.

Shutdown: SIGINT/SIGTERM -> ``stopping`` -> intake closed (queryable undeclared, late
requests refused) -> bounded wait for an upload in progress (``GRACE_S``; an abandoned
upload is cancelled with MISSION_ACK CANCELLED and the autopilot keeps the complete mission
it held) -> tasks cancelled -> link, zenoh and journal closed (WAL checkpointed).
"""

from __future__ import annotations

import asyncio
import logging
import math
import signal
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from protocol import (Event, HoverPoint, PendingRequest, Plan, PlanPoint, State, Status, encode, encode_path,
                      global_to_local, validate_mission)
from protocol.errors import MissionError

from ..mcts import MctsConfig
from ..model import pack
from ..model.fairness import is_eligible
from ..model.reward import interval_reward
from .config import ServiceConfig
from .errors import JournalError, LinkError, PlanningError
from .intake import Accepted, Intake
from .journal import Journal
from .link import LinkEvent, LinkSettings, open_link
from .link.base import MISSION_MODES, RETURNING_MODES
from .planning import (PlannedPath, Planner, VehicleFix, assemble, check_path, not_served_reason, planning_battery_j,
                       should_return)
from .progress import HOLD_RADIUS_M, HeldMission, item_dict, item_from_dict
from .zenoh_io import ZenohIO, reply_and_drop

log = logging.getLogger("planner_service")

GRACE_S = 5.0
"""Bounded wait for an upload in progress at shutdown."""
RETRY_S = 1.0
"""Wait before re-trying a failed plan, upload or start."""
CONNECT_TIMEOUT_S = 10.0
UPLOAD_SLACK_S = 0.5
"""Wall time allowed for an upload and the messages around it, when judging whether the
vehicle may reach its point before a new mission does."""


@dataclass(frozen=True)
class PlanOutcome:
    """What one planning cycle did (for logs and the bench)."""

    plan_id: int
    points: int
    planner_ms: float
    upload_ms: float


class Service:
    def __init__(self, config: ServiceConfig, clock: Callable[[], float] = time.time) -> None:
        self.cfg = config
        self.clock = clock
        self.scenario = config.scenario()
        self.p = pack(self.scenario)
        self.area = config.area()
        self.origin = config.origin_point()
        self.keys = config.keys()
        self.flavour = config.mavlink.flavour
        self.journal = Journal(config.journal.path, config.journal.synchronous, now_s=clock())
        self.intake = Intake(self.journal, self.area, clock)
        budget = config.planner.budget_ms
        self.planner = Planner(self.scenario, MctsConfig(iterations=config.planner.iterations or None, budget_ms=budget),
                               config.planner.seed)
        self.zio = ZenohIO(config.zenoh, self.keys)
        m = config.mavlink
        self.link = open_link(m.backend, LinkSettings(m.url, m.flavour, m.item_timeout_s, m.retries, m.link_timeout_s,
                                                      m.source_system, m.source_component), self._on_link_event)
        self.executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="planner")
        self.stopping = asyncio.Event()
        self._wake = asyncio.Event()
        self._urgent = asyncio.Event()
        self._idle = asyncio.Event()
        self._idle.set()
        self._version = 0
        """Bumped whenever a service is recorded: a plan computed before it is stale."""
        self._last_plan_t = -math.inf
        self._rtl_sent_t = -math.inf
        self._planning = False
        self._reached_seq = -1
        self._tasks: list[asyncio.Task[Any]] = []
        self.held: HeldMission | None = None
        self.plan_msg: Plan | None = None
        sortie = self.journal.current_sortie()
        self.sortie_over: str | None = (sortie.why or "ended") if sortie.over else None
        """Why the current sortie ended; None while it runs (or waits for its first plan)."""
        if self.sortie_over:
            self.intake.closed_reason = self._closed_reason()
        self.started = False
        self.flown = False
        """The vehicle has been airborne during this sortie (so a landing ends it)."""
        services = self.journal.services()
        self.last_hover_index = services[-1].hover_index if services else -1
        last = self.journal.last_mission()
        self.plan_id = self.journal.last_plan_id()
        if last is not None:
            self._restore_held(last.plan_id, last.items, last.points)

    # --- lifecycle ----------------------------------------------------------------------------
    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                loop.add_signal_handler(sig, self.stopping.set)
            except (NotImplementedError, RuntimeError):  # not the main thread (tests)
                pass
        self.zio.open(loop, self._on_request, self._on_state)
        log.info("zenoh %s session on %s (connect %s); keys %s/**", self.cfg.zenoh.mode, list(self.cfg.zenoh.listen),
                 list(self.cfg.zenoh.connect), f"{self.keys.prefix}/{self.keys.vehicle}")
        self._tasks = [
            asyncio.create_task(self._connect_loop(), name="connect"),
            asyncio.create_task(self._status_loop(), name="status"),
            asyncio.create_task(self._planning_loop(), name="planning"),
            asyncio.create_task(self._warm_up(), name="warm-up"),
        ]
        log.info("ready: sortie %d (%s): %d pending requests, %d services in the journal %s", self.journal.sortie,
                 f"over: {self.sortie_over}" if self.sortie_over else "running", len(self.journal.pending()),
                 len(self.journal.services()), self.cfg.journal.path)
        await self.stopping.wait()
        await self._shutdown()
        return 0

    async def _shutdown(self) -> None:
        log.info("stopping: intake closed")
        self.intake.closed_reason = "the service is shutting down"
        self.zio.stop_intake()
        try:
            await asyncio.wait_for(self._idle.wait(), GRACE_S)
        except TimeoutError:
            log.warning("an upload was still running after %.0f s: abandoned (the vehicle keeps its mission)", GRACE_S)
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self.link.close()
        self.zio.close()
        self.executor.shutdown(wait=False, cancel_futures=True)
        self.journal.close()
        log.info("stopped: journal flushed")

    async def _warm_up(self) -> None:
        """Load the compiled kernels before the first request needs them."""
        from .journal import UserRow

        fix = VehicleFix(0.0, 0.0, 0.0, self.scenario.battery_j, False)
        warm = assemble(self.scenario, [UserRow("warm-up", 100.0, 100.0, 0.0, 0)], [], [], fix, -1)
        warm.state.tasks[0] = 10
        probe = Planner(self.scenario, MctsConfig(iterations=50), 0)
        await asyncio.get_running_loop().run_in_executor(self.executor, probe.decide, warm)

    async def _connect_loop(self) -> None:
        while True:
            try:
                await self.link.connect(CONNECT_TIMEOUT_S)
                return
            except LinkError as err:
                log.warning("waiting for the autopilot: %s", err)
                await self.link.close()
                m = self.cfg.mavlink
                self.link = open_link(m.backend, self.link.settings, self._on_link_event)

    # --- zenoh handlers (on the loop's thread) -------------------------------------------------
    def _on_request(self, query: Any) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else None
        outcome = self.intake.handle(payload)
        reply_and_drop(query, self.keys.request, encode(outcome.reply))
        if isinstance(outcome, Accepted):
            detail = f"{outcome.tasks} tasks" + (f"; replaces {list(outcome.replaced)}" if outcome.replaced else "")
            self._event("request_accepted", user_id=outcome.user_id, request_id=outcome.request_id, detail=detail)
            self._wake.set()
        else:
            self._event("request_rejected", detail=f"{outcome.reply.field}: {outcome.reply.message}"[:256])

    def _on_state(self, query: Any) -> None:
        pending = [PendingRequest(request_id=r.request_id, user_id=r.user_id, x_m=r.x_m, y_m=r.y_m, z_m=r.z_m,
                                  tasks=r.tasks) for r in self.journal.pending()]
        state = State(status=self._status(), plan=self.plan_msg, pending=pending)
        reply_and_drop(query, self.keys.state, encode(state))

    def _event(self, event: str, **fields: Any) -> None:
        self.zio.publish("events", encode(Event(event=event, time_s=self.clock(), **fields)))  # type: ignore[arg-type]

    # --- telemetry ---------------------------------------------------------------------------------
    def _fix(self) -> VehicleFix:
        t = self.link.telemetry
        x, y, z = global_to_local(self.origin, t.lat_deg, t.lon_deg, self.origin.alt_m + t.rel_alt_m)
        if t.energy_used_j is not None:
            battery = self.scenario.battery_j - t.energy_used_j
        else:
            battery = t.battery_fraction * self.scenario.battery_j
        return VehicleFix(x, y, z, battery, t.airborne)

    def _phase(self) -> str:
        t = self.link.telemetry
        if not t.connected:
            return "lost"
        if self.sortie_over:
            return "landed"
        if t.airborne and t.mode in RETURNING_MODES:
            return "returning"
        if t.airborne:
            return "flying"
        return "planning" if self._planning else "idle"

    def _status(self) -> Status:
        t = self.link.telemetry
        fix = self._fix() if t.valid else VehicleFix(0.0, 0.0, 0.0, 0.0, False)
        return Status(
            vehicle=self.keys.vehicle, time_s=self.clock(), phase=self._phase(), armed=t.armed, mode=t.mode[:256],
            x_m=fix.x_m, y_m=fix.y_m, z_m=fix.z_m, battery_fraction=min(max(t.battery_fraction, 0.0), 1.0),
            mission_seq=max(t.mission_seq, 0), mission_total=max(t.mission_total, 0),
            pending_requests=len(self.journal.pending()),
            served_users=len({s.user_id for s in self.journal.services()}),
        )

    async def _status_loop(self) -> None:
        period = 1.0 / self.cfg.zenoh.status_hz
        while True:
            if self.link.telemetry.airborne:
                self.flown = True
            self.zio.publish("status", encode(self._status()))
            self._maybe_begin_sortie()
            await self._safety_check()
            await asyncio.sleep(period)

    async def _safety_check(self) -> None:
        """Return to launch when the battery reaches the threshold (the planner should never
        let it: this is the guard if the model and the aircraft disagree)."""
        t = self.link.telemetry
        if not t.valid or not t.connected:
            return
        now = time.monotonic()
        if now - self._rtl_sent_t < 2.0:
            return
        if should_return(t.battery_fraction, t.airborne, t.mode in RETURNING_MODES, self.cfg.safety.rtl_battery_fraction):
            self._rtl_sent_t = now
            self._event("returning", detail=f"battery at {t.battery_fraction:.0%}: return to launch commanded")
            try:
                await self.link.return_to_launch()
            except LinkError as err:
                log.error("return to launch failed: %s", err)

    def _on_link_event(self, ev: LinkEvent) -> None:
        t = self.link.telemetry
        if ev.kind == "connected":
            log.info("autopilot connected (%s)", ev.text)
            if t.airborne:
                self.started = self.flown = True
            self._wake.set()
        elif ev.kind == "lost":
            self._event("link_lost", detail=ev.text)
        elif ev.kind == "restored":
            self._event("link_restored", detail=ev.text)
            self._urgent.set()
            self._wake.set()
        elif ev.kind == "reached":
            self._reached(ev.seq)
        elif ev.kind == "landed":
            if self.flown:
                self._end_sortie("the vehicle landed")
        elif ev.kind == "mode" and ev.text in RETURNING_MODES:
            self._event("returning", detail=f"mode {ev.text}")
        elif ev.kind == "text":
            log.info("autopilot: %s", ev.text)
        if t.airborne:
            self.flown = True

    def _reached(self, seq: int) -> None:
        held = self.held
        point = held.point_at(seq) if held is not None else None
        if point is None:
            return
        now = self.clock()
        self.last_hover_index = point.hover_index
        self._reached_seq = seq
        self._version += 1
        services = sum(1 for s in self.journal.services() if s.user_id == point.user_id)
        request = next((r for r in self.journal.pending() if r.user_id == point.user_id), None)
        xyz = (point.x_m, point.y_m, point.z_m)
        # The hold was sized for the planned request's tasks: a newer request of the same
        # user uploads at most that many in it.
        tasks = min(request.tasks, point.tasks) if request is not None else 0
        if request is None or not is_eligible(self.p, tasks, services):
            why = "no pending request" if request is None else f"not eligible with {tasks} tasks"
            self._event("waypoint_reached", user_id=point.user_id, detail=f"point {point.hover_index}: {why}")
        else:
            reward = point.reward if tasks == point.tasks else interval_reward(self.p, tasks, point.energy_j)
            try:
                self.journal.record_service(request.request_id, point.hover_index, xyz, tasks,
                                            tasks * self.scenario.bits_per_task, reward, self._fix().battery_j, now)
            except JournalError as err:
                log.error("could not record the service of request %d: %s", request.request_id, err)
            else:
                self._event("user_served", user_id=request.user_id, request_id=request.request_id,
                            detail=f"{tasks} tasks at point {point.hover_index}")
        self._urgent.set()
        self._wake.set()

    def _end_sortie(self, why: str) -> None:
        """Close the sortie: every pending request is reported not served, with its reason;
        the intake refuses requests until the next sortie begins (``_maybe_begin_sortie``)."""
        if self.sortie_over:
            return
        counts: dict[str, int] = {}
        for s in self.journal.services():
            counts[s.user_id] = counts.get(s.user_id, 0) + 1
        reasons = {r.request_id: not_served_reason(self.scenario, r.tasks, counts.get(r.user_id, 0),
                                                   f"sortie ended before its turn ({why})")
                   for r in self.journal.pending()}
        now = self.clock()
        self.journal.end_sortie(why, reasons, now)
        self._version += 1  # a plan still being searched belongs to the sortie that ended
        for rid, reason in reasons.items():
            self._event("request_rejected", request_id=rid, detail=f"not served: {reason}"[:256])
        self.sortie_over = why
        self.intake.closed_reason = self._closed_reason()
        self._event("landed", detail=f"sortie {self.journal.sortie}: {why}")
        log.info("sortie %d over: %s; %d services, %d requests not served", self.journal.sortie, why,
                 len(self.journal.services()), len(reasons))

    def _closed_reason(self) -> str:
        """What a request hears between sorties."""
        if not self.cfg.sortie.repeat:
            return f"sortie over: {self.sortie_over}; this service flies one sortie (sortie.repeat = false)"
        return (f"sortie over: waiting for the battery (at least {self.cfg.sortie.next_battery_fraction:.0%}) "
                f"with the vehicle on the ground and disarmed before sortie {self.journal.sortie + 1}")

    def _maybe_begin_sortie(self) -> None:
        """Begin the next sortie once the last one is over and the vehicle is ready to fly
        again: on the ground, disarmed, its battery swapped or charged."""
        t = self.link.telemetry
        if not self.sortie_over or not self.cfg.sortie.repeat or self.stopping.is_set():
            return
        if not (t.valid and t.connected) or t.airborne or t.armed:
            return
        if t.battery_fraction < self.cfg.sortie.next_battery_fraction:
            return
        self._begin_sortie(t.battery_fraction)

    def _begin_sortie(self, battery_fraction: float) -> None:
        """A fresh sortie: nothing held, nothing planned, started at the base, fairness
        counts from zero (the journal's queries read the new sortie), intake open."""
        try:
            number = self.journal.begin_sortie(self.clock())
        except JournalError as err:
            log.error("could not begin the next sortie: %s", err)
            return
        self.sortie_over = None
        self.held = None
        self.plan_msg = None
        self.last_hover_index = -1
        self._reached_seq = -1
        self.started = self.flown = False
        self._version += 1
        self._last_plan_t = -math.inf
        self.planner.new_sortie()
        self.intake.closed_reason = None
        self._event("sortie_started", detail=f"sortie {number}: battery at {battery_fraction:.0%}")
        log.info("sortie %d begins: battery at %.0f%%", number, 100 * battery_fraction)
        self._wake.set()

    # --- planning ------------------------------------------------------------------------------------
    async def _planning_loop(self) -> None:
        while True:
            await self._wake.wait()
            self._wake.clear()
            if not self._urgent.is_set():
                wait = self._last_plan_t + self.cfg.planner.replan_min_interval_s - time.monotonic()
                if wait > 0:
                    try:
                        await asyncio.wait_for(self._urgent.wait(), wait)
                    except TimeoutError:
                        pass
            self._urgent.clear()
            if self.stopping.is_set():
                return
            try:
                await self._plan_once()
            except (PlanningError, MissionError, LinkError) as err:
                log.error("plan %d not flown: %s", self.plan_id, err)
                self._event("upload_failed", detail=str(err)[:256])
                asyncio.get_running_loop().call_later(RETRY_S, self._wake.set)

    def _ready_to_plan(self) -> bool:
        t = self.link.telemetry
        if self.sortie_over:
            return False
        if not t.connected or not t.valid:  # no vehicle yet: look again soon
            asyncio.get_running_loop().call_later(RETRY_S / 2, self._wake.set)
            return False
        if t.airborne and t.mode in RETURNING_MODES:
            return False  # returning: the safety or the operator decided; no more plans
        if self._busy_at_point():
            return False  # a user is uploading: the re-plan waits for the waypoint's end
        return self.flown or len(self.journal.pending()) >= self.cfg.planner.min_requests

    async def _plan_once(self) -> PlanOutcome | None:
        if not self._ready_to_plan():
            return None
        self._idle.clear()
        self._planning = True
        try:
            return await self._plan_and_upload()
        finally:
            self._planning = False
            self._idle.set()

    def _busy_at_point(self) -> bool:
        """Could a mission uploaded now find the vehicle holding over its current point?
        Replacing the mission there would cut that user's upload short, so the re-plan
        waits for the waypoint's end. The vehicle's position is as old as its last report
        and the plan takes the planner's budget: both in vehicle time (``time_rate``)."""
        t = self.link.telemetry
        if not (t.airborne and self.held is not None and t.mode in MISSION_MODES):
            return False
        if t.mission_seq <= self._reached_seq:  # that waypoint is done; MISSION_CURRENT lags
            return False
        point = self.held.point_at(t.mission_seq)
        if point is None:
            return False
        fix = self._fix()
        age_s = max(time.monotonic() - t.position_at, 0.0) + self.cfg.planner.budget_ms / 1e3 + UPLOAD_SLACK_S
        reach_m = self.scenario.speed_mps * t.time_rate * age_s + HOLD_RADIUS_M
        return math.dist((fix.x_m, fix.y_m, fix.z_m), (point.x_m, point.y_m, point.z_m)) <= reach_m

    def _planning_fix(self) -> VehicleFix:
        """The vehicle as the planner should see it: a conservative battery."""
        fix = self._fix()
        t = self.link.telemetry
        stale_wall = max(time.monotonic() - t.battery_at, 0.0) if t.battery_at else 0.0
        stale_vehicle = t.time_rate * (stale_wall + self.cfg.planner.budget_ms / 1e3 + 0.2)
        battery = planning_battery_j(self.scenario, fix.battery_j, stale_vehicle, self.cfg.safety.energy_margin_j)
        return replace(fix, battery_j=battery)

    async def _plan_and_upload(self) -> PlanOutcome | None:
        version = self._version
        fix = self._planning_fix()
        assembled = assemble(self.scenario, self.journal.users(), self.journal.pending(), self.journal.services(),
                             fix, self.last_hover_index)
        t0 = time.perf_counter()
        decision, path = await asyncio.get_running_loop().run_in_executor(self.executor, self.planner.decide, assembled)
        planner_ms = (time.perf_counter() - t0) * 1e3
        self._last_plan_t = time.monotonic()
        if self.stopping.is_set():
            return None
        if version != self._version:  # a service was recorded meanwhile: plan again from it
            self._urgent.set()
            self._wake.set()
            return None
        if self._busy_at_point():  # arrived while searching: the plan waits for the waypoint's end
            return None
        if not path.points and not (fix.airborne and self.held is not None and self.held.points):
            return None  # nothing to fly and nothing held to cancel
        check_path(path, self.area, self.scenario, fix.battery_j)
        items = encode_path([HoverPoint(p.x_m, p.y_m, p.z_m, p.hold_s) for p in path.points], self.origin,
                            self.flavour)  # type: ignore[arg-type]
        validate_mission(items, self.origin, self.area, self.flavour)  # type: ignore[arg-type]
        plan_id = self.plan_id + 1
        t1 = time.perf_counter()
        try:
            await self.link.upload(items)
        except LinkError as err:
            self.journal.record_mission(plan_id, [item_dict(i) for i in items], _points(path), f"failed: {err.result}",
                                        self.clock())
            self.plan_id = plan_id
            raise
        upload_ms = (time.perf_counter() - t1) * 1e3
        self.plan_id = plan_id
        self.journal.record_mission(plan_id, [item_dict(i) for i in items], _points(path), "accepted", self.clock())
        self.held = HeldMission.build(plan_id, items, path.points, self.flavour)
        self._reached_seq = -1
        self.plan_msg = Plan(plan_id=plan_id, time_s=self.clock(), predicted_energy_j=max(path.predicted_energy_j, 0.0),
                             points=[PlanPoint(p.x_m, p.y_m, p.z_m, p.hold_s, p.user_id) for p in path.points])
        self.zio.publish("plan", encode(self.plan_msg))
        newest = max((r.request_id for r in self.journal.pending()), default=0)
        self._event("mission_uploaded", detail=(
            f"plan {plan_id}: {len(path.points)} points; planner_ms={planner_ms:.1f} upload_ms={upload_ms:.1f} "
            f"newest_request={newest}; ends: {path.stop_reason}"))
        log.info("plan %d: %s (%d items, planner %.0f ms, upload %.0f ms; %s)", plan_id,
                 [p.hover_index for p in path.points], len(items), planner_ms, upload_ms, path.stop_reason)
        if not path.points:
            self._event("returning", detail=f"nothing more to serve ({path.stop_reason}): return to launch")
        await self._maybe_start()
        return PlanOutcome(plan_id, len(path.points), planner_ms, upload_ms)

    async def _maybe_start(self) -> None:
        t = self.link.telemetry
        if self.started or not self.cfg.mavlink.start_mission or t.airborne or self.held is None or not self.held.points:
            return
        try:
            await self.link.start()
        except LinkError as err:
            log.warning("the autopilot did not start the mission (%s); trying again", err)
            asyncio.get_running_loop().call_later(RETRY_S * 2, self._wake.set)
            return
        self.started = True
        log.info("mission started")

    def _restore_held(self, plan_id: int, items: list[dict[str, Any]], points: list[dict[str, Any]]) -> None:
        from .planning import PlannedPoint

        self.held = HeldMission.build(plan_id, [item_from_dict(i) for i in items],
                                      tuple(PlannedPoint(**p) for p in points), self.flavour)


def _points(path: PlannedPath) -> list[dict[str, Any]]:
    return [dict(p.__dict__) for p in path.points]


def run_service(config: ServiceConfig) -> int:
    """Run the service until SIGINT or SIGTERM; returns the exit status."""
    np.seterr(all="ignore")  # the kernels handle their own infinities
    service = Service(config)
    return asyncio.run(service.run())
