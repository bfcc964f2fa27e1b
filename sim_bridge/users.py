"""Simulated ground users: each walks by random waypoint over the service area and keeps a
backlog of tasks that it asks the service to take (simulated seconds; ``speedup`` simulated
seconds pass per wall second, as in the vehicle stub).

Start positions are the scenario's user layout (the paper's two rows). Tasks follow one of
two laws (``TaskParams.law``), both the model's (one physics with the planner's futures):

- ``backlog`` (default; the model's ``task_model = "backlog"``): a user's first backlog is
  the paper's draw (``draw_tasks``: N(mean, phi^2), rounded, clipped to [0, u_max]); every
  interval after it, new tasks arrive (``draw_arrivals``: Poisson of the scenario's
  ``task_arrival_mean``), added to the backlog, capped at ``backlog_max``; what the service
  serves is taken off.
  The user sends its whole backlog and position, with what it knows was served
  (``served_seen`` and its ``sortie``: the service takes off what it served since, so a
  request that crosses a service on the wire asks for nothing already served), when the
  service's count of it differs from its own (new tasks, a service it learnt of), when it
  has moved ``resend_m`` since its last request, and at least once an interval while it
  has tasks; a backlog of 0 is sent only to end a wait the service still counts ("nothing
  more to offload").
- ``redraw`` (the paper's experiments): a draw (``draw_tasks``) replaces the task count
  every interval and is sent then, whatever was served (without ``served_seen``: the draw
  is taken as it is).

A user learns what was served from its ack (``served_tasks`` in its ``sortie``) and from its
``user_place`` publication (which also says the service's count of its backlog); counts are
per sortie. Until its first news it knows of no service and sends no ``served_seen``. The
walk and the task law are pure (functions of a ``Walker``, the time and an explicit
generator); ``run_users`` adds the clock and the zenoh client. Each user walks and draws its
tasks from generators of its own (``user_streams``), so that one seed gives the same users
to any two sorties, whatever the wall clock and the planner did (``advance_users``).
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from planner_service.model import Scenario, pack, user_rows
from planner_service.model.mobility import draw_arrivals, draw_tasks
from protocol import FleetKeys, ProtocolError, TaskAck, TaskRequest, UserPlace, printable
from protocol.fleet_signing import Unverified, unverified_body
from protocol.messages import FleetServed, decode
from protocol.client import ClientError, PlannerClient, request_for

log = logging.getLogger("sim_bridge.users")
ONE_SORTIE = "flies one sortie"
"""In the service's refusal after the landing when it is configured for one sortie only."""
TICK_S = 0.05
"""Wall seconds between two looks at every user."""

Law = Literal["backlog", "redraw"]
LAWS: tuple[Law, ...] = ("backlog", "redraw")


@dataclass(frozen=True)
class WalkParams:
    """A random-waypoint walk over [0, ``side_m``]^2: each leg at a speed drawn in
    [``speed_min_mps``, ``speed_max_mps``], a pause of up to ``pause_max_s`` at each
    waypoint (``model_pace`` gives the speeds of the model's users)."""

    side_m: float
    speed_min_mps: float = 0.5
    speed_max_mps: float = 2.0
    pause_max_s: float = 20.0


def model_move_m(scenario: Scenario) -> float:
    """How far the model moves a user in an interval, on average over its draws (in the
    plane): each axis uniform in [-epsilon, epsilon] (``user_move_range_m``), in whole
    metres where ``user_move_integer`` (8.0 m for 10 m), else continuous (7.7 m)."""
    reach = scenario.user_move_range_m
    if scenario.user_move_integer:
        r = np.arange(-int(reach), int(reach) + 1, dtype=np.float64)
        return float(np.hypot(*np.meshgrid(r, r)).mean())
    return reach * (math.sqrt(2.0) + math.asinh(1.0)) / 3.0  # the mean length in the square [-1, 1]^2


