"""Submit one task request to the service over zenoh and print its reply (the ack's
request id, what the service knows of the user, or the error naming the refused field).

A request states the user's whole backlog (--tasks: every task it has waiting now; 0:
nothing more) and position; it is in force until the user's next request or until it is
served (docs/PROTOCOL.md, "Requests"). The request goes on the user's own key and only an
ack of this user with this --client-ref is taken as the answer."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from protocol.arguments import finite_float, non_negative_int, positive_float
from protocol.client_args import DEFAULT_ENDPOINT, add_client_arguments
from protocol.text import printable

if TYPE_CHECKING:
    from protocol import TaskAck

HELP = "a zenoh client that submits one task request (a user's backlog and position)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--user", required=True, help="user id (1-64 of A-Z a-z 0-9 _ . : -)")
    parser.add_argument("--x", type=finite_float, required=True, help="east position, local metres")
    parser.add_argument("--y", type=finite_float, required=True, help="north position, local metres")
    parser.add_argument("--z", type=finite_float, default=0.0, help="height, local metres (default 0)")
    parser.add_argument("--tasks", type=non_negative_int, required=True,
                        help="the user's whole backlog: every task it has waiting now (not an increment); "
                             "0: nothing (more) to offload, which ends its wait")
    parser.add_argument("--client-ref", default=None, metavar="REF",
                        help="correlation id echoed in the reply (default: 16 random hex digits); a reply "
                             "that does not carry it is refused")
    add_client_arguments(parser)
    parser.add_argument("--timeout", type=positive_float, default=5.0,
                        help="seconds to wait for the service (default 5)")


def run(args: argparse.Namespace) -> int:
    from protocol import Keys, ProtocolError
    from protocol.client import ClientError, command_client

    try:
        keys = Keys(args.prefix, args.vehicle)
    except ProtocolError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        client = command_client(args.connect or [DEFAULT_ENDPOINT], keys, timeout_s=args.timeout,
                                config_file=args.zenoh_config)
    except ProtocolError as err:  # a refused config file, or no session (ClientError)
        print(f"error: {err}", file=sys.stderr)
        return 1
    with client:
        if not client.wait_for_service(args.timeout):
            print(f"error: no service alive at {keys.alive}", file=sys.stderr)
            return 1
        try:
            ack = client.submit(args.user, args.x, args.y, args.tasks, args.z, client_ref=args.client_ref)
        except ClientError as err:
            print(f"refused: {printable(err.field)}: {printable(err.message)}", file=sys.stderr)
            return 1
        except ProtocolError as err:
            print(f"error: {printable(str(err))}", file=sys.stderr)
            return 1
    print(f"accepted: {describe(ack)}")
    return 0


def describe(ack: "TaskAck") -> str:
    """The ack in one line: the request, the queue, what was served, the place in the plan."""
    parts = [f"request {ack.request_id} for {ack.user_id} (queue position {ack.queue_position})"]
    if ack.sortie is not None:
        parts.append(f"sortie {ack.sortie}: {ack.served_tasks or 0} tasks served so far")
    if ack.place is not None:
        eta = "" if ack.eta_s is None else f", its service in about {ack.eta_s:.0f} s at the last plan"
        parts.append(f"place {ack.place} in the plan{eta}")
    elif ack.sortie is not None:
        parts.append("not in the current plan")
    if ack.note:
        parts.append(printable(ack.note))
    return "; ".join(parts)
