"""Submit one task request to the service over zenoh and print its reply (the ack's
request id, or the error naming the refused field)."""

from __future__ import annotations

import argparse
import sys

from protocol.arguments import finite_float, non_negative_int, positive_float
from protocol.client_args import DEFAULT_ENDPOINT, add_client_arguments

HELP = "a zenoh client that submits one task request"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--user", required=True, help="user id (1-64 of A-Z a-z 0-9 _ . : -)")
    parser.add_argument("--x", type=finite_float, required=True, help="east position, local metres")
    parser.add_argument("--y", type=finite_float, required=True, help="north position, local metres")
    parser.add_argument("--z", type=finite_float, default=0.0, help="height, local metres (default 0)")
    parser.add_argument("--tasks", type=non_negative_int, required=True, help="number of tasks to offload")
    add_client_arguments(parser)
    parser.add_argument("--timeout", type=positive_float, default=5.0,
                        help="seconds to wait for the service (default 5)")


def run(args: argparse.Namespace) -> int:
    from protocol import Keys, ProtocolError
    from protocol.client import ClientError, PlannerClient

    try:
        keys = Keys(args.prefix, args.vehicle)
    except ProtocolError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        client = PlannerClient(args.connect or [DEFAULT_ENDPOINT], keys, timeout_s=args.timeout,
                               config_file=args.zenoh_config)
    except ProtocolError as err:  # a refused config file, or no session (ClientError)
        print(f"error: {err}", file=sys.stderr)
        return 1
    with client:
        if not client.wait_for_service(args.timeout):
            print(f"error: no service alive at {keys.alive}", file=sys.stderr)
            return 1
        try:
            ack = client.submit(args.user, args.x, args.y, args.tasks, args.z)
        except ClientError as err:
            print(f"refused: {err.field}: {err.message}", file=sys.stderr)
            return 1
        except ProtocolError as err:
            print(f"error: {err}", file=sys.stderr)
            return 1
    print(f"accepted: request {ack.request_id} for {ack.user_id} (queue position {ack.queue_position})")
    return 0
