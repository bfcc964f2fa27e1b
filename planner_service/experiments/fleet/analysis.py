"""The fleet experiment's numbers from its sorties: a row per (N, planner, link) with the
mean and standard error over seeds, the paired differences and their verdicts. Pure: no
I/O, no plotting."""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ...fleet import MAX_JOINT_ACTIONS
from .design import BASELINE, REFERENCE, FleetConfig
from .jobs import FLEET_METRICS, FleetJob, Record

COMPARED = ("throughput_tasks_per_interval", "total_tasks", "average_reward", "jain_index", "energy_used_j")
"""The metrics whose paired differences are reported."""
MARGIN_SE = 2.0
"""A difference counts (``ahead``/``behind``) when its mean is more than this many standard
errors from 0: the issue's target for ``dec-mcts`` against ``independent``."""
JOINT_TOLERANCE = 0.05
"""A planner is "within" ``joint`` when its mean fleet throughput is within 5 % of joint's."""
NO_LINK = (0.0, 0)


def mean_se(values: Sequence[float]) -> dict[str, float | int]:
    """Mean, standard error (s / sqrt(n); nan for one value) and n."""
    x = np.asarray(values, dtype=np.float64)
    n = int(x.size)
    if n == 0:
        return {"mean": math.nan, "se": math.nan, "n": 0}
    se = float(x.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    return {"mean": float(x.mean()), "se": se, "n": n}


def verdict(diff: dict[str, float | int]) -> str:
    """``ahead`` / ``behind`` when the mean is beyond ``MARGIN_SE`` standard errors, else
    ``within noise`` (and ``one seed`` when there is no standard error)."""
    mean, se = float(diff["mean"]), float(diff["se"])
    if not math.isfinite(se):
        return "one seed"
    if mean > MARGIN_SE * se:
        return "ahead"
    if mean < -MARGIN_SE * se:
        return "behind"
    return "within noise"


class FleetResults:
    """The records of one run, looked up by (N, planner, link) and seed."""

    def __init__(self, cfg: FleetConfig, cache: dict[FleetJob, Record]) -> None:
        self.cfg = cfg
        self.runs: dict[tuple[int, str, tuple[float, int] | None], dict[int, Record]] = {}
        self.paths: dict[str, Record] = {}
        for job, rec in cache.items():
            if job.record_paths:
                self.paths[job.algo] = rec
            else:
                self.runs.setdefault((job.uavs, job.algo, job.link), {})[job.seed] = rec

    def values(self, n: int, algo: str, metric: str, link: tuple[float, int] | None = None) -> dict[int, float]:
        return {s: float(r[metric]) for s, r in self.runs.get((n, algo, link), {}).items()}

    def paired(self, a: tuple[int, str, Any], b: tuple[int, str, Any], metric: str) -> dict[str, Any]:
        """Mean difference a - b over the seeds both flew, with its standard error."""
        va, vb = self.values(*a[:2], metric, a[2]), self.values(*b[:2], metric, b[2])
        seeds = sorted(set(va) & set(vb))
        d = mean_se([va[s] - vb[s] for s in seeds])
        return {**d, "verdict": verdict(d)}

    def rows(self) -> list[dict[str, Any]]:
        """One row per (N, planner, link): each metric's mean and standard error, and the mean
        per-UAV throughput of each UAV (';'-separated, UAV 0 first)."""
        out = []
        for (n, algo, link), recs in sorted(self.runs.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2] or NO_LINK)):
            row: dict[str, Any] = {"uavs": n, "planner": algo,
                                   "loss": "" if link is None else link[0], "late_intervals": "" if link is None else link[1],
                                   "seeds": len(recs)}
            for m in FLEET_METRICS:
                ms = mean_se([r[m] for r in recs.values()])
                row[m], row[f"{m}_se"] = ms["mean"], ms["se"]
            per_uav = np.mean([r["per_uav_throughput"] for r in recs.values()], axis=0)
            row["per_uav_throughput"] = ";".join(f"{x:.3f}" for x in per_uav)
            row["message_bytes_max"] = max(int(r["message_bytes_max"]) for r in recs.values())
            out.append(row)
        return out

    def against(self, other: str) -> dict[str, Any]:
        """Every other planner minus ``other``, per N, paired per seed, for each compared metric."""
        out: dict[str, Any] = {}
        for algo in self.cfg.planners():
            if algo == other:
                continue
            for n in self.cfg.uavs:
                if (n, algo, None) in self.runs and (n, other, None) in self.runs:
                    out.setdefault(algo, {})[f"N={n}"] = {
                        m: self.paired((n, algo, None), (n, other, None), m) for m in COMPARED}
        return out

    def joint_gaps(self) -> dict[str, Any]:
        """Each planner's mean fleet throughput relative to ``joint``'s, where joint flew."""
        out: dict[str, Any] = {}
        metric = COMPARED[0]
        for algo in self.cfg.planners():
            for n in self.cfg.uavs:
                ref = self.values(n, REFERENCE, metric)
                mine = self.values(n, algo, metric)
                if algo == REFERENCE or not ref or not mine:
                    continue
                gap = float(np.mean(list(mine.values())) / np.mean(list(ref.values())) - 1.0)
                out.setdefault(algo, {})[f"N={n}"] = {"relative_gap": gap, "within_5pct": abs(gap) <= JOINT_TOLERANCE}
        return out

    def robustness(self) -> dict[str, Any]:
        """Per message-passing planner and link: fleet throughput minus the same planner's on a
        perfect link, and minus ``independent``'s, paired per seed, at ``robustness_uavs``."""
        n = self.cfg.robustness_uavs
        metric = COMPARED[0]
        out: dict[str, Any] = {}
        for algo in self.cfg.link_planners():
            for link in self.cfg.links():
                if (n, algo, link) not in self.runs:
                    continue
                out.setdefault(algo, {})[f"loss={link[0]:g} late={link[1]}"] = {
                    "throughput": mean_se(list(self.values(n, algo, metric, link).values())),
                    "minus_perfect_link": self.paired((n, algo, link), (n, algo, NO_LINK), metric),
                    f"minus_{BASELINE}": self.paired((n, algo, link), (n, BASELINE, None), metric),
                }
        return out

    def scaling(self) -> dict[str, Any]:
        """Per planner: fleet throughput at each N over N = 1's, per seed (the issue's 2.4x at N = 3)."""
        out: dict[str, Any] = {}
        metric = COMPARED[0]
        for algo in self.cfg.planners():
            one = self.values(1, algo, metric)
            for n in self.cfg.uavs:
                mine = self.values(n, algo, metric)
                seeds = sorted(set(one) & set(mine))
                if n != 1 and seeds:
                    out.setdefault(algo, {})[f"N={n}"] = mean_se([mine[s] / one[s] for s in seeds])
        return out

    def violations(self) -> dict[str, int]:
        """Double services, double holds, fairness violations over every sortie (the target: 0)."""
        recs = [r for runs in self.runs.values() for r in runs.values()]
        return {m: int(sum(r[m] for r in recs)) for m in ("double_services", "double_holds", "fairness_violations")}

    def notes(self) -> list[str]:
        """What was not run, and why (read with the summary)."""
        notes = []
        if REFERENCE not in self.cfg.planners():
            notes.append(f"'{REFERENCE}' is not in the fleet planner registry yet: no comparison with it.")
        else:
            flown = [n for n in self.cfg.uavs if self.cfg.flies(REFERENCE, n)]
            notes.append(f"'{REFERENCE}' flown at N = {flown}: up to {self.cfg.joint_max_uavs} (--joint-max-uavs) "
                         f"and where K^N = {self.cfg.base.num_hover_points}^N joint actions fit "
                         f"({MAX_JOINT_ACTIONS}).")
        if not self.cfg.link_planners():
            notes.append("No registered fleet planner takes a message link (loss, lateness) yet: the robustness "
                         "sweep (loss 0/20/50 %, late 1-3 intervals) was skipped.")
        return notes


__all__ = ["COMPARED", "FleetResults", "JOINT_TOLERANCE", "MARGIN_SE", "mean_se", "verdict"]
