"""Simulated ground users: each walks by random waypoint over the service area and submits
a task request over zenoh every interval (simulated seconds; ``speedup`` simulated seconds
pass per wall second, as in the vehicle stub).

Start positions are the scenario's user layout (the paper's two rows); task counts are the
model's draws (N(mean, phi^2), rounded, clipped to [0, u_max]). The walk is pure (``step``
with an explicit generator); ``run_users`` adds the clock and the zenoh client.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass

import numpy as np

from planner_service.model import Scenario, pack, user_rows
from planner_service.model.mobility import draw_tasks
from protocol import ProtocolError
from protocol.client import ClientError, PlannerClient

log = logging.getLogger("sim_bridge.users")
ONE_SORTIE = "flies one sortie"
"""In the service's refusal after the landing when it is configured for one sortie only."""


@dataclass
class Walker:
    """One user's random-waypoint walk (metres, seconds)."""

    user_id: str
    xy: np.ndarray
    target: np.ndarray
    speed_mps: float
    pause_s: float = 0.0
    submitted: int = 0
    acked: int = 0
    refused: int = 0
    last_refusal: str = ""
    """Counted, not kept: a user process runs through any number of sorties."""
    done: bool = False


@dataclass(frozen=True)
class WalkParams:
    side_m: float
    speed_min_mps: float = 0.5
    speed_max_mps: float = 2.0
    pause_max_s: float = 20.0


def new_walkers(count: int, scenario: Scenario, params: WalkParams, rng: np.random.Generator) -> list[Walker]:
    start = user_rows(count, scenario.area_side_m)[:, :2]
    return [Walker(f"user-{i}", start[i].copy(), rng.uniform(0.0, params.side_m, 2),
                   float(rng.uniform(params.speed_min_mps, params.speed_max_mps))) for i in range(count)]


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


def run_users(client: PlannerClient, scenario: Scenario, count: int, interval_s: float, speedup: float,
              seed: int, stop: threading.Event, duration_s: float | None = None) -> list[Walker]:
    """Walk and submit until ``stop`` is set, ``duration_s`` (wall) passes, or the service
    refuses every user because it flies no more sorties. Between two sorties the service
    refuses requests too ("sortie over: waiting for ..."): users keep walking and asking."""
    rng = np.random.default_rng(seed)
    params = WalkParams(scenario.area_side_m)
    walkers = new_walkers(count, scenario, params, rng)
    p = pack(scenario)
    tasks = np.zeros(1, dtype=np.int64)
    start = time.monotonic()
    # the first requests go out within a second so that the first plan sees every user
    due = [start + float(rng.uniform(0.0, min(1.0, interval_s / speedup))) for _ in walkers]
    last = start
    while not stop.is_set():
        now = time.monotonic()
        if duration_s is not None and now - start >= duration_s:
            break
        for w in walkers:
            step(w, (now - last) * speedup, params, rng)
        last = now
        for i, w in enumerate(walkers):
            if w.done or now < due[i]:
                continue
            due[i] = now + interval_s / speedup
            draw_tasks(p, tasks, rng)
            x, y = (float(round(v, 1)) for v in np.clip(w.xy, 0.0, params.side_m))
            w.submitted += 1
            try:
                ack = client.submit(w.user_id, x, y, int(tasks[0]), client_ref=f"{w.user_id}#{w.submitted}")
            except ClientError as err:
                w.refused += 1
                w.last_refusal = f"{err.field}: {err.message}"
                log.info("%s refused: %s: %s", w.user_id, err.field, err.message)
                if err.field == "service" and ONE_SORTIE in err.message:
                    w.done = True
                continue
            except ProtocolError as err:
                w.refused += 1
                w.last_refusal = str(err)
                continue
            w.acked += 1
            log.info("%s at (%.0f, %.0f): %d tasks -> request %d", w.user_id, x, y, tasks[0], ack.request_id)
        if all(w.done for w in walkers):
            log.info("the service's sortie is over: every user stops")
            break
        stop.wait(0.05)
    return walkers