def model_pace(scenario: Scenario, interval_s: float) -> tuple[float, float]:
    """Walking speeds (m/s) at which a user goes, over an interval of ``interval_s``
    simulated seconds, as far on average as the model moves it in one (``model_move_m``),
    from half to 1.5 times that pace: the users flown then move as the planner's futures
    have them move. (The field preset's 8.0 m an interval of 55 s is a stroll, 0.15 m/s on
    average: users who mostly stand while their device offloads.)"""
    pace = model_move_m(scenario) / interval_s
    return 0.5 * pace, 1.5 * pace


@dataclass(frozen=True)
class TaskParams:
    """How tasks arrive and when a user speaks (simulated seconds, metres)."""

    interval_s: float = 55.0
    """One interval of the model, in simulated seconds, so that tasks arrive in time as the
    planner's futures have them arrive per interval: the field preset's interval lasts 55.5 s
    on average as the model flies it (a hold and a flight; mcts, seeds 1-6, docs/MODEL.md
    "Task models"). Also the longest silence of a user with tasks."""
    law: Law = "backlog"
    backlog_max: int = 20
    """The most tasks a user holds (``backlog``); arrivals beyond it are lost."""
    resend_m: float = 50.0
    """A user with tasks that has moved this far since its last request sends a new one."""
    retry_s: float = 40.0
    """After a refusal, the wait before the next try."""
    fleet: bool = False
    """Submit to the fleet (``{prefix}/fleet/request/{user_id}``), not to one vehicle: the
    backlog comes down by the services the members announce (``fleet/served``)."""


@dataclass
class Walker:
    """One user: its random-waypoint walk (metres, seconds) and its tasks."""

    user_id: str
    xy: np.ndarray
    target: np.ndarray
    speed_mps: float
    pause_s: float = 0.0
    backlog: int = 0
    """Tasks waiting, as this user knows them."""
    next_draw_s: float = 0.0
    """Simulated time of the next draw of the model."""
    draws: int = 0
    fresh: bool = False
    """``redraw``: a draw not sent yet."""
    view: int | None = None
    """The service's count of this user's backlog, as last heard (None: nothing in force in
    this sortie that it knows of)."""
    view_request: int = 0
    """The request ``view`` is about."""
    sortie: int | None = None
    served_seen: int = 0
    """Tasks served in ``sortie``, as last heard."""
    sent_xy: np.ndarray | None = None
    sent_at_s: float = -math.inf
    wait_until_s: float = -math.inf
    """After a refusal: no request before this simulated time."""
    arrived: int = 0
    lost: int = 0
    """Tasks that arrived to a full backlog."""
    served: int = 0
    """Tasks the service served, as learnt, over every sortie."""
    submitted: int = 0
    acked: int = 0
    refused: int = 0
    last_refusal: str = ""
    """Counted, not kept: a user process runs through any number of sorties."""
    done: bool = False
    request_id: int = 0
    """This user's last acked request."""
    history: list[tuple[float, int]] = field(default_factory=list)
    """(simulated time, backlog) of each request sent, for the tests."""


def new_walkers(count: int, scenario: Scenario, params: WalkParams, rng: np.random.Generator,
                first_within_s: float = 0.0) -> list[Walker]:
    """``count`` users at the scenario's layout, each with its first draw within
    ``first_within_s`` simulated seconds (so that the first plan sees every user)."""
    start = user_rows(count, scenario.area_side_m)[:, :2]
    return [Walker(f"user-{i}", start[i].copy(), rng.uniform(0.0, params.side_m, 2),
                   float(rng.uniform(params.speed_min_mps, params.speed_max_mps)),
                   next_draw_s=float(rng.uniform(0.0, first_within_s))) for i in range(count)]


