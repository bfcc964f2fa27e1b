"""Run experiments: every sortie they need (shared ones once), then per experiment the CSV
of every point, the figure(s) and the JSON summary with the paper's claims checked."""

from __future__ import annotations

import time
from dataclasses import fields
from pathlib import Path
from typing import Any, Sequence

from ..model import Scenario
from .jobs import Job, Record
from .progress import Progress
from .registry import Experiment, RunConfig
from .results import Results
from .runner import run_jobs
from .writers import write_csv, write_json


def run_experiments(exps: Sequence[Experiment], cfg: RunConfig, out: Path, workers: int,
                    progress: Progress | None = None, provenance: dict[str, Any] | None = None) -> list[Path]:
    """Fly the sorties of ``exps`` on ``workers`` processes and write their files to ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    cache: dict[Job, Record] = {}
    run_jobs([job for e in exps for _, job in e.jobs(cfg)], workers, cache, progress)
    if progress is not None:
        progress.close()
    sorties_s = time.perf_counter() - start
    written: list[Path] = []
    for e in exps:
        res = e.results(cfg, cache)
        written += write_experiment(e, cfg, res, out, {
            **(provenance or {}),
            "workers": workers,
            "sorties_wall_s": sorties_s,
            "experiments_in_run": [x.name for x in exps],
            "sorties_cpu_s": sum(cache[j]["wall_s"] for _, j in e.jobs(cfg)),
        })
    return written


def write_experiment(e: Experiment, cfg: RunConfig, res: Results, out: Path, run: dict[str, Any]) -> list[Path]:
    rows = res.rows(e.name, cfg.base.name)
    claims = e.claims(res)
    figures = e.draw(res, out)
    csv_path = write_csv(rows, out / f"{e.name}.csv")
    summary = {
        "experiment": e.name,
        "title": e.title,
        "paper": e.paper,
        "metric": e.metric,
        "preset": cfg.base.name,
        "quick": cfg.quick,
        "episodes": list(res.episodes),
        "seeds": list(res.seeds),
        "settings": [{"label": s.label, "scenario_name": s.scenario.name, "changes": differences(cfg.base, s.scenario)}
                     for s in res.settings],
        "base_scenario": cfg.base.as_dict(),
        "claims": [c.as_dict() for c in claims],
        "points": rows,
        "paths": {f"{label} / {algo}": {k: rec[k] for k in ("seed", "episodes", "average_reward",
                                                              "throughput_tasks_per_interval")}
                  | {"hover_points": [t["hover_point"] for t in rec["trace"]],
                     "served": [t["user"] for t in rec["trace"]],
                     "tasks": [t["tasks"] for t in rec["trace"]]}
                  for (label, algo), rec in res.paths.items()},
        "files": [p.name for p in (*figures, csv_path)] + [f"{e.name}.json"],
        "run": run,
    }
    if e.summary is not None:
        summary["paired"] = e.summary(res)
    json_path = write_json(summary, out / f"{e.name}.json")
    return [*figures, csv_path, json_path]


def differences(base: Scenario, other: Scenario) -> dict[str, Any]:
    """The fields of ``other`` that differ from ``base`` (a setting's overrides)."""
    a, b = base.as_dict(), other.as_dict()
    return {f.name: b[f.name] for f in fields(Scenario) if a[f.name] != b[f.name]}


__all__ = ["differences", "run_experiments", "write_experiment"]
