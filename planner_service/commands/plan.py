"""Fly one simulated sortie with a planner, without I/O, and print its summary; with
``--uavs N``, a fleet's sortie (docs/MODEL.md, "A fleet"; docs/PLANNER.md, "A fleet's
planners") with per-UAV and fleet figures."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from ..fleet import fleet_algorithms, run_fleet_sortie
from ..fleet.policies import BASES
from ..model import Scenario, ScenarioError
from ..model.fleet import Fleet
from ..policy import PolicySpec
from ..registry import algorithms
from ..sortie import run_sortie
from .common import add_scenario_arguments, scenario_from_args

HELP = "one simulated sortie without I/O (a fleet's with --uavs N); JSON summary with --json"


def configure(parser: argparse.ArgumentParser) -> None:
    add_scenario_arguments(parser)
    parser.add_argument("--algo", default=None, choices=algorithms() + fleet_algorithms(),
                        help="planner (default: mcts; with --uavs a fleet planner, default independent: "
                             "independent, claims, dec-mcts (each UAV planned by --base) or joint)")
    parser.add_argument("--uavs", type=int, default=None, metavar="N",
                        help="fly a fleet of N UAVs over the same users (1-16); a fleet of 1 is the sortie without it")
    parser.add_argument("--base", default="mcts", choices=BASES,
                        help="with --uavs: each UAV's own planner (default: mcts)")
    parser.add_argument("--layer-m", type=float, default=Fleet.layer_m,
                        help=f"with --uavs: UAV j flies j * this many metres above the scenario's altitude "
                             f"(default: {Fleet.layer_m:g})")
    parser.add_argument("--base-step-m", type=float, default=Fleet.base_step_m,
                        help="with --uavs: UAV j's base lies j * this many metres east of the scenario's "
                             f"(default: {Fleet.base_step_m:g}, one ground station)")
    parser.add_argument("--msg-drop", type=float, default=None, metavar="P",
                        help="with --algo dec-mcts: probability that a UAV's message misses a given other UAV "
                             "(default: 0)")
    parser.add_argument("--msg-age", type=int, default=None, metavar="N",
                        help="with --algo dec-mcts: messages arrive N of the sender's intervals late (default: 0)")
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
    spec = PolicySpec(args.iterations, args.budget_ms)
    if args.uavs is not None:
        return _run_fleet(args, scenario, spec)
    algo = args.algo or "mcts"
    if algo in fleet_algorithms():
        print(f"error: --algo {algo} plans a fleet: give --uavs N", file=sys.stderr)
        return 2
    try:
        summary = run_sortie(scenario, algo, args.seed, spec)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.json:
        json.dump(summary, sys.stdout, indent=1)
        print()
        return 0
    print(f"{algo} on {scenario.name}, seed {args.seed}: {summary['intervals']} intervals")
    print(f"  throughput      {summary['throughput_tasks_per_interval']:.2f} tasks/interval "
          f"({summary['throughput_bits_per_interval'] / 1e6:.2f} Mbit/interval)")
    print(f"  average reward  {summary['average_reward']:.4f}")
    print(f"  energy          {summary['energy_used_j'] / 1e3:.1f} of {summary['energy_budget_j'] / 1e3:.1f} kJ")
    print(f"  path            {summary['hover_points']}")
    print(f"  served users    {summary['served']}")
    print(f"  violations      fairness {summary['fairness_violations']}, energy {summary['energy_violation']}")
    print(f"  wall time       {summary['wall_s']:.3f} s")
    return 0


def _run_fleet(args: argparse.Namespace, scenario: Scenario, spec: PolicySpec) -> int:
    algo = args.algo or "independent"
    if algo not in fleet_algorithms():
        print(f"error: --algo {algo} plans one UAV; with --uavs choose from {fleet_algorithms()} "
              f"(each UAV's own planner: --base)", file=sys.stderr)
        return 2
    settings = {k: v for k, v in (("drop", args.msg_drop), ("age", args.msg_age)) if v is not None}
    if settings and algo != "dec-mcts":
        print("error: --msg-drop and --msg-age are dec-mcts's messages: give --algo dec-mcts", file=sys.stderr)
        return 2
    try:
        fleet = Fleet(uavs=args.uavs, layer_m=args.layer_m, base_step_m=args.base_step_m)
        summary = run_fleet_sortie(scenario, fleet, algo, args.seed, spec, base=args.base, settings=settings)
    except ScenarioError as err:
        option = {"uavs": "--uavs", "layer_m": "--layer-m", "base_step_m": "--base-step-m"}.get(err.field)
        print(f"error: {option + ': ' if option else ''}{err}", file=sys.stderr)
        return 2
    except ValueError as err:
        option = next((o for k, o in (("drop", "--msg-drop"), ("age", "--msg-age")) if str(err).startswith(k)), None)
        print(f"error: {option + ': ' if option else ''}{err}", file=sys.stderr)
        return 2
    if args.json:
        json.dump(summary, sys.stdout, indent=1)
        print()
        return 0
    _print_fleet(summary, scenario)
    return 0


def _print_fleet(summary: dict[str, Any], scenario: Scenario) -> None:
    f = summary["fleet"]
    print(f"{summary['algo']} ({summary['base']} per UAV) on {scenario.name}, {summary['uavs']} UAVs, "
          f"seed {summary['seed']}: {f['intervals']} intervals")
    print(f"  {'UAV':>4} {'intervals':>9} {'tasks/int':>9} {'tasks':>6} {'reward':>7} {'energy kJ':>9} "
          f"{'fairness':>8}  ended")
    for u in summary["per_uav"]:
        print(f"  {u['uav']:>4} {u['intervals']:>9} {u['throughput_tasks_per_interval']:>9.2f} {u['total_tasks']:>6} "
              f"{u['average_reward']:>7.4f} {u['energy_used_j'] / 1e3:>9.1f} {u['fairness_violations']:>8}  "
              f"{u['ended']}")
    print(f"  fleet throughput  {f['throughput_tasks_per_interval']:.2f} tasks/interval (sum over the UAVs), "
          f"{f['total_tasks']} tasks in all")
    print(f"  average reward    {f['average_reward']:.4f} (every interval flown)")
    print(f"  energy            {f['energy_used_j'] / 1e3:.1f} kJ; energy violations {f['energy_violations']}")
    print(f"  services          {f['services']} to {f['users_served']} users; fairness violations "
          f"{f['fairness_violations']}")
    print(f"  double services   {f['double_services']}, double holds {f['double_holds']}, blocked choices "
          f"{f['blocked_choices']}")
    if "messages" in f:
        print(f"  messages          {f['messages']}, at most {f['message_bytes_max']} bytes")
    print(f"  wall time         {summary['wall_s']:.3f} s")
