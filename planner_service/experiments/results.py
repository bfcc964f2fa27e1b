"""An experiment's results: the records by (setting, algorithm, episodes, seed), the
aggregated points (mean and 95 % interval over seeds), and paired differences.

The same seed gives every algorithm the same world (the world's draws do not depend on the
actions), and every setting the same generator streams, so differences between two curves
are taken seed by seed (common random numbers) and their interval is that of the paired
differences: much tighter than comparing two independent intervals.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from .errors import ExperimentError
from .jobs import METRICS, STATIC, Record, Setting
from .stats import Interval, mean_interval

Key = tuple[str, str, "int | None"]
"""(setting label, algorithm, episodes); episodes is None for ``STATIC`` algorithms."""


@dataclass
class Results:
    """What an experiment measured, indexed for plots and claims."""

    settings: list[Setting]
    algos: Sequence[str]
    episodes: tuple[int, ...]
    seeds: tuple[int, ...]
    records: dict[Key, dict[int, Record]] = field(default_factory=dict)
    paths: dict[tuple[str, str], Record] = field(default_factory=dict)
    """(setting label, algorithm) -> the recorded sortie of the figure's seed."""

    def add(self, label: str, record: Record) -> None:
        key = (label, record["algo"], record["episodes"])
        self.records.setdefault(key, {})[record["seed"]] = record

    @property
    def labels(self) -> list[str]:
        return [s.label for s in self.settings]

    @property
    def top(self) -> int:
        """The largest episodes count (where the paper reads its "converged" values)."""
        return max(self.episodes)

    def key(self, label: str, algo: str, episodes: int | None) -> Key:
        return (label, algo, None if algo in STATIC else episodes)

    def values(self, label: str, algo: str, episodes: int | None, metric: str) -> dict[int, float]:
        """seed -> metric for one point."""
        key = self.key(label, algo, episodes)
        if key not in self.records:
            raise ExperimentError(f"no results for {key}")
        return {seed: float(r[metric]) for seed, r in self.records[key].items()}

    def point(self, label: str, algo: str, episodes: int | None, metric: str) -> Interval:
        return mean_interval(list(self.values(label, algo, episodes, metric).values()))

    def paired(self, a: Key, b: Key, metric: str,
               combine: Callable[[float, float], float] = lambda x, y: x - y) -> Interval:
        """Interval of combine(a, b) taken seed by seed over the seeds both have."""
        va, vb = self.values(*a, metric), self.values(*b, metric)
        seeds = sorted(set(va) & set(vb))
        return mean_interval([combine(va[s], vb[s]) for s in seeds])

    def per_seed(self, fn: Callable[[int], float]) -> Interval:
        """Interval of any per-seed statistic (for differences of differences)."""
        return mean_interval([fn(s) for s in self.seeds])

    def rows(self, experiment: str, preset: str) -> list[dict[str, Any]]:
        """One row per point: every metric's mean and 95 % interval over seeds."""
        out = []
        for setting in self.settings:
            for algo in self.algos:
                for n in ([None] if algo in STATIC else list(self.episodes)):
                    key = (setting.label, algo, n)
                    if key not in self.records:
                        continue
                    row: dict[str, Any] = {"experiment": experiment, "preset": preset, "setting": setting.label,
                                           "algo": algo, "episodes": "" if n is None else n,
                                           "seeds": len(self.records[key])}
                    for m in METRICS:
                        iv = self.point(setting.label, algo, n, m)
                        row[f"{m}_mean"], row[f"{m}_lo"], row[f"{m}_hi"] = iv.mean, iv.lo, iv.hi
                    out.append(row)
        return out

    def curve(self, label: str, algo: str, metric: str) -> tuple[np.ndarray, list[Interval]]:
        """x (episodes) and the intervals of one algorithm's curve in one setting."""
        xs = np.array(self.episodes, dtype=float)
        return xs, [self.point(label, algo, n, metric) for n in self.episodes]


__all__ = ["Key", "Results"]
