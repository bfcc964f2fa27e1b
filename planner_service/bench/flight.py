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
"""

from __future__ import annotations

import contextlib
import io
import re
import statistics
import tempfile
from pathlib import Path
from typing import Any, Callable, Sequence

from ..policy import PolicySpec
from ..sortie import run_sortie

ALGOS = ("mcts", "greedy", "random")
FIGURES = ("throughput_tasks_per_interval", "average_reward", "total_tasks")


def offline_scenario(users: int) -> Any:
    """The scenario the demo's service flies, as the model plans it offline."""
    from ..service.config import build_config

    return build_config({}, {}).scenario().replace(num_users=users, task_model="backlog")


def fly(algo: str, seed: int, users: int, speedup: float, budget_ms: float,
        echo: Callable[[str], None]) -> dict[str, Any]:
    """One sortie through the service; its summary with the decisions counted."""
    from ..service.demo import run_demo

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


def plan_offline(algo: str, seed: int, users: int, budget_ms: float, echo: Callable[[str], None],
                 scenario: Any = None) -> dict[str, Any]:
    """The sortie planned offline on ``scenario`` (default: the demo's, ``offline_scenario``)."""
    scenario = offline_scenario(users) if scenario is None else scenario.replace(num_users=users)
    with contextlib.redirect_stdout(io.StringIO()):
        summary = run_sortie(scenario, algo, seed, PolicySpec(iterations=None, budget_ms=budget_ms))
    echo(f"  offline {algo:7s} seed {seed}: {summary['intervals']} intervals, "
         f"{summary['throughput_tasks_per_interval']:.1f} tasks/interval, reward {summary['average_reward']:.3f}")
    return summary


def run_flight_bench(seeds: Sequence[int], algos: Sequence[str] = ALGOS, users: int = 10, speedup: float = 25.0,
                     budget_ms: float = 150.0, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    echo = progress or (lambda _: None)
    rows = []
    for algo in algos:
        flown = [fly(algo, seed, users, speedup, budget_ms, echo) for seed in seeds]
        offline = [plan_offline(algo, seed, users, budget_ms, echo) for seed in seeds]
        row: dict[str, Any] = {"algo": algo, "seeds": list(seeds)}
        for key in FIGURES:
            f, o = statistics.median(s[key] for s in flown), statistics.median(s[key] for s in offline)
            row[key] = {"flown": f, "offline": o, "ratio": f / o if o else float("nan")}
        row["planned_request_share"] = statistics.median(s["planned_request_share"] for s in flown)
        row["decisions_per_service"] = statistics.median(s["decisions_per_service"] for s in flown)
        row["flown_per_seed"] = {key: [s[key] for s in flown] for key in FIGURES}
        row["fairness_violations"] = sum(s["fairness_violations"] for s in flown)
        row["energy_violations"] = sum(bool(s["energy_violation"]) for s in flown)
        rows.append(row)
    return {"users": users, "speedup": speedup, "budget_ms": budget_ms, "rows": rows}


def format_flight(r: dict[str, Any]) -> str:
    lines = [f"flown through the service (stub x{r['speedup']:g}, {r['users']} users, {r['budget_ms']:g} ms a "
             f"decision) against planned offline, medians over seeds {r['rows'][0]['seeds']}:",
             f"{'algo':8s} {'tasks/interval':>24s} {'average reward':>24s} {'tasks/sortie':>22s} "
             f"{'planned req.':>12s} {'decisions/service':>17s}",
             f"{'':8s} {'flown  offline  ratio':>24s} {'flown  offline  ratio':>24s} {'flown offline ratio':>22s}"]
    for row in r["rows"]:
        t, q, n = (row[k] for k in FIGURES)
        lines.append(f"{row['algo']:8s} {t['flown']:7.1f} {t['offline']:7.1f} {t['ratio']:6.2f}  "
                     f"{q['flown']:7.3f} {q['offline']:7.3f} {q['ratio']:6.2f}  "
                     f"{n['flown']:6.0f} {n['offline']:6.0f} {n['ratio']:6.2f}  "
                     f"{row['planned_request_share']:11.0%} {row['decisions_per_service']:17.2f}")
    first = r["rows"][0]
    for row in r["rows"][1:]:
        lines.append(paired_line(first, row))
    return "\n".join(lines)


def paired_line(a: dict[str, Any], b: dict[str, Any]) -> str:
    """Flown ``a`` against flown ``b`` seed by seed (each seed's users are the same in both
    flights: ``sim_bridge.users.user_streams``): the median difference and the seeds each
    leads, in tasks per interval and in reward."""
    parts = []
    for key, name, fmt in (("throughput_tasks_per_interval", "tasks/interval", "+.2f"), ("average_reward", "reward", "+.3f")):
        diffs = [x - y for x, y in zip(a["flown_per_seed"][key], b["flown_per_seed"][key])]
        ahead, behind = sum(d > 0 for d in diffs), sum(d < 0 for d in diffs)
        parts.append(f"{name} {statistics.median(diffs):{fmt}} (ahead on {ahead}, behind on {behind} of {len(diffs)})")
    return f"flown {a['algo']} - {b['algo']}, per seed: " + "; ".join(parts)
