"""The flight-side service: takes task requests over zenoh, plans with MCTS and keeps the
autopilot holding the best mission. Runs until SIGINT or SIGTERM. Every configuration key
is documented in docs/planner.example.toml; any can be overridden with --set."""

from __future__ import annotations

import argparse
import logging
import sys

HELP = "the long-running flight-side service (zenoh intake, MCTS planning, MAVLink missions)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, help="TOML configuration file (default: built-in defaults)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override a configuration key, e.g. --set mavlink.backend=mavsdk (repeatable)")
    parser.add_argument("--journal", default=None, help="journal file (same as --set journal.path=...)")
    parser.add_argument("--mavlink", default=None, metavar="URL", help="autopilot connection (mavlink.url)")
    parser.add_argument("--backend", default=None, choices=["pymavlink", "mavsdk"], help="MAVLink library (mavlink.backend)")
    parser.add_argument("--listen", default=None, metavar="ENDPOINT", help="zenoh listen endpoint (zenoh.listen)")
    parser.add_argument("--zenoh-config", default=None, metavar="FILE",
                        help="zenoh configuration file (JSON5) as the session's base: TLS, access control "
                             "(zenoh.config_file; docs/zenoh/service-tls-acl.json5)")
    parser.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])


def run(args: argparse.Namespace) -> int:
    from ..service import ConfigError, ServiceError, load_config, parse_overrides
    from ..service.app import run_service

    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        overrides = parse_overrides(args.overrides)
        for flag, key in (("journal", "journal.path"), ("mavlink", "mavlink.url"), ("backend", "mavlink.backend"),
                          ("listen", "zenoh.listen"), ("zenoh_config", "zenoh.config_file")):
            if getattr(args, flag) is not None:
                overrides[key] = getattr(args, flag)
        config = load_config(args.config, overrides)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        return run_service(config)
    except ServiceError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
