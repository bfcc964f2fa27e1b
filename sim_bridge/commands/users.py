"""Simulated ground users: each walks by random waypoint, keeps a backlog of tasks (a first
one drawn, new ones arriving every interval, as the model's backlog task model; what the
service serves is taken off) and submits it over zenoh when
it changes, when the user has moved, and at least every interval (--tasks redraw: the
paper's fresh draw every interval instead). Stops on SIGINT/SIGTERM, after --duration, or
when the service says it flies no more sorties (between two sorties it refuses requests and
the users keep asking). Logs go to stderr; a one-line summary per user at the end."""

from __future__ import annotations

import argparse
import logging
import sys
import threading

from protocol.arguments import positive_float, positive_int
from protocol.client_args import DEFAULT_ENDPOINT, add_client_arguments
from protocol.stopping import stop_on_signals

HELP = "simulated ground users that move by random waypoint and submit their task backlogs over zenoh"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--count", type=positive_int, default=10, help="number of users (default 10)")
    parser.add_argument("--preset", default="field", help="scenario preset: area, layout and task draws (default field)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="override a scenario field")
    parser.add_argument("--interval", type=positive_float, default=55.0,
                        help="simulated seconds of one interval of the model: arrivals come once an interval "
                             "(the field preset's interval lasts about 55 s: a hold and a flight), and a user "
                             "with tasks speaks at least this often (default 55)")
    parser.add_argument("--tasks", choices=("backlog", "redraw"), default="backlog",
                        help="backlog (default; the model's task_model = backlog): a first backlog drawn N(mean, "
                             "phi^2), then each interval Poisson(task_arrival_mean) new tasks (capped at "
                             "--backlog-max); what is served is taken off; the backlog is sent when it changes; "
                             "redraw: the paper's experiments, a fresh N(mean, phi^2) draw replaces the count every "
                             "interval and is sent then")
    parser.add_argument("--backlog-max", type=positive_int, default=None, metavar="N",
                        help="most tasks a user holds (default: the scenario's task_max, u_max)")
    parser.add_argument("--resend-m", type=positive_float, default=50.0, metavar="M",
                        help="a user with tasks that has moved this far since its last request sends again "
                             "(default 50)")
    parser.add_argument("--walk-speed", type=walk_speeds, default=None, metavar="LO,HI",
                        help="walking speeds in m/s, each leg of the random-waypoint walk drawn in [LO, HI] "
                             "(default: the model's pace, a user going as far in an interval as the scenario's "
                             "user_move_range_m moves it: 0.07,0.22 for the field preset)")
    parser.add_argument("--speedup", type=positive_float, default=1.0,
                        help="simulated seconds per wall second (default 1)")
    parser.add_argument("--fleet", action="store_true",
                        help="submit to the fleet ({prefix}/fleet/request/{user}): every member holds each request, "
                             "the one that plans it soonest answers for it (docs/OPERATIONS.md, section A fleet)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the walks and task draws (default 0)")
    parser.add_argument("--duration", type=positive_float, default=None, help="stop after this many wall seconds")
    add_client_arguments(parser)
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(stream=sys.stderr, level=args.log_level, format="%(asctime)s users %(levelname)s %(message)s")
    from planner_service.model import ScenarioError, preset
    from protocol import Keys, ProtocolError
    from protocol.client import PlannerClient
    from sim_bridge.users import TaskParams, run_users

    if args.count < 1 or not args.interval > 0 or not args.speedup > 0 or not args.resend_m > 0:
        print("error: --count must be at least 1, --interval, --speedup and --resend-m positive", file=sys.stderr)
        return 2
    from protocol.messages import MAX_TASKS
    if args.backlog_max is not None and not 1 <= args.backlog_max <= MAX_TASKS:
        print(f"error: --backlog-max must be 1 to {MAX_TASKS} (the most tasks a request may carry)", file=sys.stderr)
        return 2
    try:
        scenario = preset(args.preset).with_overrides(args.set)
        keys = Keys(args.prefix, args.vehicle)
    except (ScenarioError, ProtocolError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    stop = threading.Event()
    stop_on_signals(stop)
    try:
        client = PlannerClient(args.connect or [DEFAULT_ENDPOINT], keys, config_file=args.zenoh_config)
    except ProtocolError as err:  # a refused config file, or no session (ClientError)
        print(f"error: {err}", file=sys.stderr)
        return 1
    with client:
        logging.getLogger("sim_bridge.users").info("%d users waiting for the service at %s", args.count, keys.alive)
        while not (client.wait_for_fleet(1.0) if args.fleet else client.wait_for_service(1.0)):
            if stop.is_set():
                return 0
        tasks = TaskParams(interval_s=args.interval, law=args.tasks, resend_m=args.resend_m, retry_s=args.interval,
                           fleet=args.fleet,
                           backlog_max=scenario.task_max if args.backlog_max is None else args.backlog_max)
        walkers = run_users(client, scenario, args.count, tasks, args.speedup, args.seed, stop, args.duration,
                            args.walk_speed)
    for w in walkers:
        print(f"{w.user_id}: {w.submitted} submitted, {w.acked} acked, {w.refused} refused; {w.arrived} tasks arrived, "
              f"{w.lost} lost to a full backlog, {w.served} served, backlog {w.backlog}", file=sys.stderr)
    return 0


def walk_speeds(text: str) -> tuple[float, float]:
    """``LO,HI`` in m/s, each a positive number and LO <= HI, checked as parsed."""
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r} is not LO,HI")
    lo, hi = (positive_float(part) for part in parts)
    if lo > hi:
        raise argparse.ArgumentTypeError(f"{text!r}: LO is above HI")
    return lo, hi
