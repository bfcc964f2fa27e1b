"""The main job on the embedded default: the vehicle stub, simulated ground users and the
service on loopback, one sortie flown with the stub's speed-up. Progress (served users,
battery, throughput) on the terminal; summary.json, trajectory.png and mission.plan (the
first complete mission, QGroundControl format) in --out, with the logs and the journal. The
live map's address (``operator web``'s page) is printed as the sortie begins; --web keeps it
open after the landing until Ctrl-C.
With --mavlink URL no stub is started: the service flies the autopilot there (ArduCopter
SITL, PX4 SITL: README, "Flying ArduCopter SITL or PX4 SITL"). Every process it starts is
stopped, also on error or Ctrl-C."""

from __future__ import annotations

import argparse
import json
import sys
import threading
from pathlib import Path
from typing import Any, Callable

from protocol.arguments import positive_float, positive_int

HELP = "the main job on the embedded default (writes summary.json, trajectory.png, mission.plan)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="demo-out", help="output folder (default: demo-out)")
    parser.add_argument("--users", type=positive_int, default=None,
                        help="simulated users (default 10; 12 with --uavs)")
    parser.add_argument("--uavs", type=positive_int, default=1,
                        help="UAVs: with 2 or more, a fleet (a stub and a service each, two meshed zenoh routers, "
                             "the users submitting to the fleet; docs/OPERATIONS.md, A fleet); writes summary.json "
                             "and paths.png (default 1)")
    parser.add_argument("--speedup", type=positive_float, default=25.0, help="simulated seconds per wall second (default 25)")
    parser.add_argument("--budget-ms", type=positive_float, default=150.0, help="planner budget per decision (default 150)")
    parser.add_argument("--backend", default="pymavlink", choices=["pymavlink", "mavsdk"], help="MAVLink library")
    parser.add_argument("--flavour", default=None, choices=["ardupilot", "px4"],
                        help="autopilot the stub imitates (with --mavlink: the autopilot's; it must say so in its "
                             "HEARTBEAT); default: --config's mavlink.flavour, else ardupilot")
    parser.add_argument("--seed", type=int, default=1, help="seed of the users and the planner (default 1)")
    parser.add_argument("--timeout", type=positive_float, default=180.0, help="give up after this many wall seconds (default 180)")
    parser.add_argument("--algo", default="mcts", choices=("mcts", "greedy", "random", "ts-mcts", "mcts-paper"),
                        help="the planner the service flies (planner.algo; default mcts)")
    parser.add_argument("--mavlink", default=None, metavar="URL", type=_mavlink_url,
                        help="fly the autopilot at this connection string (e.g. tcp:127.0.0.1:5760 for ArduCopter "
                             "SITL) instead of starting the stub; --speedup must be its speed-up")
    parser.add_argument("--web", action="store_true",
                        help="keep the live map (its address is printed when the sortie begins) and the services "
                             "open after the sortie, until Ctrl-C")
    parser.add_argument("--config", default=None, metavar="FILE",
                        help="service configuration to start from (its [scenario], [safety], [planner]; e.g. "
                             "docs/sitl-copter.toml for ArduCopter SITL); the demo sets zenoh, the journal and the "
                             "MAVLink link")


def _mavlink_url(text: str) -> str:
    from ..service.config import mavlink_url_problem

    why = mavlink_url_problem(text, "pymavlink")
    if why is not None:
        raise argparse.ArgumentTypeError(why)
    return text


