"""Run the fleet experiment: every sortie on the process pool, then fleet.csv, fleet.png,
fleet-paths.png and fleet.json (the paired differences, their verdicts, the notes) in --out."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from ...fleet import run_fleet_sortie
from ...model.fleet import Fleet
from ...policy import PolicySpec
from ..errors import ExperimentError
from ..progress import Progress
from ..runner import run_jobs
from ..writers import write_csv, write_json
from .analysis import JOINT_TOLERANCE, MARGIN_SE, FleetResults
from .design import BASELINE, REFERENCE, FleetConfig, fleet_jobs
from .jobs import FleetJob, Record, run_fleet_job


def warm_fleet() -> None:
    """Compile (or load from numba's cache) what a fleet sortie runs, before any timed one."""
    from ...model import preset

    for algo in FleetConfig(preset("fleet")).planners():
        if algo != REFERENCE:
            run_fleet_sortie(preset("fleet"), Fleet(uavs=2), algo, 0, PolicySpec(iterations=2))


def run_fleet_experiment(cfg: FleetConfig, out: Path, workers: int, progress: Progress | None = None,
                         provenance: dict[str, Any] | None = None) -> list[Path]:
    """Fly every sortie of ``cfg`` on ``workers`` processes and write the files to ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    cache: dict[FleetJob, Record] = {}
    run_jobs(fleet_jobs(cfg), workers, cache, progress, run=run_fleet_job, warm=warm_fleet)
    if progress is not None:
        progress.close()
    res = FleetResults(cfg, cache)
    try:
        from .figures import plot_metrics, plot_paths
    except ImportError as err:
        raise ExperimentError(f"the figures need matplotlib ({err}): pip install -e '.[experiments]'") from None
    figures = [plot_metrics(res, out), plot_paths(res, out)]
    csv_path = write_csv(res.rows(), out / "fleet.csv")
    summary = {
        "experiment": "fleet",
        "title": "N UAVs over shared users: fleet and per-UAV figures, coordinated planners against independent",
        "paper": "ours (issue 26)",
        "preset": cfg.base.name,
        "quick": cfg.quick,
        "uavs": list(cfg.uavs),
        "seeds": list(cfg.seeds),
        "iterations": cfg.iterations,
        "planners": cfg.planners(),
        "base_scenario": cfg.base.as_dict(),
        "rules": {"margin_standard_errors": MARGIN_SE, "joint_tolerance": JOINT_TOLERANCE,
                  "joint_max_uavs": cfg.joint_max_uavs, "robustness_uavs": cfg.robustness_uavs,
                  "links": [list(link) for link in cfg.links()]},
        f"against_{BASELINE}": res.against(BASELINE),
        f"against_{REFERENCE}": res.against(REFERENCE) if REFERENCE in cfg.planners() else {},
        f"{REFERENCE}_gaps": res.joint_gaps(),
        "robustness": res.robustness(),
        "scaling_over_one_uav": res.scaling(),
        "violations": res.violations(),
        "notes": res.notes(),
        "points": res.rows(),
        "paths": {a: {k: r[k] for k in ("seed", "uavs", "throughput_tasks_per_interval", "average_reward", "paths")}
                  for a, r in res.paths.items()},
        "files": [p.name for p in (*figures, csv_path)] + ["fleet.json"],
        "run": {**(provenance or {}), "workers": workers, "sorties": len(cache),
                "sorties_wall_s": time.perf_counter() - start,
                "sorties_cpu_s": sum(r["wall_s"] for r in cache.values())},
    }
    return [*figures, csv_path, write_json(summary, out / "fleet.json")]


__all__ = ["run_fleet_experiment", "warm_fleet"]
