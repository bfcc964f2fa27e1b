"""One simulated fleet sortie and its summary: per UAV the ``plan --json`` summary of one
UAV (``sortie.summarize``), and the fleet's figures over them."""

from __future__ import annotations

import time
from typing import Any, Iterable

import numpy as np

from ..model import Scenario
from ..model.fairness import fairness_violations
from ..model.fleet import Fleet, FleetEnv
from ..model.fleet.audit import Hold, overlaps
from ..model.interval import NO_USER
from ..policy import PolicySpec
from ..sortie import summarize
from .policies import MessageLink, intent_of, make_fleet_policy

FLEET_ONLY = ("uav", "start_s", "end_s", "ended")
"""Keys of a fleet step's record that a single UAV's trace does not have."""


def fleet_streams(seed: int, uavs: int) -> tuple[np.random.Generator, list[np.random.Generator]]:
    """The world's generator and one per UAV's planner, all fixed by ``seed``. The world's
    and UAV 0's are the single-UAV sortie's (``sortie.seed_streams``: a seed sequence's
    children do not depend on how many are spawned), so a fleet of one draws what it does."""
    children = np.random.SeedSequence(seed).spawn(1 + uavs)
    return np.random.default_rng(children[0]), [np.random.default_rng(c) for c in children[1:]]


def run_fleet_sortie(scenario: Scenario, fleet: Fleet, algo: str, seed: int, spec: PolicySpec | None = None,
                     base: str = "mcts", options: dict[str, Any] | None = None,
                     settings: dict[str, Any] | None = None, link: MessageLink | None = None) -> dict[str, Any]:
    """Fly one fleet sortie with fleet planner ``algo`` (each UAV's planner ``base``) and
    return its summary: ``per_uav`` (each UAV's ``plan --json`` summary, its ``holds``
    [start_s, end_s] beside it) and ``fleet`` (the fleet's figures, ``fleet_figures``).
    ``settings``: the fleet planner's own (``policies.FleetFactory``); ``link``: the
    messages' loss and lateness, for a planner that sends some. ``messages``: what the UAVs
    sent one another (``message_figures``); ``dec-mcts`` also adds its counts to ``fleet``."""
    spec = spec or PolicySpec()
    world_rng, planner_rngs = fleet_streams(seed, fleet.uavs)
    env = FleetEnv(scenario, fleet)
    env.rng = world_rng
    env.reset(options=options)
    policy = make_fleet_policy(algo, base, spec, planner_rngs, link, **(settings or {}))
    traces: list[list[dict[str, Any]]] = [[] for _ in range(fleet.uavs)]
    holds: list[list[list[float]]] = [[] for _ in range(fleet.uavs)]
    decision_s: list[list[float]] = [[] for _ in range(fleet.uavs)]
    events: list[dict[str, Any]] = []
    start = time.perf_counter()
    policy.begin(env)
    while not env.done:
        j = env.due
        t0 = time.perf_counter()
        decision = policy.decide(env)
        decision_s[j].append(time.perf_counter() - t0)
        _, _, _, _, info = env.step(decision.action, intent_of(decision))
        record = {k: v for k, v in info.items() if k not in FLEET_ONLY}
        traces[j].append(record)
        holds[j].append([info["start_s"], info["end_s"]])
        events.append({"uav": j, "user": record["user"], "tasks": record["tasks"], "point": record["hover_point"],
                       "start_s": info["start_s"], "end_s": info["end_s"]})
    wall = time.perf_counter() - start
    per_uav = []
    for j, uav_scenario in enumerate(env.scenarios):
        summary = summarize(uav_scenario, traces[j])
        summary.update(algo=base, preset=scenario.name, seed=seed, iterations=spec.iterations,
                       budget_ms=spec.budget_ms, wall_s=wall,
                       decision_ms_median=float(np.median(decision_s[j]) * 1e3) if decision_s[j] else 0.0,
                       uav=j, holds=holds[j], ended=env.ended.get(j))
        per_uav.append(summary)
    every = [s for d in decision_s for s in d]
    figures = fleet_figures(scenario, per_uav, events, getattr(policy, "blocked", 0))
    link = getattr(policy, "link", None)
    if link is not None:
        sizes = link.sizes
        figures.update(messages=len(sizes), message_bytes_max=max(sizes, default=0),
                       message_bytes_mean=float(np.mean(sizes)) if sizes else 0.0)
    return {
        "algo": algo, "base": base, "uavs": fleet.uavs, "layer_m": fleet.layer_m, "base_step_m": fleet.base_step_m,
        "preset": scenario.name, "seed": seed, "iterations": spec.iterations, "budget_ms": spec.budget_ms,
        "wall_s": wall, "decision_ms_median": float(np.median(every) * 1e3) if every else 0.0,
        "fleet": figures, "settings": dict(settings or {}),
        "messages": message_figures(sent_sizes(policy)),
        "per_uav": per_uav, "events": events, "scenario": scenario.as_dict(),
    }