def step(w: Walker, dt_s: float, params: WalkParams, rng: np.random.Generator) -> None:
    """Advance one walker by ``dt_s``: walk to the waypoint, pause, draw the next one."""
    left = dt_s
    while left > 1e-9:
        if w.pause_s > 0:
            used = min(left, w.pause_s)
            w.pause_s -= used
            left -= used
            continue
        gap = w.target - w.xy
        dist = float(math.hypot(*gap))
        reach = w.speed_mps * left
        if reach < dist:
            w.xy = w.xy + gap * (reach / dist)
            return
        w.xy = w.target.copy()
        left -= dist / w.speed_mps if w.speed_mps > 0 else left
        w.pause_s = float(rng.uniform(0.0, params.pause_max_s))
        w.target = rng.uniform(0.0, params.side_m, 2)
        w.speed_mps = float(rng.uniform(params.speed_min_mps, params.speed_max_mps))


def arrive(w: Walker, now_s: float, p: np.ndarray, tp: TaskParams, rng: np.random.Generator) -> None:
    """Every draw due by ``now_s``: one draw of the model per interval, added to the backlog
    (capped) or, ``redraw``, in its place."""
    one = np.zeros(1, dtype=np.int64)
    while now_s >= w.next_draw_s:
        if tp.law == "backlog" and w.draws > 0:
            draw_arrivals(p, one, rng)
        else:
            draw_tasks(p, one, rng)
        w.draws += 1
        drawn = int(one[0])
        if tp.law == "redraw":
            w.backlog, w.fresh = drawn, True
        else:
            kept = min(drawn, max(tp.backlog_max - w.backlog, 0))
            w.backlog += kept
            w.arrived += kept
            w.lost += drawn - kept
        w.next_draw_s += tp.interval_s


UserStreams = tuple[np.random.Generator, np.random.Generator]
"""One user's own generators: its walk's and its tasks'."""


def user_streams(seed: int, count: int) -> tuple[np.random.Generator, list[UserStreams]]:
    """The generators of ``count`` users from ``seed``: one for their start (``new_walkers``)
    and, for each user, one for its walk and one for its tasks (independent streams of one
    ``SeedSequence``)."""
    seqs = np.random.SeedSequence(seed).spawn(1 + 2 * count)
    rngs = [np.random.default_rng(s) for s in seqs]
    return rngs[0], [(rngs[1 + 2 * i], rngs[2 + 2 * i]) for i in range(count)]


def advance_users(walkers: list[Walker], streams: list[UserStreams], dt_s: float, now_s: float, params: WalkParams,
                  p: np.ndarray, tp: TaskParams) -> None:
    """Walk every user ``dt_s`` and add the tasks due by ``now_s``, each user from its own
    generators: a user's walk and tasks are then functions of the seed and the simulated
    time alone, not of how the wall clock cut that time into ticks nor of what the other
    users drew. Two sorties with one seed meet the same users whatever their planner does
    (the common random numbers of ``bench --flight``'s A/B); only a service changes a
    backlog."""
    for w, (walk, tasks) in zip(walkers, streams):
        step(w, dt_s, params, walk)
        arrive(w, now_s, p, tp, tasks)


def learn_served(w: Walker, sortie: int | None, served_tasks: int | None) -> None:
    """The service says ``served_tasks`` of this user were served in ``sortie``: what is new
    of it comes off the backlog. The first news is the baseline; a later sortie counts
    from zero; a stale one (an earlier sortie, a smaller count) is ignored."""
    if sortie is None or served_tasks is None:
        return
    if w.sortie is None:
        w.sortie, w.served_seen = sortie, served_tasks
        return
    if sortie < w.sortie or (sortie == w.sortie and served_tasks <= w.served_seen):
        return
    if sortie > w.sortie:  # a new sortie: the last one's requests were closed with it
        w.sortie, w.served_seen, w.view, w.view_request = sortie, 0, None, 0
    new = served_tasks - w.served_seen
    w.served_seen = served_tasks
    w.served += new
    w.backlog = max(w.backlog - new, 0)


