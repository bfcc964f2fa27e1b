"""``bench --fleet --flight``: fleets of N UAVs flown on loopback (``demo --uavs N``: a stub
and a service each, two routers, the users submitting to the fleet) against the offline
fleet planner on the same scenario and seed; the coordination traffic each UAV sent on the
fleet's keys (bytes/s) and the services' decision latency. Figures, not pass/fail."""

from __future__ import annotations

import re
import statistics
import tempfile
from pathlib import Path
from typing import Any, Callable

from ..harness.fleet_demo import run_fleet_demo

DECISION = re.compile(r"decision \([^)]*\): \[[^\]]+\] in (\d+) ms")
"""A decision that found points to fly (one that found none took no search)."""


def decision_ms(folder: Path) -> list[float]:
    """Every decision's time in the services' logs under ``folder``."""
    return [float(m) for log in sorted(folder.glob("uav*/service.log")) for m in DECISION.findall(log.read_text())]


def run_fleet_flight(uav_counts: list[int], seeds: list[int], users: int, speedup: float, budget_ms: float,
                     progress: Callable[[str], None]) -> dict[str, Any]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="fleet-flight-") as tmp:
        for n in uav_counts:
            runs = []
            for seed in seeds:
                folder = Path(tmp) / f"n{n}-s{seed}"
                summary = run_fleet_demo(folder, uavs=n, users=users, speedup=speedup, budget_ms=budget_ms,
                                         seed=seed, echo=lambda _: None)
                traffic = [t["fleet_keys"] for t in summary["traffic_bytes_per_s"].values()]
                runs.append({"seed": seed, "flown": summary["fleet"]["throughput_tasks_per_interval"],
                             "offline": summary["offline"]["throughput_tasks_per_interval"],
                             "flown_to_offline": summary["flown_to_offline"],
                             "twice": len(summary["fleet"]["users_served_by_two_uavs"]),
                             "fairness_violations": summary["fleet"]["fairness_violations"],
                             "traffic_bytes_per_s": statistics.mean(traffic),
                             "decision_ms": decision_ms(folder)})
                progress(f"  N={n} seed {seed}: flown {runs[-1]['flown']:.1f}, offline {runs[-1]['offline']:.1f} "
                         f"tasks/interval, {runs[-1]['traffic_bytes_per_s']:.0f} B/s per UAV")
            every_ms = [ms for r in runs for ms in r["decision_ms"]]
            rows.append({"uavs": n, "runs": runs,
                         "flown_median": statistics.median(r["flown"] for r in runs),
                         "offline_median": statistics.median(r["offline"] for r in runs),
                         "ratio_median": statistics.median(r["flown_to_offline"] or 0.0 for r in runs),
                         "traffic_bytes_per_s_median": statistics.median(r["traffic_bytes_per_s"] for r in runs),
                         "decision_ms_median": statistics.median(every_ms) if every_ms else None,
                         "users_served_twice": sum(r["twice"] for r in runs),
                         "fairness_violations": sum(r["fairness_violations"] for r in runs)})
    return {"users": users, "speedup": speedup, "budget_ms": budget_ms, "seeds": seeds, "rows": rows}


def format_fleet_flight(results: dict[str, Any]) -> str:
    lines = [f"fleets flown on loopback (stubs x{results['speedup']:g}, {results['users']} users, "
             f"{results['budget_ms']:g} ms per decision, seeds {results['seeds']}): medians",
             f"{'N':>3} {'flown':>7} {'offline':>8} {'ratio':>6} {'B/s/UAV':>8} {'decision ms':>12} "
             f"{'served by two':>14} {'fairness viol.':>15}"]
    for r in results["rows"]:
        ms = "-" if r["decision_ms_median"] is None else f"{r['decision_ms_median']:.0f}"
        lines.append(f"{r['uavs']:>3} {r['flown_median']:>7.1f} {r['offline_median']:>8.1f} {r['ratio_median']:>6.2f} "
                     f"{r['traffic_bytes_per_s_median']:>8.0f} {ms:>12} {r['users_served_twice']:>14} "
                     f"{r['fairness_violations']:>15}")
    return "\n".join(lines)
