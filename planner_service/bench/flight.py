"""Flown against planned: the same seeded world flown through the service (vehicle stub,
simulated users and the service as real processes on loopback, at a speed-up) and planned
offline (``run_sortie``: the model alone), side by side, algorithm by algorithm.

"The same world": the scenario the service flies (the `field` preset with the users'
backlog law, ``task_model = "backlog"``, as many users), the same user layout, laws and
seed. The draws are not the same numbers (the users walk in time, the model in intervals),
so each figure is a median over seeds, and the ratio of the medians is the figure to read.

Per sortie: throughput in tasks per interval (per service), average reward (11), tasks per
sortie, the services whose request was the one the plan was made for, and decisions per
service (the service's decisions, counted from its log, over its services). Two flights of
one seed meet the same users (each user draws from its own generators), so the algorithms
are also compared seed by seed against the first.

A third world, ``timed``, is planned offline too: the scenario's, but with the users' tasks
arriving as ``sim_bridge users``' do (a draw every ``USERS_ARRIVAL_PERIOD_S`` of flight and
hold at each user's phase, ``SortieEnv`` option ``arrivals_every_s``), whatever law the
planners' futures assume (the scenario's ``task_arrival_period_s``). What the algorithms do
there, against what they do in the scenario's own world, is the part of the flown figures
that comes from the difference of the two laws; ``--offline-only`` plans both worlds
without flying (seconds, not minutes).
"""

from __future__ import annotations

import math
import re
import statistics
import tempfile
from pathlib import Path
from typing import Any, Callable, Sequence

from ..harness.demo import run_demo
from ..harness.offline import USERS_ARRIVAL_PERIOD_S, plan_offline

ALGOS = ("mcts", "greedy", "random")
FIGURES = ("throughput_tasks_per_interval", "average_reward", "total_tasks")
WORLDS = ("flown", "offline", "timed")


def fly(algo: str, seed: int, users: int, speedup: float, budget_ms: float,
        echo: Callable[[str], None]) -> dict[str, Any]:
    """One sortie through the service; its summary with the decisions counted."""
    with tempfile.TemporaryDirectory(prefix="uav-flight-") as tmp:
        out = Path(tmp)
        summary = run_demo(out, users=users, speedup=speedup, budget_ms=budget_ms, seed=seed, algo=algo,
                           offline=False, echo=lambda _: None)
        decisions = len(re.findall(r"decision \(", (out / "service.log").read_text(errors="replace")))
    n = summary["intervals"]
    summary["decisions_per_service"] = decisions / n if n else float("nan")
    summary["planned_request_share"] = summary["services_of_the_planned_request"] / n if n else float("nan")
    echo(f"  flown   {algo:7s} seed {seed}: {n} services, {summary['throughput_tasks_per_interval']:.1f} "
         f"tasks/interval, reward {summary['average_reward']:.3f}, {decisions} decisions")
    return summary


def run_flight_bench(seeds: Sequence[int], algos: Sequence[str] = ALGOS, users: int = 10, speedup: float = 25.0,
                     budget_ms: float = 150.0, progress: Callable[[str], None] | None = None,
                     fly_too: bool = True, iterations: int | None = None) -> dict[str, Any]:
    """Each algorithm on each seed in each world (``WORLDS``; without ``fly_too`` the two
    offline ones only): medians, the flown-to-offline ratios and the per-seed figures.
    ``iterations``: offline, MCTS decides on that many instead of ``budget_ms``."""
    echo = progress or (lambda _: None)
    rows = []
    for algo in algos:
        runs = {}
        if fly_too:
            runs["flown"] = [fly(algo, seed, users, speedup, budget_ms, echo) for seed in seeds]
        for world in ("offline", "timed"):
            runs[world] = [plan_offline(algo, seed, users, budget_ms, echo, timed=world == "timed",
                                        iterations=iterations) for seed in seeds]
        row: dict[str, Any] = {"algo": algo, "seeds": list(seeds)}
        for key in FIGURES:
            row[key] = {world: statistics.median(s[key] for s in runs[world]) for world in runs}
            if fly_too:
                o = row[key]["offline"]
                row[key]["ratio"] = row[key]["flown"] / o if o else float("nan")
        row["per_seed"] = {world: {key: [s[key] for s in runs[world]] for key in FIGURES} for world in runs}
        if fly_too:
            flown = runs["flown"]
            row["planned_request_share"] = statistics.median(s["planned_request_share"] for s in flown)
            row["decisions_per_service"] = statistics.median(s["decisions_per_service"] for s in flown)
            row["fairness_violations"] = sum(s["fairness_violations"] for s in flown)
            row["energy_violations"] = sum(bool(s["energy_violation"]) for s in flown)
        rows.append(row)
    return {"users": users, "speedup": speedup, "budget_ms": budget_ms, "iterations": iterations, "flown": fly_too,
            "arrivals_every_s": USERS_ARRIVAL_PERIOD_S, "rows": rows}


