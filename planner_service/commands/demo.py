"""The main job: vehicle stub, simulated users and the service on loopback, one sortie."""

from __future__ import annotations

import argparse
import sys

HELP = "the main job on the embedded default (writes summary.json, trajectory.png, mission.plan)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo-out", help="output folder (default: demo-out)")


def run(args: argparse.Namespace) -> int:
    print("demo: not yet built (the service lands with issue 7); try:", file=sys.stderr)
    print("  python -m planner_service plan --algo greedy --seed 1", file=sys.stderr)
    return 0
