"""The fleet experiment's figures (matplotlib, Agg): its metrics against N per planner, and
the paths of one sortie per planner."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless, as the other experiments' plots
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ...model import base_position, hover_points  # noqa: E402
from ...model.fleet import Fleet, uav_scenarios  # noqa: E402
from .analysis import FleetResults  # noqa: E402
from .design import BASELINE  # noqa: E402

DPI = 100
PANELS = (("throughput_tasks_per_interval", "fleet throughput (tasks/interval)"),
          ("per_uav", "throughput per UAV (tasks/interval)"),
          ("average_reward", "average reward (11)"),
          ("jain_index", "Jain index over users' tasks"),
          ("energy_used_j", "fleet energy used (J)"),
          ("diff", f"fleet throughput minus {BASELINE}'s (±2 SE)"))


def plot_metrics(res: FleetResults, out: Path) -> Path:
    """Six panels against N: the fleet's and per UAV's throughput, reward, fairness, energy,
    and each planner's paired difference to the baseline."""
    fig, axes = plt.subplots(2, 3, figsize=(14, 8))
    colors = plt.get_cmap("tab10")
    for ax, (metric, label) in zip(axes.ravel(), PANELS):
        for k, algo in enumerate(res.cfg.planners()):
            ns, ys, es = [], [], []
            for n in res.cfg.uavs:
                if (n, algo, None) not in res.runs:
                    continue
                if metric == "diff":
                    if algo == BASELINE:
                        continue
                    d = res.paired((n, algo, None), (n, BASELINE, None), "throughput_tasks_per_interval")
                    ns.append(n), ys.append(d["mean"]), es.append(2 * d["se"])
                    continue
                key = "throughput_tasks_per_interval" if metric == "per_uav" else metric
                v = np.array(list(res.values(n, algo, key).values())) / (n if metric == "per_uav" else 1)
                ns.append(n), ys.append(v.mean()), es.append(v.std(ddof=1) / np.sqrt(v.size) if v.size > 1 else 0)
            if ns:
                ax.errorbar(ns, ys, yerr=np.nan_to_num(es), marker="o", capsize=3, label=algo, color=colors(k))
        if metric == "diff":
            ax.axhline(0.0, color="gray", linewidth=0.8)
        ax.set_xlabel("UAVs N")
        ax.set_ylabel(label, fontsize=8)
        ax.set_xticks(list(res.cfg.uavs))
        ax.legend(fontsize=7)
    fig.suptitle(f"Fleet on {res.cfg.base.name}: mean ± SE over {len(res.cfg.seeds)} seeds, mcts at "
                 f"{res.cfg.iterations} iterations per UAV decision", fontsize=10)
    fig.tight_layout()
    return _save(fig, out / "fleet.png")


def plot_paths(res: FleetResults, out: Path) -> Path:
    """One sortie per planner (the first seed): each UAV's hovering points in order, from its base."""
    algos = [a for a in res.cfg.planners() if a in res.paths]
    n = res.cfg.paths_uavs()
    fig, axes = plt.subplots(1, len(algos), figsize=(5.5 * len(algos), 5.5), squeeze=False)
    scenario = res.cfg.base
    hp = hover_points(scenario)
    colors = plt.get_cmap("tab10")
    for ax, algo in zip(axes[0], algos):
        rec = res.paths[algo]
        ax.scatter(hp[:, 0], hp[:, 1], marker="^", s=14, color="lightgray", label="hovering points")
        for j, (path, uav_scenario) in enumerate(zip(rec["paths"], uav_scenarios(scenario, Fleet(uavs=n)))):
            xyz = np.array([base_position(uav_scenario)] + path)
            ax.plot(xyz[:, 0], xyz[:, 1], marker="o", markersize=3, color=colors(j), label=f"UAV {j}")
            served = np.array(rec["served_xyz"][j]).reshape(-1, 3)
            ax.scatter(served[:, 0], served[:, 1], marker="x", s=20, color=colors(j))
        ax.set_title(f"{algo}: {rec['throughput_tasks_per_interval']:.1f} tasks/interval, "
                     f"reward {rec['average_reward']:.3f}", fontsize=9)
        ax.set_aspect("equal")
        ax.legend(fontsize=7, loc="lower right")
    fig.suptitle(f"Paths of one sortie per planner: N = {n}, seed {res.cfg.seeds[0]} on {scenario.name} "
                 "(x: users served, where they were)", fontsize=10)
    fig.tight_layout()
    return _save(fig, out / "fleet-paths.png")


def _save(fig, path: Path) -> Path:
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


__all__ = ["plot_metrics", "plot_paths"]