def format_flight(r: dict[str, Any]) -> str:
    """The table: per algorithm, each figure in each world (and flown / offline)."""
    worlds = [w for w in WORLDS if w in r["rows"][0]["per_seed"]]
    ratio = "flown" in worlds
    pace = f"{r['budget_ms']:g} ms" if r["iterations"] is None else f"{r['iterations']} iterations"
    lines = [(f"flown through the service (stub x{r['speedup']:g}, {r['users']} users, {pace} a "
              "decision) against planned offline" if ratio else f"planned offline ({r['users']} users, "
              f"{pace} a decision)") + f", medians over seeds {_span(r['rows'][0]['seeds'])}; timed: "
             f"offline, the users' tasks arriving every {r['arrivals_every_s']:g} s as in flight:"]
    cols = " ".join(f"{w:>7s}" for w in worlds) + ("  ratio" if ratio else "")
    width = len(cols)
    lines.append(f"{'algo':8s} {'tasks/interval':>{width}s}  {'average reward':>{width}s}  {'tasks/sortie':>{width}s}"
                 + ("  planned req.  decisions/service" if ratio else ""))
    lines.append(f"{'':8s} {cols}  {cols}  {cols}")
    for row in r["rows"]:
        cells = []
        for key, fmt in zip(FIGURES, ("7.1f", "7.3f", "7.0f")):
            figure = row[key]
            cells.append(" ".join(f"{figure[w]:{fmt}}" for w in worlds) + (f" {figure['ratio']:6.2f}" if ratio else ""))
        extra = f"  {row['planned_request_share']:11.0%} {row['decisions_per_service']:18.2f}" if ratio else ""
        lines.append(f"{row['algo']:8s} " + "  ".join(cells) + extra)
    first = r["rows"][0]
    for row in r["rows"][1:]:
        lines += [paired_line(first, row, world) for world in worlds]
    return "\n".join(lines)


def _span(seeds: list[int]) -> str:
    """``1-12`` for consecutive seeds, else the list."""
    return f"{seeds[0]}-{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) else str(seeds)


def paired_line(a: dict[str, Any], b: dict[str, Any], world: str = "flown") -> str:
    """``a`` against ``b`` seed by seed in ``world`` (each seed's users are the same for
    both: ``sim_bridge.users.user_streams`` in flight, the seed's own draws offline): the
    median and mean difference with the mean's standard error, and the seeds each leads, in
    tasks per interval and in reward."""
    parts = []
    for key, name, fmt in (("throughput_tasks_per_interval", "tasks/interval", ".2f"), ("average_reward", "reward", ".3f")):
        diffs = [x - y for x, y in zip(a["per_seed"][world][key], b["per_seed"][world][key])]
        ahead, behind = sum(d > 0 for d in diffs), sum(d < 0 for d in diffs)
        se = statistics.stdev(diffs) / math.sqrt(len(diffs)) if len(diffs) > 1 else float("nan")
        parts.append(f"{name} median {statistics.median(diffs):+{fmt}}, mean {statistics.fmean(diffs):+{fmt}} "
                     f"+- {se:{fmt}} (ahead on {ahead}, behind on {behind} of {len(diffs)})")
    return f"{world} {a['algo']} - {b['algo']}, per seed: " + "; ".join(parts)
