"""``bench --fleet``: a fleet planner's decision time per UAV and the size of the messages its
UAVs send, for N = 3 and 5 at the paper's size and at K = 200 points / I = 1000 users.

Every planner of the fleet registry is timed (``joint`` only up to ``JOINT_MAX_UAVS`` and
where its search over K^N joint actions fits: ``fleet.joint_fits``). A decision is timed as a sortie asks for it (the UAV whose
interval ends first decides, on the states the fleet meets), so the time includes what the
planner does between decisions of one UAV (``claims`` rebuilding its tree when the others'
claims change). Message sizes are what the planner reports (``message_bytes``); 0 for a
planner that sends none.
"""

from __future__ import annotations

import time
from typing import Any, Callable

import numpy as np

from ..fleet import MAX_JOINT_ACTIONS, fleet_algorithms, fleet_streams, joint_fits, make_fleet_policy, message_figures
from ..fleet.sortie import sent_sizes
from ..fleet.policies import intent_of
from ..model import HAVE_NUMBA, Scenario
from ..model.fleet import Fleet, FleetEnv
from ..policy import PolicySpec
from .run import scenario_of

SIZES = ((20, 10), (200, 1000))
"""(K, I): the paper's size, and the issue's large one."""
UAVS = (3, 5)
JOINT_MAX_UAVS = 3
"""``joint`` is timed up to this N (as ``experiment fleet --joint-max-uavs``'s default)."""
TARGET_MS = 150.0
"""The issue's target per UAV decision at N = 5, K = 200, I = 1000, 1000 iterations (p50)."""
TARGET_MESSAGE_BYTES = 2048


def time_fleet_decisions(scenario: Scenario, uavs: int, algo: str, iterations: int, decisions: int,
                         seed: int = 0) -> dict[str, Any]:
    """Fly ``algo``'s sortie(s) on ``scenario`` with ``uavs`` UAVs from ``seed`` on until
    ``decisions`` decisions are timed; their median and p95 in ms, and the messages sent."""
    seconds: list[float] = []
    sent: list[int] = []
    while len(seconds) < decisions:
        world_rng, rngs = fleet_streams(seed, uavs)
        env = FleetEnv(scenario, Fleet(uavs=uavs))
        env.rng = world_rng
        env.reset()
        policy = make_fleet_policy(algo, "mcts", PolicySpec(iterations=iterations), rngs)
        policy.begin(env)
        while not env.done and len(seconds) < decisions:
            start = time.perf_counter()
            decision = policy.decide(env)
            seconds.append(time.perf_counter() - start)
            env.step(decision.action, intent_of(decision))
        sent += sent_sizes(policy)
        seed += 1
    messages = message_figures(sent)
    return {"decisions": len(seconds), "median_ms": float(np.median(seconds) * 1e3),
            "p95_ms": float(np.percentile(seconds, 95) * 1e3), "messages_sent": messages["sent"],
            "message_bytes_median": messages["bytes_median"], "message_bytes_max": messages["bytes_max"]}


def run_fleet_bench(decisions: int, iterations: int, sizes=SIZES, uavs=UAVS,
                    progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Every registered fleet planner at every (N, K, I)."""
    results: dict[str, Any] = {"numba": HAVE_NUMBA, "iterations": iterations, "target_ms": TARGET_MS,
                               "target_message_bytes": TARGET_MESSAGE_BYTES, "rows": [], "skipped": []}
    algos = fleet_algorithms()
    for k, i in sizes:
        scenario = scenario_of(k, i)
        for algo in algos:  # warm-up: numba's compile (or cache load) outside the timing
            if algo != "joint":
                time_fleet_decisions(scenario, 2, algo, 2, 2)
        for n in uavs:
            for algo in algos:
                if algo == "joint" and n > JOINT_MAX_UAVS:
                    results["skipped"].append(f"joint at N={n}, K={k}: beyond JOINT_MAX_UAVS={JOINT_MAX_UAVS}")
                    continue
                if algo == "joint" and not joint_fits(k, n):
                    results["skipped"].append(f"joint at N={n}, K={k}: K^N = {k ** n} joint actions, beyond "
                                              f"{MAX_JOINT_ACTIONS}")
                    continue
                if progress:
                    progress(f"{algo} N={n} K={k} I={i}: {decisions} decisions")
                row = time_fleet_decisions(scenario, n, algo, iterations, decisions)
                results["rows"].append({"algo": algo, "N": n, "K": k, "I": i, **row})
    return results


def format_fleet(results: dict[str, Any]) -> str:
    lines = [f"fleet decisions per UAV, mcts {results['iterations']} iterations per decision "
             f"(numba: {results['numba']}); target {results['target_ms']:g} ms at N=5 K=200 I=1000, "
             f"messages under {results['target_message_bytes']} B",
             f"{'planner':>12} {'N':>2} {'K':>4} {'I':>5} {'decisions':>9} {'median ms':>10} {'p95 ms':>8} "
             f"{'messages':>8} {'max B':>6}"]
    for r in results["rows"]:
        lines.append(f"{r['algo']:>12} {r['N']:>2} {r['K']:>4} {r['I']:>5} {r['decisions']:>9} {r['median_ms']:>10.1f} "
                     f"{r['p95_ms']:>8.1f} {r['messages_sent']:>8} {r['message_bytes_max']:>6}")
    lines += [f"skipped: {s}" for s in results["skipped"]]
    return "\n".join(lines)


__all__ = ["SIZES", "TARGET_MESSAGE_BYTES", "TARGET_MS", "UAVS", "format_fleet", "run_fleet_bench",
           "time_fleet_decisions"]