def sent_sizes(policy: object) -> list[int]:
    """The size in bytes of every message a fleet planner's UAVs sent (none: empty): its
    ``message_bytes``, or its simulated link's (``dec-mcts``)."""
    sizes = getattr(policy, "message_bytes", None)
    if sizes is None:
        sizes = getattr(getattr(policy, "link", None), "sizes", ())
    return [int(b) for b in sizes]


def message_figures(message_bytes: Iterable[int]) -> dict[str, Any]:
    """What a fleet planner's UAVs sent one another, from the size in bytes of each message
    (0 for a planner that sends none)."""
    sizes = [int(b) for b in message_bytes]
    return {"sent": len(sizes), "bytes_median": float(np.median(sizes)) if sizes else 0.0,
            "bytes_max": max(sizes, default=0), "bytes_total": int(sum(sizes))}


def fleet_figures(scenario: Scenario, per_uav: list[dict[str, Any]], events: list[dict[str, Any]],
                  blocked: int) -> dict[str, Any]:
    """The fleet's figures: ``throughput_tasks_per_interval`` is the sum of the UAVs'
    (tasks per interval: the fleet's sum rate, each UAV's interval in parallel);
    ``total_tasks``, ``energy_used_j`` and ``services`` are sums; ``average_reward`` the
    mean q over every interval flown; ``fairness_violations`` the rule (3), (9c) over the
    fleet's services in the order made (the users' counts are shared); ``double_services``
    and ``double_holds`` the overlaps in time of two UAVs' intervals on one user or one
    point (``audit.overlaps``: the environment refuses both, this recounts them from the
    records); ``blocked_choices`` the choices the fleet did not allow, replaced."""
    rewards = [r["reward"] for s in per_uav for r in s["trace"]]
    services = [(e["user"], e["tasks"]) for e in events if e["user"] != NO_USER]
    doubles, holds = overlaps(Hold(e["uav"], e["point"], e["user"], e["start_s"], e["end_s"]) for e in events)
    return {
        "throughput_tasks_per_interval": float(sum(s["throughput_tasks_per_interval"] for s in per_uav)),
        "throughput_bits_per_interval": float(sum(s["throughput_bits_per_interval"] for s in per_uav)),
        "total_tasks": int(sum(s["total_tasks"] for s in per_uav)),
        "intervals": int(sum(s["intervals"] for s in per_uav)),
        "average_reward": float(np.mean(rewards)) if rewards else 0.0,
        "energy_used_j": float(sum(s["energy_used_j"] for s in per_uav)),
        "services": len(services),
        "users_served": len({u for u, _ in services}),
        "fairness_violations": fairness_violations(scenario, services),
        "energy_violations": int(sum(bool(s["energy_violation"]) for s in per_uav)),
        "double_services": doubles,
        "double_holds": holds,
        "blocked_choices": int(blocked),
    }
