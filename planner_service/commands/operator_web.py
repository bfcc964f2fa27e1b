"""``operator web``: the live map in the browser. A zenoh peer that reads the fleet under the
prefix (every vehicle's status, plan, events and users, the members' signed positions and
claims with ``--fleet-roster``) into the fleet picture, and a web server on 127.0.0.1 (by
default) that draws it and sends the operator's start and hold, proved with the keys given.
Prints the page's address with its login token; runs until Ctrl-C."""

from __future__ import annotations

import argparse
import ipaddress
import ssl
import sys
import threading
from pathlib import Path
from typing import Any

from protocol.arguments import USAGE_ERROR
from protocol.stopping import stop_on_signals

DEFAULT_LISTEN = "127.0.0.1:8765"
DEFAULT_NICE = 10
"""The live map is the operator's eyes, not the flight: where its server shares the CPU with
a service (a companion computer, the ground station that routes the fleet, ``bench --e2e
--web``), the service's work comes first (docs/LIVE-MAP.md, "What it costs")."""


def configure(parser: argparse.ArgumentParser) -> None:
    """The web's own options (the operator command adds them to its parser)."""
    web = parser.add_argument_group("web (the live map)")
    web.add_argument("--listen", default=DEFAULT_LISTEN, metavar="HOST:PORT",
                     help=f"web: where the page is served (default {DEFAULT_LISTEN}; port 0 picks a free one); an "
                          "address other than loopback needs --tls-cert and --tls-key")
    web.add_argument("--tls-cert", metavar="FILE", default=None, help="web: the server's certificate chain (PEM)")
    web.add_argument("--tls-key", metavar="FILE", default=None, help="web: the server's private key (PEM)")
    web.add_argument("--vehicle-key", action="append", default=[], metavar="VEHICLE=FILE",
                     help="web: the operator key of one vehicle (repeatable; a fleet's services each have their own); "
                          "--operator-key is every other vehicle's")
    web.add_argument("--origin", default=None, metavar="LAT,LON[,ALT]",
                     help="web: the local frame's origin (a lone UAV's origin.*; a fleet's members announce theirs): "
                          "for GeoJSON and the map tiles")
    web.add_argument("--tiles", default=None, metavar="DIR",
                     help="web: local map tiles, DIR/Z/X/Y.png (slippy-map numbering), drawn under the fleet")
    web.add_argument("--token-file", metavar="FILE", default=None,
                     help="web: read the login token from FILE (at least 16 characters, mode 0600) instead of drawing "
                          "one at start: for scripts and a fixed bookmark")
    web.add_argument("--nice", type=int, default=DEFAULT_NICE, metavar="N",
                     help=f"web: lower this process's CPU priority by N (default {DEFAULT_NICE}; 0 keeps it): where the "
                          "page's server shares a computer with a service or a router, it yields to them")
    web.add_argument("--tiles-zoom", type=int, default=17, metavar="Z", help="web: the tiles' zoom level (default 17)")