def _flown(fly: Callable[[], dict[str, Any]]) -> dict[str, Any] | int:
    """The demo's summary, or the exit status when it failed or was interrupted (said)."""
    from ..harness.demo import DemoError

    try:
        return fly()
    except DemoError as err:
        print(f"demo failed: {err}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("demo interrupted; every process stopped", file=sys.stderr)
        return 130


def run(args: argparse.Namespace) -> int:
    from ..harness.demo import run_demo

    out = Path(args.out)
    if args.uavs > 1:
        return run_fleet(args, out)
    summary = _flown(lambda: run_demo(
        out, users=args.users or 10, speedup=args.speedup, budget_ms=args.budget_ms, backend=args.backend,
        flavour=args.flavour, seed=args.seed, timeout_s=args.timeout, mavlink=args.mavlink, algo=args.algo,
        config=Path(args.config) if args.config else None, echo=_echo, web=args.web))
    if isinstance(summary, int):
        return summary
    print(f"\n{summary['intervals']} services to {summary['served_users']} users, "
          f"{summary['throughput_tasks_per_interval']:.1f} tasks/interval, average reward {summary['average_reward']:.3f}, "
          f"energy {summary['energy_used_j'] / 1e3:.1f} of {summary['energy_budget_j'] / 1e3:.1f} kJ, "
          f"fairness violations {summary['fairness_violations']}, energy violation {summary['energy_violation']}")
    print(f"requests: {json.dumps(summary['requests'])}")
    if summary.get("flown_to_offline") is not None:
        off = summary["offline"]
        print(f"planned offline on the same scenario and seed ({summary['algo']}, the model alone): "
              f"{off['throughput_tasks_per_interval']:.1f} tasks/interval, average reward {off['average_reward']:.3f}; "
              f"flown / offline: {summary['flown_to_offline']:.2f}")
    print(f"{summary['wall_s']:.1f} s wall; wrote {out / 'summary.json'}, {out / 'trajectory.png'}, {out / 'mission.plan'}")
    return 0


_lock = threading.Lock()


def _echo(line: str) -> None:
    with _lock:
        print(line, flush=True)


def run_fleet(args: argparse.Namespace, out: Path) -> int:
    """``demo --uavs N``: the fleet's sortie, its summary per UAV and for the fleet."""
    from ..harness.fleet_demo import run_fleet_demo

    alone = [flag for flag, given in (("--mavlink", args.mavlink), ("--config", args.config),
                                      ("--flavour", args.flavour), ("--algo", args.algo != "mcts"),
                                      ("--backend", args.backend != "pymavlink")) if given]
    if alone:
        print(f"error: {', '.join(alone)} fly one UAV; --uavs {args.uavs} flies the stubs with the defaults",
              file=sys.stderr)
        return 2
    summary = _flown(lambda: run_fleet_demo(out, uavs=args.uavs, users=args.users or 12, speedup=args.speedup,
                                            budget_ms=args.budget_ms, seed=args.seed, timeout_s=args.timeout,
                                            echo=_echo, web=args.web))
    if isinstance(summary, int):
        return summary
    for vehicle, s in summary["per_uav"].items():
        traffic = summary["traffic_bytes_per_s"][vehicle]
        print(f"{vehicle}: {s['intervals']} services to {s['served_users']} users, "
              f"{s['throughput_tasks_per_interval']:.1f} tasks/interval, requests {json.dumps(s['requests'])}; "
              f"sent {traffic['fleet_keys']:.0f} B/s on the fleet keys, {traffic['status']:.0f} B/s of status")
    f = summary["fleet"]
    print(f"fleet: {f['intervals']} services to {f['users_served']} users, {f['throughput_tasks_per_interval']:.1f} "
          f"tasks/interval (sum of the UAVs'), users served by two UAVs {f['users_served_by_two_uavs'] or 0}, "
          f"fairness violations {f['fairness_violations']}, energy violations {f['energy_violations']}")
    if summary.get("flown_to_offline") is not None:
        off = summary["offline"]
        print(f"planned offline by the fleet planner {off['algo']} on the same scenario and seed: "
              f"{off['throughput_tasks_per_interval']:.1f} tasks/interval; flown / offline: "
              f"{summary['flown_to_offline']:.2f}")
    print(f"{summary['wall_s']:.1f} s wall; wrote {out / 'summary.json'}, {out / 'paths.png'}")
    return 0
