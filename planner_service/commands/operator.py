"""The operator's command line. ``web``: the live map in the browser (``operator_web.py``).
``watch``: a live view of the service (phase, mode, battery
and its source, position, authority, the fleet's members, layers and separation, the plan,
pending users, the last events), redrawn from its status, plan and event publications and
its state query, until Ctrl-C; plain text (on a terminal that cannot clear, or into a file
or pipe, each changed view is printed after the last). ``start``: give the service authority to
arm, switch modes and start the mission; ``hold``: take it back (the service commands
nothing more, the vehicle keeps its mission); ``status``: ask. Each prints what the service
did. Exit status: 0 accepted, 1 refused or no answer, 2 a usage error, 141 the reader of its
output went away.

Who may command: without zenoh access control, the holder of the service's operator key
(``--operator-key``; each command carries its proof, never the key); under access control,
an operator's certificate (docs/zenoh/operator-tls.json5). The pending requests (every
user's position and backlog) that ``watch`` shows come from ``status``: the operator's too."""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from typing import Any

from protocol.arguments import USAGE_ERROR, positive_float, positive_int
from protocol.client_args import DEFAULT_ENDPOINT, add_client_arguments
from protocol.stopping import stop_on_signals

HELP = "the operator's command line: watch the service live (as text, or the live map in the browser), or start / hold / status"
ACTIONS = ("watch", "web", "start", "hold", "status")
DEFAULT_KEY = "operator.key"
"""The service's default key file: ``operator.key`` beside its default journal (both in the
folder it starts in)."""
CLEAR = "\x1b[H\x1b[2J"
"""Cursor home and clear screen (ANSI): used only on a terminal that is not ``dumb``."""


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", choices=ACTIONS,
                        help="watch: live view until Ctrl-C; web: the live map in the browser until Ctrl-C; start: give the service authority over modes and arming; "
                             "hold: take it back; status: ask")
    parser.add_argument("--reason", default="", metavar="TEXT",
                        help="start or hold: why, in words (at most 256 characters; kept in the service's log and in "
                             "status.authority_detail)")
    parser.add_argument("--operator-key", metavar="FILE", default=None,
                        help=f"the service's operator key (its operator.key_file; default {DEFAULT_KEY}, where the "
                             "service makes it beside a journal in the current folder): each command carries its "
                             "proof, which a service without zenoh access control requires. A missing default file "
                             "is skipped (under access control the certificate is the proof)")
    add_client_arguments(parser)
    parser.add_argument("--timeout", type=positive_float, default=5.0,
                        help="seconds to wait for the service's answer (default 5)")
    parser.add_argument("--refresh", type=positive_float, default=1.0,
                        help="watch: seconds between redraws (default 1)")
    parser.add_argument("--events", type=positive_int, default=8, help="watch: how many last events (default 8)")
    parser.add_argument("--once", action="store_true",
                        help="watch: print one view (after waiting up to --timeout for a status) and exit: 0 if a "
                             "status came, 1 if not")
    parser.add_argument("--fleet-roster", metavar="FILE", default=None,
                        help="watch, web: the fleet's roster (fleet.roster_file): the members' signed announcements and "
                             "positions are read against it; without it the fleet's messages cannot be verified and "
                             "no member is shown")
    from .operator_web import configure as configure_web

    configure_web(parser)
    parser.add_argument("--plain", action="store_true",
                        help="watch: never clear the screen, print each changed view after the last (the default "
                             "when TERM is dumb or the output is not a terminal)")


def _key(path: str | None) -> bytes | None:
    """The operator key of ``path``; None when no path was given and the default is absent."""
    from protocol.signing import load_key

    if path is None:
        if not os.path.lexists(DEFAULT_KEY):
            return None
        path = DEFAULT_KEY
    return load_key(path)


def _fleet_roster(path: str | None) -> dict[str, Any]:
    """The enrolled vehicles' public keys ({} without a roster: nothing of the fleet verifies)."""
    from protocol.fleet_signing import read_roster

    return {} if path is None else read_roster(path)