def parse_listen(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (an IPv6 host in brackets) -> (host, port); ``ValueError`` naming what is wrong."""
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise ValueError(f"{text!r} is not HOST:PORT (e.g. {DEFAULT_LISTEN})")
    return host, int(port)


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def _origin(text: str | None) -> Any:
    from protocol import GeoOrigin

    if text is None:
        return None
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
        if len(values) not in (2, 3):
            raise ValueError
        return GeoOrigin(*values)
    except (ValueError, TypeError) as err:
        raise ValueError(f"--origin: {text!r} is not LAT,LON or LAT,LON,ALT in degrees and metres ({err})") from None


def _operator_keys(args: argparse.Namespace) -> dict[str, bytes]:
    from protocol.signing import load_key

    keys = {} if args.key is None else {"*": args.key}
    for given in args.vehicle_key:
        vehicle, sep, path = given.partition("=")
        if not sep or not vehicle or not path:
            raise ValueError(f"--vehicle-key: {given!r} is not VEHICLE=FILE")
        keys[vehicle] = load_key(path)
    return keys


MIN_TOKEN_CHARS = 16


def read_token(path: str) -> str:
    """The login token in ``path``; ``ValueError`` naming what is wrong (others may read it,
    too short)."""
    import os
    import stat

    try:
        mode = os.stat(path).st_mode
        token = Path(path).read_text().strip()
    except OSError as err:
        raise ValueError(f"--token-file: {err.strerror}: {path}") from None
    if stat.S_IMODE(mode) & 0o077:
        raise ValueError(f"--token-file: {path} may be read by others (mode {stat.S_IMODE(mode):o}); chmod 600 it")
    if len(token) < MIN_TOKEN_CHARS:
        raise ValueError(f"--token-file: {len(token)} characters; at least {MIN_TOKEN_CHARS}")
    return token


def run(args: argparse.Namespace) -> int:
    """Serve the live map until Ctrl-C (0), or a usage error (2) / no session (1)."""
    from protocol import ProtocolError, SigningError
    from protocol.client import client_config

    import zenoh

    from ..live.feed import LiveFeed
    from ..live.picture import FleetPicture
    from ..web.server import LiveMapServer, RunningServer

    import logging
    import os

    if args.nice:
        os.nice(max(min(args.nice, 19), 0))
    # what the server saw (logins refused, commands sent, pages following) on stderr
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s %(levelname)s %(message)s")
    for noisy in ("aiohttp.access", "zenoh"):
        logging.getLogger(noisy).setLevel(logging.WARNING)
    try:
        host, port = parse_listen(args.listen)
        origin = _origin(args.origin)
        operator_keys = _operator_keys(args)
        token = read_token(args.token_file) if args.token_file else None
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return USAGE_ERROR
    except SigningError as err:
        print(f"error: --vehicle-key: {err}", file=sys.stderr)
        return 1
    context = None
    if args.tls_cert or args.tls_key:
        if not (args.tls_cert and args.tls_key):
            print("error: --tls-cert and --tls-key go together", file=sys.stderr)
            return USAGE_ERROR
        context = ssl.create_default_context(ssl.Purpose.CLIENT_AUTH)
        try:
            context.load_cert_chain(args.tls_cert, args.tls_key)
        except (OSError, ssl.SSLError) as err:
            print(f"error: --tls-cert/--tls-key: {err}", file=sys.stderr)
            return 1
    elif not is_loopback(host):
        print(f"error: --listen {args.listen}: the page (and the operator's start and hold) would cross the network "
              "in clear; give --tls-cert and --tls-key, or listen on 127.0.0.1", file=sys.stderr)
        return USAGE_ERROR
    if args.tiles is not None and not Path(args.tiles).is_dir():
        print(f"error: --tiles: {args.tiles} is not a folder", file=sys.stderr)
        return USAGE_ERROR
    try:
        session = zenoh.open(client_config(args.connect or ["tcp/127.0.0.1:7447"], config_file=args.zenoh_config))
    except (zenoh.ZError, ProtocolError) as err:
        print(f"error: cannot open a zenoh session: {err}", file=sys.stderr)
        return 1
    lock = threading.Lock()
    feed = LiveFeed(session, FleetPicture(args.prefix, origin), lock, fleet_keys=args.fleet_keys,
                    operator_keys=operator_keys)
    stop = threading.Event()
    stop_on_signals(stop)
    running = None
    try:
        feed.start()
        server = LiveMapServer(feed, token, tiles=None if args.tiles is None else Path(args.tiles),
                               tiles_zoom=args.tiles_zoom, secure=context is not None)
        try:
            running = RunningServer(server, host, port, context).start()
        except OSError as err:
            print(f"error: --listen {args.listen}: {err.strerror or err}", file=sys.stderr)
            return 1
        print(f"live map: {running.login_url}", flush=True)
        print("  (the token logs the browser in once; Ctrl-C stops the server)", flush=True)
        stop.wait()
        return 0
    finally:
        if running is not None:
            running.close()
        feed.close()
        session.close()
