"""Fly one simulated sortie with a planner, without I/O, and print its summary."""

from __future__ import annotations

import argparse
import json
import sys

from ..policy import PolicySpec
from ..registry import algorithms
from ..sortie import run_sortie
from .common import add_scenario_arguments, scenario_from_args

HELP = "one simulated sortie without I/O; JSON summary with --json"


def configure(parser: argparse.ArgumentParser) -> None:
    add_scenario_arguments(parser)
    parser.add_argument("--algo", default="mcts", choices=algorithms(), help="planner (default: mcts)")
    parser.add_argument("--iterations", type=int, default=None,
                        help="MCTS iterations per decision, or training episodes for ql/dqn (default: 1000, "
                             "or no limit when --budget-ms is given)")
    parser.add_argument("--budget-ms", type=float, default=None,
                        help="wall-clock budget per mcts decision in ms (anytime); with --iterations, whichever ends first")
    parser.add_argument("--seed", type=int, default=0, help="seed of the world and the planner (default: 0)")
    parser.add_argument("--json", action="store_true", help="print the full JSON summary (with scenario and trace)")


def run(args: argparse.Namespace) -> int:
    if args.iterations is None and args.budget_ms is None:
        args.iterations = 1000
    if args.iterations is not None and args.iterations < 1:
        print("error: --iterations must be at least 1", file=sys.stderr)
        return 2
    if args.budget_ms is not None and not args.budget_ms > 0:
        print("error: --budget-ms must be positive", file=sys.stderr)
        return 2
    scenario = scenario_from_args(args)
    try:
        summary = run_sortie(scenario, args.algo, args.seed, PolicySpec(args.iterations, args.budget_ms))
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.json:
        json.dump(summary, sys.stdout, indent=1)
        print()
        return 0
    print(f"{args.algo} on {scenario.name}, seed {args.seed}: {summary['intervals']} intervals")
    print(f"  throughput      {summary['throughput_tasks_per_interval']:.2f} tasks/interval "
          f"({summary['throughput_bits_per_interval'] / 1e6:.2f} Mbit/interval)")
    print(f"  average reward  {summary['average_reward']:.4f}")
    print(f"  energy          {summary['energy_used_j'] / 1e3:.1f} of {summary['energy_budget_j'] / 1e3:.1f} kJ")
    print(f"  path            {summary['hover_points']}")
    print(f"  served users    {summary['served']}")
    print(f"  violations      fairness {summary['fairness_violations']}, energy {summary['energy_violation']}")
    print(f"  wall time       {summary['wall_s']:.3f} s")
    return 0