def run(args: argparse.Namespace) -> int:
    from protocol import Keys, ProtocolError, SigningError
    from protocol.client import PlannerClient, command_client
    from protocol.text import printable

    if args.reason and args.action not in ("start", "hold"):
        print(f"error: --reason: only start and hold take a reason, not {args.action}", file=sys.stderr)
        return USAGE_ERROR
    if len(args.reason) > 256:
        print(f"error: --reason: {len(args.reason)} characters; at most 256", file=sys.stderr)
        return USAGE_ERROR
    if args.action != "watch" and (args.once or args.plain):
        print("error: --once and --plain are for watch", file=sys.stderr)
        return USAGE_ERROR
    if args.action != "web" and (args.vehicle_key or args.tiles or args.origin or args.tls_cert or args.tls_key
                                  or args.token_file):
        print("error: --vehicle-key, --tiles, --origin, --tls-cert, --tls-key and --token-file are for web",
              file=sys.stderr)
        return USAGE_ERROR
    try:
        args.key = _key(args.operator_key)
    except SigningError as err:
        print(f"error: --operator-key: {printable(str(err), 400)}", file=sys.stderr)
        return 1
    try:
        args.fleet_keys = _fleet_roster(args.fleet_roster)
    except SigningError as err:
        print(f"error: --fleet-roster: {printable(str(err), 400)}", file=sys.stderr)
        return 1
    if args.action == "web":
        from .operator_web import run as run_web

        return run_web(args)
    keys = Keys(args.prefix, args.vehicle)
    stop = threading.Event()
    if args.action == "watch":  # Ctrl-C (or SIGTERM) ends the watch between two redraws
        stop_on_signals(stop)
    try:
        try:
            # a command: the one-shot client (command_client); the watch a peer, which waits for a
            # service that is not there yet
            opener = PlannerClient if args.action == "watch" else command_client
            client = opener(args.connect or [DEFAULT_ENDPOINT], keys, timeout_s=args.timeout,
                            config_file=args.zenoh_config)
        except ProtocolError as err:  # no session: nothing listening, a TLS handshake refused
            print(f"error: {err}", file=sys.stderr)
            return 1
        with client:
            if args.action == "watch":
                return _watch(client, args, stop)
            return _command(client, args)
    except KeyboardInterrupt:  # Ctrl-C while a command waits for its answer
        print("interrupted: no answer awaited", file=sys.stderr)
        return 130


def _command(client: Any, args: argparse.Namespace) -> int:
    from protocol.client import ClientError
    from protocol.text import printable

    try:
        reply = client.operator(args.action, args.reason, args.timeout, key=args.key)
    except ClientError as err:
        hint = ("; is the service running, and is this an operator's certificate? (under access control only "
                "operators may send commands)") if err.field == "service" else ""
        if err.field == "proof":
            hint = ("; give the service's operator key with --operator-key FILE" if args.key is None else
                    "; is --operator-key the service's operator.key_file?")
        print(f"error: {printable(err.field, 64)}: {printable(err.message, 300)}{hint}", file=sys.stderr)
        return 1
    verdict = "accepted" if reply.accepted else "refused"
    print(f"{verdict}: {args.action}: {printable(reply.message, 300)}")
    print(f"authority {reply.authority}, phase {reply.phase}")
    if reply.status is not None:
        from ..operator_view import status_lines

        for line in status_lines(reply.status):
            print(f"  {line}")
    return 0 if reply.accepted else 1


def _watch(client: Any, args: argparse.Namespace, stop: threading.Event) -> int:
    from protocol import ProtocolError
    from protocol.client import ClientError

    from ..live.feed import LiveFeed
    from ..live.picture import FleetPicture
    from ..operator_view import render

    vehicle = client.keys.vehicle
    picture = FleetPicture(client.keys.prefix, events_kept=args.events)
    lock = threading.Lock()
    # the live map's read model and feed; the pending requests asked here, of this vehicle only
    feed = LiveFeed(client.session, picture, lock, fleet_keys=args.fleet_keys, state_every_s=None)
    feed.start()
    term = os.environ.get("TERM", "")
    plain = args.plain or not sys.stdout.isatty() or term in ("", "dumb", "unknown")
    last: list[str] | None = None
    deadline = time.monotonic() + args.timeout
    try:
        while not stop.is_set():  # also when the service is absent: the view says so
            try:
                reply = client.operator("status", timeout_s=min(args.timeout, 1.0), key=args.key)
                state = reply.state if reply.state is not None else client.state(timeout_s=min(args.timeout, 1.0))
                with lock:
                    picture.on_pending(vehicle, list(state.pending))
                    seen = picture.vehicle(vehicle)
                    if seen.status is None:  # no publication yet: the state's snapshot will do
                        picture.on_status(vehicle, state.status, time.monotonic())
                    if state.plan is not None and (seen.plan is None or state.plan.plan_id > seen.plan.plan_id):
                        picture.on_plan(vehicle, state.plan)  # published before the watch began
            except ClientError as err:
                with lock:
                    picture.on_pending(vehicle, None, f"no answer to the operator's status ({err.field}: {err.message})")
            except ProtocolError as err:
                with lock:
                    picture.on_pending(vehicle, None,
                                       f"the operator's status answer was refused ({err.field}: {err.message})")
            with lock:
                has_status = picture.vehicle(vehicle).status is not None
            if args.once and not has_status and time.monotonic() < deadline:
                stop.wait(0.1)
                continue
            if args.once and client.wait_for_service(timeout_s=1.0):
                with lock:  # the token's history may reach the subscriber after the state's answer
                    if picture.vehicle(vehicle).alive is None:
                        picture.on_alive(vehicle, True)
            if args.once:  # one view: with the layers and positions of the members the roster knows of
                feed.settle(min(args.timeout, 2.0))
            feed.read_fleet()
            with lock:
                lines = render(picture, vehicle, time.monotonic())
            if plain:
                if last is None or lines[1:] != last[1:]:  # the header's age changes every time
                    print("\n".join(lines) + "\n" + "-" * 40, flush=True)
            else:
                sys.stdout.write(CLEAR + "\n".join(lines) + "\n\n(Ctrl-C to quit)\n")
                sys.stdout.flush()
            last = lines
            if args.once:
                return 0 if has_status else 1
            stop.wait(args.refresh)
    finally:
        feed.close()
    if not plain:
        print()
    return 0
