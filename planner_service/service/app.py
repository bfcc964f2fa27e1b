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
                      global_to_local, same_mission, validate_mission)
from protocol.errors import MissionError
from protocol.mission import max_points

from ..mcts import MctsConfig
from ..model import pack
from ..model.fairness import is_eligible
from ..model.reward import interval_reward
from .config import ServiceConfig
from .errors import JournalError, LinkError, PlanningError
from .intake import Accepted, Intake
from .journal import Journal
from .link import LinkEvent, LinkSettings, open_link
from .link.base import HOLDING_MODES, MISSION_MODES, RETURNING_MODES
from .planning import (PlannedPath, Planner, VehicleFix, assemble, check_path, not_served_reason, planning_battery_j,
                       should_return)
from .progress import HOLD_RADIUS_M, HeldMission, item_dict, item_from_dict
from .throttle import RateLimit
from .zenoh_io import ZenohIO, reply_and_drop

log = logging.getLogger("planner_service")

GRACE_S = 5.0
"""Bounded wait for an upload in progress at shutdown."""
RETRY_S = 1.0
"""Wait before re-trying a failed plan, upload or start."""
CONNECT_TIMEOUT_S = 10.0
FLOWN_KEY = "flown_sortie"
"""Journal meta key: the number of the last sortie in which the vehicle was airborne."""
REFUSAL_EVENTS_PER_S = 5.0
"""At most this many ``request_rejected`` events a second for refused requests (a flood of
bad requests must not become a flood of events); the rest are counted in the next one."""
BUSY_LOG_EVERY_S = 10.0
"""Period of the warning that counts queries answered busy."""
UPLOAD_SLACK_S = 0.5
"""Wall time allowed for an upload and the messages around it, when judging whether the
vehicle may reach its point before a new mission does (at least; more when uploads have
been taking longer: see ``_upload_s``)."""
UPLOAD_HISTORY = 5
"""Uploads whose wall time is remembered: the longest of them is expected of the next."""
PROGRESS_WAIT_S = 2.0
"""After the vehicle's mission was read back, wait this long at most for its MISSION_CURRENT
(streamed at 2 Hz) before planning, so that points flown meanwhile are recorded first."""


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
        self.intake = Intake(self.journal, self.area, clock, config.intake)
        self._refusal_events = RateLimit(REFUSAL_EVENTS_PER_S, time.monotonic())
        self._refusals_unreported = 0
        self._busy_logged = (time.monotonic(), 0)
        budget = config.planner.budget_ms
        self.planner = Planner(self.scenario, MctsConfig(iterations=config.planner.iterations or None, budget_ms=budget),
                               config.planner.seed, max_points(config.mavlink.max_mission_items, self.flavour),
                               config.planner.algo)
        self.zio = ZenohIO(config.zenoh, self.keys)
        m = config.mavlink
        self.link = open_link(m.backend, LinkSettings(m.url, m.flavour, m.item_timeout_s, m.retries, m.link_timeout_s,
                                                      m.source_system, m.source_component,
                                                      signing_key_file=m.signing_key_file,
                                                      signing_timestamp_file=m.signing_timestamp_file),
                              self._on_link_event)
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
        self._tasks: list[asyncio.Task[Any]] = []
        self.held: HeldMission | None = None
        """The mission the vehicle holds, as far as the service knows."""
        self._held_gen: int | None = None
        """The link generation ``held`` is known to match (``LinkEvent.mission``); None while
        in doubt: progress reports are then ignored until a download settles it."""
        self._counted: set[int] = set()
        """Item seqs of ``held``'s points already recorded (served, or reached and judged)."""
        self._previous: tuple[HeldMission, int, set[int]] | None = None
        """The mission the last upload replaced, its generation and its points counted: a
        point it completed just before the new mission was accepted is still recorded."""
        self._doubt_reason: str | None = None
        """Why the vehicle may hold another mission than ``held``: read it back before planning."""
        self._unconfirmed: HeldMission | None = None
        """An upload whose last item went out but whose ACK never came, nor a read-back."""
        self._must_upload = False
        """The vehicle's mission is gone: upload even a plan of no points (return to launch)."""
        self._resume_pending = False
        """The vehicle lost its mission in the air: resume (or ask the operator) after the upload."""
        self._vehicle_restarted = False
        """The vehicle restarted since the mission was last read back: it came back holding."""
        self._progress_after = 0.0
        self._progress_seen = True
        self._upload_times_s: list[float] = []
        """Wall time of the last accepted uploads (a lossy link makes them seconds long)."""
        self.plan_msg: Plan | None = None
        sortie = self.journal.current_sortie()
        self.sortie_over: str | None = (sortie.why or "ended") if sortie.over else None
        """Why the current sortie ended; None while it runs (or waits for its first plan)."""
        if self.sortie_over:
            self.intake.closed_reason = self._closed_reason()
        self.started = False
        self.flown = self.journal.get_meta(FLOWN_KEY) == str(sortie.number)
        """The vehicle has been airborne during this sortie (so a landing ends it); kept in
        the journal, so that a landing while the service was down still ends the sortie."""
        services = self.journal.services()
        self.last_hover_index = services[-1].hover_index if services else -1
        last = self.journal.last_mission()
        self.plan_id = self.journal.last_plan_id()
        if last is not None:
            self._restore_held(last.plan_id, last.items, last.points)
            assert self.held is not None
            self._counted = self.held.counted_from(last.time_s, [(s.user_id, s.time_s) for s in services])

    # --- lifecycle ----------------------------------------------------------------------------
    async def run(self) -> int:
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                loop.add_signal_handler(sig, self.stopping.set)
            except (NotImplementedError, RuntimeError):  # not the main thread (tests)
                pass
        self._tasks = [
            asyncio.create_task(self._connect_loop(), name="connect"),
            asyncio.create_task(self._status_loop(), name="status"),
            asyncio.create_task(self._planning_loop(), name="planning"),
            asyncio.create_task(self._warm_up(), name="warm-up"),
        ]
        z = self.cfg.zenoh
        try:
            opened = await self.zio.open(loop, self._on_request, self._on_state, self.stopping)
        except BaseException:
            for task in self._tasks:
                task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)
            await self.link.close()
            self.journal.close()
            raise
        if opened:
            log.info("zenoh %s session on %s (connect %s%s); keys %s/**", z.mode, list(z.listen), list(z.connect),
                     f"; base {z.config_file}" if z.config_file else "", f"{self.keys.prefix}/{self.keys.vehicle}")
            log.info("ready: sortie %d (%s): %d pending requests, %d services in the journal %s",
                     self.journal.sortie, f"over: {self.sortie_over}" if self.sortie_over else "running",
                     len(self.journal.pending()), len(self.journal.services()), self.cfg.journal.path)
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
        """Compile every kernel the planner uses before the first request needs them."""
        await asyncio.get_running_loop().run_in_executor(self.executor, self.planner.warm_up)

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
        elif self._refusal_events.take(time.monotonic()):
            unreported = f"[{self._refusals_unreported} more refused, not reported] " if self._refusals_unreported else ""
            self._refusals_unreported = 0
            self._event("request_rejected", detail=f"{unreported}{outcome.reply.field}: {outcome.reply.message}"[:256])
        else:
            self._refusals_unreported += 1

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
                self._mark_flown()
            self._landed_unseen()
            self.zio.publish("status", encode(self._status()))
            self._maybe_begin_sortie()
            self._log_busy()
            await self._safety_check()
            await asyncio.sleep(period)

    def _log_busy(self) -> None:
        """Say how many queries were answered busy (they never reach the loop otherwise)."""
        since, seen = self._busy_logged
        now, refused = time.monotonic(), self.zio.in_flight.refused
        if refused > seen and now - since >= BUSY_LOG_EVERY_S:
            log.warning("%d queries answered busy in the last %.0f s (zenoh.max_queries_in_flight = %d)",
                        refused - seen, now - since, self.zio.in_flight.limit)
            self._busy_logged = (now, refused)
        elif refused == seen:
            self._busy_logged = (now, refused)

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
                self.started = True
                self._mark_flown()
            if self.held is not None:  # from the journal: does the vehicle still fly it?
                self._doubt(f"the service started with plan {self.held.plan_id} in its journal")
            self._wake.set()
        elif ev.kind == "lost":
            self._event("link_lost", detail=ev.text)
        elif ev.kind == "restored":
            self._event("link_restored", detail=ev.text)
            if self.held is not None or self.flown:
                self._doubt("the link was lost")  # a radio gap, or the vehicle restarted
            self._urgent.set()
            self._wake.set()
        elif ev.kind == "restarted":
            self._vehicle_restarted = True
            self._event("vehicle_restarted", detail=ev.text[:256])
            self._doubt(f"the vehicle restarted: {ev.text}")
        elif ev.kind == "reached":
            self._progress(ev.seq, ev.mission, including=True)
        elif ev.kind == "current":
            self._on_current(ev)
        elif ev.kind == "landed":
            if self.flown:
                self._end_sortie("the vehicle landed")
        elif ev.kind == "mode" and ev.text in RETURNING_MODES:
            self._event("returning", detail=f"mode {ev.text}")
        elif ev.kind == "text":
            log.info("autopilot: %s", ev.text)
        if t.airborne:
            self._mark_flown()

    def _mark_flown(self) -> None:
        if self.flown or self.sortie_over:
            return
        self.flown = True
        try:
            self.journal.set_meta(FLOWN_KEY, str(self.journal.current_sortie().number))
        except JournalError as err:
            log.error("could not note that the sortie has flown: %s", err)

    def _landed_unseen(self) -> None:
        """A sortie that has flown ends when the vehicle is found on the ground, disarmed,
        even if its landing was never seen (it landed while the service was down or the
        link was out): otherwise the next plan would fly a second sortie in this one."""
        t = self.link.telemetry
        if self.flown and not self.sortie_over and t.connected and t.landed_known and not (t.airborne or t.armed):
            self._end_sortie("the vehicle was found landed")

    def _doubt(self, why: str) -> None:
        """The vehicle may no longer hold ``held``: ignore its progress reports until the
        mission is read back (before the next plan)."""
        log.warning("%s: the mission held will be read back before planning", why)
        self._doubt_reason = why
        self._held_gen, self._previous = None, None
        self._urgent.set()
        self._wake.set()

    def _on_current(self, ev: LinkEvent) -> None:
        held = self.held
        if self._previous is not None and ev.mission == self._previous[1]:
            self._progress(ev.seq, ev.mission, including=False)
            return
        if held is None or ev.mission != self._held_gen:
            return
        self._progress_seen = True
        # MISSION_CURRENT.total leaves ArduPilot's home out by the spec (the stub counts it);
        # 0: the vehicle has no mission, -1: it does not say. Else a mission we did not upload.
        n = len(held.items)
        if ev.total >= 0 and ev.total not in (n, n - 1 if self.flavour == "ardupilot" else n):
            self._doubt(f"the vehicle reports a mission of {ev.total} items, not the {n} of plan {held.plan_id}")
            return
        self._progress(ev.seq, ev.mission, including=False)

    def _progress(self, seq: int, mission: int, *, including: bool) -> None:
        """The vehicle flies item ``seq`` (or completed it): record every point before it
        (and it) not yet recorded. MISSION_ITEM_REACHED is sent once and may be lost; the
        streamed MISSION_CURRENT catches up, also after a link gap or a restart of ours."""
        if self.held is not None and mission == self._held_gen:
            held, counted = self.held, self._counted
        elif self._previous is not None and mission == self._previous[1]:
            held, _, counted = self._previous
        else:
            return  # about another mission, or in doubt
        for done in held.points_done(seq, counted, including=including):
            self._reached(held, counted, done)

    def _reached(self, held: HeldMission, counted: set[int], seq: int) -> None:
        point = held.point_at(seq)
        if point is None or seq in counted:
            return
        counted.add(seq)
        now = self.clock()
        if held is self.held or not self._counted:  # a late report of the mission before is not where it is now
            self.last_hover_index = point.hover_index
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
        # the last sortie's mission and what was judged of it (a doubt is about that mission)
        self.held, self._held_gen, self._counted, self._unconfirmed = None, None, set(), None
        self._previous = None  # a late report of the last sortie's mission must not count in this one
        self._doubt_reason, self._must_upload, self._resume_pending = None, False, False
        self._progress_seen, self._progress_after = True, 0.0
        self.plan_msg = None
        self.last_hover_index = -1
        self.started = self.flown = False
        self._version += 1
        self._last_plan_t = -math.inf
        self.planner.new_sortie()
        self.intake.new_sortie()
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
        if self.flown and not t.landed_known:  # in the air or landed meanwhile? know first
            asyncio.get_running_loop().call_later(RETRY_S / 2, self._wake.set)
            return False
        self._landed_unseen()
        if self.sortie_over:
            return False
        if not self._progress_seen and time.monotonic() < self._progress_after:
            # The mission was just read back: its MISSION_CURRENT first, so that points
            # flown meanwhile are recorded before the planner counts its users.
            asyncio.get_running_loop().call_later(0.2, self._wake.set)
            return False
        if t.airborne and t.mode in RETURNING_MODES:
            return False  # returning: the safety or the operator decided; no more plans
        if self._busy_at_point():
            return False  # a user is uploading: the re-plan waits for the waypoint's end
        return self.flown or len(self.journal.pending()) >= self.cfg.planner.min_requests

    async def _plan_once(self) -> PlanOutcome | None:
        if self.sortie_over:
            return None
        self._idle.clear()
        try:
            if self._doubt_reason is not None and not await self._settle():
                return None
            if not self._ready_to_plan():
                return None
            self._planning = True
            return await self._plan_and_upload()
        finally:
            self._planning = False
            self._idle.set()

    async def _settle(self) -> bool:
        """Read back the mission the vehicle holds and take it as ``held`` if it is ours
        (the last accepted, or an upload whose ACK was lost); otherwise the vehicle's
        mission is gone or stale (it restarted): plan again and upload, whatever the plan."""
        why = self._doubt_reason
        t = self.link.telemetry
        if not t.connected:
            asyncio.get_running_loop().call_later(RETRY_S, self._wake.set)
            return False
        try:
            items = await self.link.download()
        except LinkError as err:
            log.warning("could not read back the vehicle's mission (%s): %s; trying again", why, err)
            asyncio.get_running_loop().call_later(RETRY_S, self._wake.set)
            return False
        if self._doubt_reason != why:
            return False  # another doubt arose meanwhile: read again
        self._doubt_reason = None
        for candidate in (self.held, self._unconfirmed):
            if candidate is None or not same_mission(items, candidate.items, self.flavour):  # type: ignore[arg-type]
                continue
            if candidate is not self.held:  # the upload whose ACK was lost went through
                self.held, self._counted = candidate, set()
                self.journal.record_mission(candidate.plan_id, [item_dict(i) for i in candidate.items],
                                            [dict(p.__dict__) for p in candidate.points], "accepted", self.clock())
                self._publish_plan(candidate)
            self._held_gen, self._unconfirmed = self.link.generation, None
            self._progress_seen, self._progress_after = False, time.monotonic() + PROGRESS_WAIT_S
            # A restarted vehicle may hold our mission (uploaded to it before its restart
            # showed) and still hover where it came back: it needs resuming all the same.
            self._resume_pending = self._vehicle_restarted and t.airborne
            self._vehicle_restarted = False
            log.info("%s: the vehicle holds plan %d (read back)", why, candidate.plan_id)
            return True
        lost = self.held
        self.held, self._held_gen, self._counted, self._unconfirmed = None, None, set(), None
        self._must_upload = t.airborne
        self._resume_pending = t.airborne
        self._vehicle_restarted = False
        ours = f"plan {lost.plan_id}" if lost is not None else "a mission of ours"
        detail = f"{why}: the vehicle holds {len(items)} items, not {ours}; re-planning from where it is"
        log.warning("%s", detail)
        if not why or "restarted" not in why:
            self._event("vehicle_restarted", detail=detail[:256])
        return True

    def _busy_at_point(self) -> bool:
        """Could a mission uploaded now find the vehicle holding over its current point?
        Replacing the mission there would cut that user's upload short, so the re-plan
        waits for the waypoint's end. The vehicle's position is as old as its last report
        and the plan takes the planner's budget: both in vehicle time (``time_rate``)."""
        t = self.link.telemetry
        if not (t.airborne and self.held is not None and t.mode in MISSION_MODES):
            return False
        if self._held_gen is None or t.mission_seq in self._counted:  # in doubt, or done (MISSION_CURRENT lags)
            return False
        point = self.held.point_at(t.mission_seq)
        if point is None:
            return False
        fix = self._fix()
        age_s = max(time.monotonic() - t.position_at, 0.0) + self.cfg.planner.budget_ms / 1e3 + self._upload_s()
        reach_m = self.scenario.speed_mps * t.time_rate * age_s + HOLD_RADIUS_M
        return math.dist((fix.x_m, fix.y_m, fix.z_m), (point.x_m, point.y_m, point.z_m)) <= reach_m

    def _upload_s(self) -> float:
        """Wall time the next upload may take: the longest of the last few (seconds on a
        lossy link, where each lost message waits ``item_timeout_s``), at least
        ``UPLOAD_SLACK_S``. The vehicle flies the old mission meanwhile."""
        return max([UPLOAD_SLACK_S, *self._upload_times_s])

    def _planning_fix(self) -> VehicleFix:
        """The vehicle as the planner should see it: a conservative battery, less what it
        spends until the plan is flown (the reading's age, the search, the upload)."""
        fix = self._fix()
        t = self.link.telemetry
        stale_wall = max(time.monotonic() - t.battery_at, 0.0) if t.battery_at else 0.0
        stale_vehicle = t.time_rate * (stale_wall + self.cfg.planner.budget_ms / 1e3 + self._upload_s())
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
        if self.stopping.is_set() or self.sortie_over or self._doubt_reason is not None:
            self._wake.set()  # the doubt is settled first; a landing or shutdown ends it all
            return None
        if version != self._version:  # a service was recorded meanwhile: plan again from it
            self._urgent.set()
            self._wake.set()
            return None
        if self._busy_at_point():  # arrived while searching: the plan waits for the waypoint's end
            return None
        if not path.points and not (fix.airborne and (self._must_upload or (self.held is not None and self.held.points))):
            return None  # nothing to fly and nothing held to cancel
        check_path(path, self.area, self.scenario, fix.battery_j)
        items = encode_path([HoverPoint(p.x_m, p.y_m, p.z_m, p.hold_s) for p in path.points], self.origin,
                            self.flavour)  # type: ignore[arg-type]
        validate_mission(items, self.origin, self.area, self.flavour,  # type: ignore[arg-type]
                         max_items=self.cfg.mavlink.max_mission_items)
        plan_id = self.plan_id + 1
        t1 = time.perf_counter()
        try:
            await self.link.upload(items)
        except LinkError as err:
            outcome = "unknown" if err.outcome_unknown else "failed"
            self.journal.record_mission(plan_id, [item_dict(i) for i in items], _points(path), f"{outcome}: {err.result}",
                                        self.clock())
            self.plan_id = plan_id
            if err.outcome_unknown:  # the vehicle may hold it: find out before anything else
                self._unconfirmed = HeldMission.build(plan_id, items, path.points, self.flavour)
                self._doubt(f"the outcome of plan {plan_id}'s upload is unknown")
            raise
        upload_ms = (time.perf_counter() - t1) * 1e3
        self._upload_times_s = [*self._upload_times_s, upload_ms / 1e3][-UPLOAD_HISTORY:]
        self.plan_id = plan_id
        self.journal.record_mission(plan_id, [item_dict(i) for i in items], _points(path), "accepted", self.clock())
        if self.held is not None and self._held_gen is not None:
            self._previous = (self.held, self._held_gen, self._counted)
        self.held = HeldMission.build(plan_id, items, path.points, self.flavour)
        self._held_gen, self._counted, self._unconfirmed, self._must_upload = self.link.generation, set(), None, False
        # Reports that came between the ACK and now (the vehicle restarts the mission).
        self._progress(self.link.telemetry.mission_seq, self._held_gen, including=False)
        self._publish_plan(self.held, path.predicted_energy_j)
        newest = max((r.request_id for r in self.journal.pending()), default=0)
        self._event("mission_uploaded", detail=(
            f"plan {plan_id}: {len(path.points)} points; planner_ms={planner_ms:.1f} upload_ms={upload_ms:.1f} "
            f"newest_request={newest}; ends: {path.stop_reason}"))
        log.info("plan %d: %s (%d items, planner %.0f ms, upload %.0f ms; %s)", plan_id,
                 [p.hover_index for p in path.points], len(items), planner_ms, upload_ms, path.stop_reason)
        if not path.points:
            self._event("returning", detail=f"nothing more to serve ({path.stop_reason}): return to launch")
        await self._maybe_start()
        await self._maybe_resume()
        return PlanOutcome(plan_id, len(path.points), planner_ms, upload_ms)

    def _publish_plan(self, held: HeldMission, predicted_energy_j: float = 0.0) -> None:
        self.plan_msg = Plan(plan_id=held.plan_id, time_s=self.clock(), predicted_energy_j=max(predicted_energy_j, 0.0),
                             points=[PlanPoint(p.x_m, p.y_m, p.z_m, p.hold_s, p.user_id) for p in held.points])
        self.zio.publish("plan", encode(self.plan_msg))

    async def _maybe_resume(self) -> None:
        """After the vehicle lost its mission in the air (a restart: it holds position), fly
        the new one: if the service started the mission (``start_mission``), it resumes it;
        otherwise it says the operator must (it never takes control it was not given)."""
        t = self.link.telemetry
        if not self._resume_pending or self.held is None:
            return
        if not t.airborne or t.mode not in HOLDING_MODES:
            self._resume_pending = False  # flying it already, going home, or in the operator's hands
            return
        if not (self.cfg.mavlink.start_mission and self.started):
            self._resume_pending = False
            self._event("resume_needed", detail=(f"plan {self.held.plan_id} uploaded; the vehicle holds position in "
                                                 f"{t.mode}: the operator must switch to AUTO to resume")[:256])
            return
        try:
            await self.link.resume()
        except LinkError as err:
            log.warning("the autopilot did not resume the mission (%s); trying again", err)
            asyncio.get_running_loop().call_later(RETRY_S, lambda: asyncio.ensure_future(self._maybe_resume()))
            return
        self._resume_pending = False
        self._event("mission_resumed", detail=f"plan {self.held.plan_id} from its start (was {t.mode})")
        log.info("mission resumed after the vehicle lost its mission (plan %d)", self.held.plan_id)

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
