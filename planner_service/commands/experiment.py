"""Run a figure of the paper (or ``all``): a CSV of every point (mean and 95 % interval over
seeds), a PNG figure and a JSON summary with the paper's claims checked, in --out DIR.

Full form: episodes 10, 30, 100, 300, 1000 and 20 seeds (``all``: about 25 core-minutes per
preset, 12-17 minutes on 2 workers); --quick: episodes 10, 30, 100 and 3 seeds (``all`` in
about 20 s). ``fleet`` (issue 26: N UAVs, on the ``fleet`` preset unless --preset says
otherwise) has no episodes axis and is not part of ``all``: it alone takes longer than all
the paper's quick figures. See docs/EXPERIMENTS.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from ..experiments import (EXPERIMENTS, FULL_EPISODES, FULL_SEEDS, QUICK_EPISODES, QUICK_SEEDS, ExperimentError,
                           Progress, RunConfig, experiment, run_experiments)
from ..experiments.fleet import (FULL_ITERATIONS, FULL_UAVS, QUICK_ITERATIONS, FleetConfig,
                                  run_fleet_experiment)
from ..experiments.fleet import FULL_SEEDS as FULL_FLEET_SEEDS
from ..experiments.fleet import QUICK_SEEDS as QUICK_FLEET_SEEDS
from ..model import HAVE_NUMBA
from .common import add_scenario_arguments, scenario_from_args

HELP = "a figure of the paper (or all), or the fleet's: CSV, PNG and JSON summary"
FLEET = "fleet"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("name", choices=[*EXPERIMENTS, "all", FLEET],
                        help="the experiment, all of the paper's, or fleet (N UAVs; not part of all)")
    parser.add_argument("--out", required=True, type=Path, help="directory for the CSV, PNG and JSON files")
    parser.add_argument("--quick", action="store_true",
                        help=f"small form: episodes {','.join(map(str, QUICK_EPISODES))}, {QUICK_SEEDS} seeds")
    parser.add_argument("--seeds", type=int, default=None,
                        help=f"number of seeds (default {FULL_SEEDS}; {QUICK_SEEDS} with --quick)")
    parser.add_argument("--first-seed", type=int, default=0, help="seeds are first-seed, first-seed + 1, ... (default 0)")
    parser.add_argument("--episodes", default=None, metavar="N,N,...",
                        help=f"the episodes axis (default {','.join(map(str, FULL_EPISODES))})")
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                        help="worker processes (default: min(2, cores)); 1 runs in this process")
    fleet = parser.add_argument_group("fleet", "options of the fleet experiment (docs/EXPERIMENTS.md, \"Fleet\")")
    fleet.add_argument("--uavs", default=None, metavar="N,N,...",
                       help=f"fleet sizes (default {','.join(map(str, FULL_UAVS))}, with --quick too)")
    fleet.add_argument("--iterations", type=int, default=None,
                       help=f"mcts iterations per UAV decision (default {FULL_ITERATIONS}; {QUICK_ITERATIONS} "
                            f"with --quick); seeds default {FULL_FLEET_SEEDS} ({QUICK_FLEET_SEEDS} with --quick)")
    fleet.add_argument("--joint-max-uavs", type=int, default=None,
                       help="fly the joint planner (where registered) up to this N (default 3) and where its "
                            "K^N joint actions fit (at most 10000)")
    add_scenario_arguments(parser, default=None, default_help="paper; fleet for the fleet experiment")


def run(args: argparse.Namespace) -> int:
    if args.name == FLEET:
        args.preset = args.preset or "fleet"
        return _run_fleet(args)
    args.preset = args.preset or "paper"
    given = [o for o, v in (("--uavs", args.uavs), ("--iterations", args.iterations),
                            ("--joint-max-uavs", args.joint_max_uavs)) if v is not None]
    if given:
        print(f"error: {', '.join(given)} only apply to the fleet experiment (the paper's figures take --episodes)",
              file=sys.stderr)
        return 2
    try:
        cfg = _config(args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    exps = list(EXPERIMENTS.values()) if args.name == "all" else [experiment(args.name)]
    start = time.perf_counter()
    progress = Progress(0, f"{args.name} ({cfg.base.name})")
    try:
        written = run_experiments(exps, cfg, args.out, max(args.workers, 1), progress, _provenance())
    except ExperimentError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    wall = time.perf_counter() - start
    for path in written:
        print(path)
    print(f"{args.name}: {len(exps)} experiment(s) on {cfg.base.name}, {len(cfg.seeds)} seeds, "
          f"episodes {list(cfg.episodes)}, {wall:.1f} s wall on {args.workers} worker(s)", file=sys.stderr)
    return 0


def _run_fleet(args: argparse.Namespace) -> int:
    try:
        cfg = _fleet_config(args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    start = time.perf_counter()
    try:
        written = run_fleet_experiment(cfg, args.out, max(args.workers, 1), Progress(0, f"fleet ({cfg.base.name})"),
                                       _provenance())
    except ExperimentError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    for path in written:
        print(path)
    print(f"fleet: N = {list(cfg.uavs)}, planners {cfg.planners()} on {cfg.base.name}, {len(cfg.seeds)} seeds, "
          f"{cfg.iterations} iterations, {time.perf_counter() - start:.1f} s wall on {args.workers} worker(s)",
          file=sys.stderr)
    return 0


def _fleet_config(args: argparse.Namespace) -> FleetConfig:
    if args.episodes is not None:
        raise ValueError("--episodes does not apply to the fleet experiment (give --iterations)")
    if args.uavs is not None:
        try:
            uavs = tuple(int(x) for x in args.uavs.split(","))
        except ValueError:
            raise ValueError(f"--uavs must be integers separated by commas, got {args.uavs!r}") from None
        if not uavs or min(uavs) < 1 or max(uavs) > 16 or len(set(uavs)) != len(uavs):
            raise ValueError(f"--uavs must be distinct fleet sizes from 1 to 16, got {args.uavs!r}")
    else:
        uavs = FULL_UAVS
    seeds = args.seeds if args.seeds is not None else (QUICK_FLEET_SEEDS if args.quick else FULL_FLEET_SEEDS)
    if seeds < 1:
        raise ValueError("--seeds must be at least 1")
    iterations = args.iterations if args.iterations is not None else (QUICK_ITERATIONS if args.quick else FULL_ITERATIONS)
    if iterations < 1:
        raise ValueError("--iterations must be at least 1")
    joint_max = 3 if args.joint_max_uavs is None else args.joint_max_uavs
    if joint_max < 1:
        raise ValueError("--joint-max-uavs must be at least 1")
    return FleetConfig(base=scenario_from_args(args), uavs=tuple(sorted(uavs)),
                       seeds=tuple(range(args.first_seed, args.first_seed + seeds)), iterations=iterations,
                       joint_max_uavs=joint_max, robustness_uavs=3 if 3 in uavs else max(uavs),
                       quick=args.quick)


def _config(args: argparse.Namespace) -> RunConfig:
    if args.episodes is not None:
        try:
            episodes = tuple(int(x) for x in args.episodes.split(","))
        except ValueError:
            raise ValueError(f"--episodes must be integers separated by commas, got {args.episodes!r}") from None
    else:
        episodes = QUICK_EPISODES if args.quick else FULL_EPISODES
    if not episodes or min(episodes) < 1 or len(set(episodes)) != len(episodes):
        raise ValueError("--episodes must be distinct positive integers")
    seeds = args.seeds if args.seeds is not None else (QUICK_SEEDS if args.quick else FULL_SEEDS)
    if seeds < 1:
        raise ValueError("--seeds must be at least 1")
    base = scenario_from_args(args)
    return RunConfig(base=base, episodes=tuple(sorted(episodes)),
                     seeds=tuple(range(args.first_seed, args.first_seed + seeds)), quick=args.quick)


def _provenance() -> dict[str, Any]:
    """Where the numbers came from: the command, the commit (and whether the planner code
    differed from it), the machine."""
    repo = Path(__file__).resolve().parents[2]

    def git(*cmd: str) -> str:
        try:
            return subprocess.run(["git", *cmd], cwd=repo, capture_output=True, text=True, timeout=10).stdout.strip()
        except (OSError, subprocess.SubprocessError):
            return ""

    return {
        "command": "python -m planner_service " + " ".join(sys.argv[1:]),
        "commit": git("rev-parse", "HEAD"),
        "uncommitted_planner_changes": git("status", "--porcelain", "--", "planner_service/model", "planner_service/mcts",
                                           "planner_service/baselines", "planner_service/policy.py",
                                           "planner_service/registry.py", "planner_service/sortie.py").splitlines(),
        "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "numba": HAVE_NUMBA,
        "cores": os.cpu_count(),
    }
