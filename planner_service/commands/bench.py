"""Performance figures: mcts decision latency (median, p99) and playouts per second at the
paper's size (K=20, I=10) and larger, with a plain pure-Python reference timed in the same
run so the speed-up is a ratio; with --fleet, the fleet planners' decision time per UAV and
message size. Figures, not pass/fail: run it on a quiet machine."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HELP = "performance figures: decision latency, playouts/s, speed-up over a plain reference"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the figures as JSON")
    parser.add_argument("--decisions", type=int, default=None,
                        help="decisions timed at each size (default: 50 at K=20 and K=40, 20 at K=200, 10 at K=400)")
    parser.add_argument("--iterations", type=int, default=1000, help="MCTS iterations per decision (default: 1000)")
    parser.add_argument("--reference-decisions", type=int, default=5, help="decisions timed with the pure-Python reference (default: 5; 0 skips it)")
    parser.add_argument("--quick", action="store_true", help="only the paper's size")
    parser.add_argument("--e2e", action="store_true",
                        help="instead: end-to-end latency on loopback, request -> mission accepted by the vehicle stub "
                             "(real service and stub processes; the planner's time excluded)")
    parser.add_argument("--web", action="store_true",
                        help="with --e2e: the same figures without and with the live map open (operator web in its own "
                             "process, the page in headless Chromium where found), alternating rounds in one run; the "
                             "ratio with / without (use --e2e-requests 800 or more: p99 needs samples)")
    parser.add_argument("--e2e-requests", type=int, default=200, help="requests timed with --e2e (default: 200)")
    parser.add_argument("--e2e-budget-ms", type=float, default=20.0, help="planner budget with --e2e (default: 20)")
    parser.add_argument("--link", action="store_true",
                        help="instead: mission upload time over a lossy MAVLink link at 0, 5 and 20 %% loss each way "
                             "(the service's link -> sim_bridge lossy-proxy -> vehicle stub; median, p90, failures, "
                             "ratio to the clean link); with --quick 10 uploads per rate (about 30 s), else "
                             "--link-uploads")
    parser.add_argument("--link-uploads", type=int, default=50, help="uploads per loss rate with --link (default: 50)")
    parser.add_argument("--flight", action="store_true",
                        help="instead: the same seeded world flown through the service (stub, simulated users, "
                             "real processes) and planned offline, side by side per algorithm: tasks/interval, "
                             "reward, tasks per sortie, services of the planned request, decisions per service "
                             "(medians over --seeds; with --quick 2 seeds and mcts only); also offline in a "
                             "world whose tasks arrive in time as the simulated users' do (timed)")
    parser.add_argument("--offline-only", action="store_true",
                        help="with --flight: plan the two offline worlds only, no flights (seconds per seed), "
                             "mcts on --iterations per decision (the same decisions every run) instead of the clock")
    parser.add_argument("--seeds", type=seed_range, default="1-12", metavar="A-B",
                        help="seeds with --flight (default 1-12: one seed's flight differs from another's by more "
                             "than one planner's from another's; 3 algorithms take about 16 minutes)")
    parser.add_argument("--algos", default="mcts,greedy,random", help="algorithms with --flight (default mcts,greedy,random)")
    parser.add_argument("--speedup", type=float, default=None,
                        help="the stubs' speed-up with --flight (default 25) or --scale (default 2.5: the radios' "
                             "delays are wall time, so a faster flight meets them as longer; twenty services "
                             "flew 0.57-0.88 of the offline plan at x10, 0.58-0.98 at x5, 0.87-0.94 at x2.5)")
    parser.add_argument("--budget-ms", type=float, default=150.0, help="planner budget with --flight (default 150)")
    parser.add_argument("--fleet", action="store_true",
                        help="instead: every fleet planner's decision time per UAV (median, p95) and message size "
                             "for N = 3 and 5 at K=20/I=10 and K=200/I=1000, --iterations per decision "
                             "(--decisions each, default 30; with --quick the paper's size only, 10 decisions); "
                             "with --flight: fleets of --uavs flown on loopback against the offline fleet planner, "
                             "the traffic each UAV sends and the decision time (medians over --seeds; --quick: 1 seed)")
    parser.add_argument("--scale", action="store_true",
                        help="with --fleet: fleets of --uavs (default 5,10,20) flown past one machine's loopback: each "
                             "UAV's computer, each router and the ground station a network namespace, the UAVs' "
                             "radios emulated (--delay-ms, --jitter-ms, --loss) and one cut mid-sortie; traffic per UAV, "
                             "intentions heard, served by two, holds of two, agreement after the cut, CPU and memory, "
                             "flown/offline, and the traffic's model in N (needs root; docs/PERFORMANCE.md)")
    parser.add_argument("--uavs", default=None, metavar="N,N,...",
                        help="fleet sizes with --fleet --flight (default 1,2,3) or --fleet --scale (default 5,10,20)")
    parser.add_argument("--delay-ms", type=float, default=100.0, help="with --scale: the radios' one-way delay (default 100)")
    parser.add_argument("--jitter-ms", type=float, default=10.0, help="with --scale: its uniform spread (default 10)")
    parser.add_argument("--loss", type=float, default=0.05, help="with --scale: each packet's loss probability (default 0.05)")
    parser.add_argument("--users-per-uav", type=int, default=4, help="with --scale: simulated users per UAV (default 4)")
    parser.add_argument("--cut-at-s", type=float, default=20.0,
                        help="with --scale: uav1's radio cut this many seconds after the users begin (default 20)")
    parser.add_argument("--cut-for-s", type=float, default=15.0,
                        help="with --scale: ... and restored this much later (default 15: longer than zenoh's 10 s lease)")
    parser.add_argument("--zenoh-mode", choices=("client", "peer"), default="client",
                        help="with --scale: the services' zenoh mode (default client: each UAV links to one ground "
                             "router; peer: each also links to every other UAV it hears of, over the radios)")
    parser.add_argument("--keep", default=None, metavar="DIR", help="with --scale: keep every log and journal in DIR")
    parser.add_argument("--users", type=int, default=12, help="simulated users with --fleet --flight (default 12)")


def seed_range(text: str) -> list[int]:
    """``A-B`` (or ``A``): the seeds A to B."""
    lo, _, hi = text.partition("-")
    try:
        seeds = list(range(int(lo), int(hi or lo) + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not A-B") from None
    if not seeds:
        raise argparse.ArgumentTypeError(f"{text!r}: no seed from A to B")
    return seeds


def run(args: argparse.Namespace) -> int:
    if args.speedup is None:
        args.speedup = 2.5 if args.scale else 25.0
    if args.web and not args.e2e:
        print("error: --web goes with --e2e (the end-to-end latency without and with the live map open)",
              file=sys.stderr)
        return 2
    if args.e2e:
        return _run_e2e(args)
    if args.link:
        return _run_link(args)
    if args.scale and not args.fleet:
        print("error: --scale goes with --fleet (fleets past one machine)", file=sys.stderr)
        return 2
    if args.fleet and args.scale:
        return _run_fleet_scale(args)
    if args.fleet and args.flight:
        return _run_fleet_flight(args)
    if args.flight:
        return _run_flight(args)
    if args.fleet:
        return _run_fleet(args)
    from ..bench.run import SIZES, format_table, run_bench

    if (args.decisions is not None and args.decisions < 1) or args.iterations < 1 or args.reference_decisions < 0:
        print("error: --decisions and --iterations must be at least 1", file=sys.stderr)
        return 2
    sizes = SIZES[:1] if args.quick else SIZES
    results = run_bench(args.decisions, args.iterations, args.reference_decisions, sizes,
                        progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    print(json.dumps(results, indent=1) if args.json else format_table(results))
    return 0


def _run_fleet(args: argparse.Namespace) -> int:
    from ..bench.fleet import SIZES, format_fleet, run_fleet_bench

    decisions = args.decisions if args.decisions is not None else (10 if args.quick else 30)
    if decisions < 1 or args.iterations < 1:
        print("error: --decisions and --iterations must be at least 1", file=sys.stderr)
        return 2
    results = run_fleet_bench(decisions, args.iterations, SIZES[:1] if args.quick else SIZES,
                              progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    print(json.dumps(results, indent=1) if args.json else format_fleet(results))
    return 0


def _run_e2e(args: argparse.Namespace) -> int:
    from ..bench.e2e import format_e2e, run_e2e

    if args.e2e_requests < 1 or not args.e2e_budget_ms > 0:
        print("error: --e2e-requests must be at least 1 and --e2e-budget-ms positive", file=sys.stderr)
        return 2
    progress = lambda msg: print(msg, file=sys.stderr, flush=True)  # noqa: E731
    if args.web:
        from ..bench.e2e import format_e2e_with_page, run_e2e_with_page

        both = run_e2e_with_page(args.e2e_requests, args.e2e_budget_ms, progress=progress)
        print(json.dumps(both, indent=1) if args.json else format_e2e_with_page(both))
        return 0
    results = run_e2e(args.e2e_requests, args.e2e_budget_ms, progress=progress)
    for samples in ("e2e_samples", "ack_samples"):
        del results[samples]
    print(json.dumps(results, indent=1) if args.json else format_e2e(results))
    return 0


def _run_link(args: argparse.Namespace) -> int:
    from ..bench.link import format_link, run_link_bench

    uploads = 10 if args.quick else args.link_uploads
    if uploads < 1:
        print("error: --link-uploads must be at least 1", file=sys.stderr)
        return 2
    results = run_link_bench(uploads, progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    print(json.dumps(results, indent=1) if args.json else format_link(results))
    return 0


def uav_counts(text: str) -> list[int] | None:
    try:
        return [int(n) for n in text.split(",") if n]
    except ValueError:
        print(f"error: --uavs {text!r} is not a number list", file=sys.stderr)
        return None


def fleet_sizes(text: str | None, default: str, most: int, users: int, users_flag: str,
                speedup: float) -> list[int] | None:
    """The fleet sizes ``--uavs`` asks for (``default`` without it), or None once the error
    is said: each 1 to ``most``, the users (``users_flag``) and the speed-up positive."""
    counts = uav_counts(text or default)
    if counts is None:
        return None
    if not counts or any(not 1 <= n <= most for n in counts) or users < 1 or not speedup > 0:
        print(f"error: --uavs 1 to {most} each, {users_flag} and --speedup positive", file=sys.stderr)
        return None
    return counts


def _run_fleet_scale(args: argparse.Namespace) -> int:
    from ..bench.fleet_scale import format_fleet_scale, run_fleet_scale
    from ..harness.demo import DemoError
    from ..harness.sites import Radio, SitesError, can_make_sites
    from ..model import ScenarioError

    counts = fleet_sizes(args.uavs, "5,10,20", 40, args.users_per_uav, "--users-per-uav", args.speedup)
    if counts is None:
        return 2
    if args.delay_ms < 0 or args.jitter_ms < 0 or not 0 <= args.loss < 1 or args.cut_at_s < 0 or args.cut_for_s < 0:
        print("error: --delay-ms, --jitter-ms, --cut-at-s and --cut-for-s must not be negative, --loss in [0, 1)",
              file=sys.stderr)
        return 2
    why = can_make_sites()
    if why:
        print(f"error: --scale cannot make its sites here: {why}", file=sys.stderr)
        return 2
    try:
        results = run_fleet_scale(counts, Radio(args.delay_ms, args.jitter_ms, args.loss), args.users_per_uav,
                                  args.speedup, args.budget_ms, args.seeds[0], args.cut_at_s, args.cut_for_s,
                                  progress=lambda msg: print(msg, file=sys.stderr, flush=True),
                                  keep=Path(args.keep) if args.keep else None, zenoh_mode=args.zenoh_mode)
    except (DemoError, SitesError, ScenarioError) as err:
        print(f"error: a fleet flight failed: {err}", file=sys.stderr)
        return 1
    print(json.dumps(results, indent=1) if args.json else format_fleet_scale(results))
    return 0


def _run_fleet_flight(args: argparse.Namespace) -> int:
    from ..bench.fleet_flight import format_fleet_flight, run_fleet_flight

    seeds = args.seeds
    counts = fleet_sizes(args.uavs, "1,2,3", 8, args.users, "--users", args.speedup)
    if counts is None:
        return 2
    from ..harness.demo import DemoError

    try:
        results = run_fleet_flight(counts, seeds[:1] if args.quick else seeds, args.users, args.speedup,
                                   args.budget_ms, progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    except DemoError as err:
        print(f"error: a fleet flight failed: {err}", file=sys.stderr)
        return 1
    print(json.dumps(results, indent=1) if args.json else format_fleet_flight(results))
    return 0


def _run_flight(args: argparse.Namespace) -> int:
    from ..bench.flight import ALGOS, format_flight, run_flight_bench

    seeds = args.seeds
    algos = [a for a in args.algos.split(",") if a]
    if any(a not in ALGOS + ("ts-mcts", "mcts-paper") for a in algos) or not args.speedup > 0:
        print("error: --algos (mcts, greedy, random, ts-mcts, mcts-paper) or --speedup invalid",
              file=sys.stderr)
        return 2
    if args.quick:
        seeds, algos = seeds[:2], ["mcts"]
    results = run_flight_bench(seeds, algos, speedup=args.speedup, budget_ms=args.budget_ms,
                               fly_too=not args.offline_only, iterations=args.iterations if args.offline_only else None,
                               progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    print(json.dumps(results, indent=1) if args.json else format_flight(results))
    return 0