def on_ack(w: Walker, ack: TaskAck, request: TaskRequest) -> None:
    """The service took ``request``: its count now is the request's less what it served
    that the request had not taken off (``counted_backlog``, from the ack's ``sortie`` and
    ``served_tasks``, which ``learn_served`` takes off our backlog too: the counts agree).
    Without them in the ack, or without ``served_seen`` in the request, its count is the
    request's tasks (if the ack shows services the request did not know of, the counts
    differ and the user sends again)."""
    w.acked += 1
    w.request_id = ack.request_id
    learn_served(w, ack.sortie, ack.served_tasks)
    counted = request.tasks if ack.sortie is None or ack.served_tasks is None else \
        request.counted_backlog(ack.sortie, ack.served_tasks)
    w.view, w.view_request = counted, ack.request_id


def on_place(w: Walker, place: UserPlace) -> None:
    """The service's ``user_place`` for this user: what it served, and its count of the
    backlog of the request in force (if it is this user's latest as far as it knows)."""
    learn_served(w, place.sortie, place.served_tasks)
    if place.sortie != w.sortie:
        return
    if place.request_id is None:
        w.view, w.view_request = None, 0
    elif place.request_id >= w.view_request:
        w.view, w.view_request = place.backlog, place.request_id


def on_refused(w: Walker, now_s: float, tp: TaskParams, why: str) -> None:
    w.refused += 1
    w.last_refusal = why
    w.wait_until_s = now_s + tp.retry_s


def wants_to_send(w: Walker, now_s: float, tp: TaskParams) -> bool:
    """Whether the user sends a request now (see the module's docstring)."""
    if w.done or now_s < w.wait_until_s:
        return False
    if tp.law == "redraw":
        return w.fresh
    if w.view is None:
        return w.backlog > 0
    if w.backlog != w.view:
        return True
    if w.backlog == 0:
        return False
    moved = w.sent_xy is None or float(math.hypot(*(w.xy - w.sent_xy))) >= tp.resend_m
    return moved or now_s - w.sent_at_s >= tp.interval_s


def sent(w: Walker, now_s: float) -> int:
    """The user sends its backlog now: note it; the tasks sent."""
    w.submitted += 1
    w.sent_xy, w.sent_at_s, w.fresh = w.xy.copy(), now_s, False
    w.history.append((now_s, w.backlog))
    return w.backlog


def on_fleet_served(w: Walker, done: FleetServed) -> None:
    """A member of the fleet served this user: what it served comes off the backlog, and
    off every member's count of the request in force (each counts the others' services)."""
    w.served += done.tasks
    w.backlog = max(w.backlog - done.tasks, 0)
    if w.view is not None:
        w.view = max(w.view - done.tasks, 0)


def follow_fleet_services(client: PlannerClient, sink: "queue.SimpleQueue[FleetServed]") -> None:
    """Every service the fleet's members fly (``{prefix}/fleet/served/*``), into ``sink``."""
    def handler(sample: object) -> None:
        try:  # a simulated user's own backlog: the envelope's signature is the members' to check
            sink.put(decode(unverified_body(sample.payload.to_bytes()), FleetServed))  # type: ignore[attr-defined]
        except (ProtocolError, Unverified):
            pass
    client._subs.append(client.session.declare_subscriber(FleetKeys(client.keys.prefix).all_served, handler))


def request_of(w: Walker, now_s: float, tp: TaskParams, params: WalkParams) -> TaskRequest:
    """The request the user sends now (noted by ``sent``): its backlog, where it stands
    (in the area, to 0.1 m) and, under the ``backlog`` law once it has heard of its sortie,
    the tasks served to it there that its backlog has taken off (``served_seen``)."""
    x, y = (float(round(v, 1)) for v in np.clip(w.xy, 0.0, params.side_m))
    tasks = sent(w, now_s)
    knows = tp.law == "backlog" and w.sortie is not None and not tp.fleet
    return request_for(w.user_id, x, y, tasks, client_ref=f"{w.user_id}#{w.submitted}",
                       served_seen=w.served_seen if knows else None, sortie=w.sortie if knows else None)


