"""A zenoh router: a Python session in router mode that routes between client-mode
sessions (there is no standalone zenohd here). Stands in for the ground router in tests and
demos: the service in client mode connects to it, and so do users. Runs until SIGINT or
SIGTERM."""

from __future__ import annotations

import argparse
import sys
import threading

from protocol.arguments import existing_file, zenoh_endpoint
from protocol.stopping import stop_on_signals

HELP = "a zenoh router (a session in router mode) for client-mode services and users"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", action="append", required=True, metavar="ENDPOINT", type=zenoh_endpoint,
                        help="endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable)")
    parser.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", type=zenoh_endpoint,
                        help="endpoint of another router to connect to (repeatable)")
    parser.add_argument("--zenoh-config", default=None, metavar="FILE", type=existing_file,
                        help="zenoh configuration file (JSON5) as the base: TLS, access control; "
                             "--listen and --connect are applied on top")


def run(args: argparse.Namespace) -> int:
    import zenoh

    from protocol import ProtocolError
    from protocol.zenoh_config import error_text, session_config

    stop = threading.Event()
    stop_on_signals(stop)
    try:
        conf = session_config("router", args.listen, args.connect, False, args.zenoh_config)
        session = zenoh.open(conf)
    except (ProtocolError, zenoh.ZError) as err:
        print(f"error: cannot start the router on {args.listen}: {error_text(err)}", file=sys.stderr)
        return 1
    print(f"router listening on {args.listen} (zid {session.info.zid()})", file=sys.stderr, flush=True)
    try:
        while not stop.wait(0.5):
            pass
    finally:
        session.close()
    return 0
