"""Compile the planner's kernels into numba's on-disk cache (beside the sources, in
``__pycache__``), so that the first plan of a fresh install, a test or a service just booted
on a companion computer loads them instead of compiling them for a minute or more.

``make`` runs it once after installing. It warms every algorithm on the service's default
scenario (tasks arriving in time) and on the paper's (tasks once per interval), whose
playouts use different kernels; a later run loads them from the cache in seconds."""

from __future__ import annotations

import argparse
import time

HELP = "compile the planner's kernels into numba's cache (make runs it after installing)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quiet", action="store_true", help="print nothing")


def run(args: argparse.Namespace) -> int:
    from ..mcts.planner import MctsConfig
    from ..model import preset
    from ..service.config import build_config
    from ..service.planning import FLIGHT_ALGOS, Planner

    start = time.perf_counter()
    for scenario in (build_config({}, {}).scenario(), preset("paper")):
        for algo in FLIGHT_ALGOS:
            Planner(scenario, MctsConfig(), 0, None, algo).warm_up()
    if not args.quiet:
        print(f"planner kernels compiled or loaded in {time.perf_counter() - start:.1f} s")
    return 0