def run_users(client: PlannerClient, scenario: Scenario, count: int, tp: TaskParams, speedup: float,
              seed: int, stop: threading.Event, duration_s: float | None = None,
              speeds_mps: tuple[float, float] | None = None) -> list[Walker]:
    """Walk, let tasks arrive and submit until ``stop`` is set, ``duration_s`` (wall) passes,
    or the service refuses every user because it flies no more sorties. Between two sorties
    the service refuses requests too ("sortie over: waiting for ..."): users keep walking,
    their tasks keep arriving, and they ask again after ``tp.retry_s``. They walk at
    ``speeds_mps`` (default: ``model_pace``)."""
    setup, streams = user_streams(seed, count)
    params = WalkParams(scenario.area_side_m, *(speeds_mps or model_pace(scenario, tp.interval_s)))
    # the first draws within a wall second, so that the first plan sees every user
    walkers = new_walkers(count, scenario, params, setup, min(tp.interval_s, speedup))
    by_id = {w.user_id: w for w in walkers}
    p = pack(scenario)
    places: queue.SimpleQueue[UserPlace] = queue.SimpleQueue()
    fleet_served: queue.SimpleQueue[FleetServed] = queue.SimpleQueue()
    if tp.fleet:  # the services the members fly; each member's places are its own
        follow_fleet_services(client, fleet_served)
    else:
        client.follow_places(places.put)  # zenoh's thread: handed over to this one
    start = time.monotonic()
    last = start
    while not stop.is_set():
        now = time.monotonic()
        if duration_s is not None and now - start >= duration_s:
            break
        sim = (now - start) * speedup
        while not places.empty():
            place = places.get()
            if place.user_id in by_id:
                on_place(by_id[place.user_id], place)
        while not fleet_served.empty():
            done = fleet_served.get()
            if done.user_id in by_id:
                on_fleet_served(by_id[done.user_id], done)
        advance_users(walkers, streams, (now - last) * speedup, sim, params, p, tp)
        last = now
        for w in walkers:
            if stop.is_set():  # each submit may take a round trip over a slow radio: many take seconds
                break
            if wants_to_send(w, sim, tp):
                submit(client, w, sim, tp, params)
        if all(w.done for w in walkers):
            log.info("the service's sortie is over: every user stops")
            break
        stop.wait(TICK_S)
    return walkers


def submit(client: PlannerClient, w: Walker, now_s: float, tp: TaskParams, params: WalkParams) -> None:
    """Send the user's backlog, position and what it knows was served; take in the ack or
    the refusal."""
    request = request_of(w, now_s, tp, params)
    x, y, tasks = request.x_m, request.y_m, request.tasks
    try:
        if tp.fleet:
            answer = client.submit_to_fleet(request)
            ack = answer.ack
        else:
            ack = client.submit_request(request)
    except ClientError as err:
        on_refused(w, now_s, tp, f"{err.field}: {err.message}")
        log.info("%s refused: %s", w.user_id, printable(w.last_refusal))
        if err.field == "service" and ONE_SORTIE in err.message:
            w.done = True
        return
    except ProtocolError as err:
        on_refused(w, now_s, tp, str(err))
        log.info("%s: %s", w.user_id, printable(w.last_refusal))
        return
    if tp.fleet:  # each member's sortie and served counts are its own: the user counts what it heard
        w.acked += 1
        w.request_id, w.view, w.view_request = ack.request_id, request.tasks, ack.request_id
    else:
        on_ack(w, ack, request)
    where = "" if ack.place is None else f", place {ack.place} in about {ack.eta_s or 0.0:.0f} s"
    log.info("%s at (%.0f, %.0f): backlog %d -> request %d (served %d so far%s)", w.user_id, x, y, tasks,
             ack.request_id, w.served, where)
