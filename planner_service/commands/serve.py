"""The flight-side service: takes task requests over zenoh, plans with MCTS and keeps the
autopilot holding the best mission. Runs until SIGINT or SIGTERM. Every configuration key
is documented in docs/planner.example.toml; any can be overridden with --set."""

from __future__ import annotations

import argparse
import atexit
import logging
import os
import sys
import threading
from typing import NoReturn

from protocol.arguments import existing_file, zenoh_endpoint

HELP = "the long-running flight-side service (zenoh intake, MCTS planning, MAVLink missions)"
EXIT_DEADLINE_S = 3.0
"""Once the service has stopped (its last line logged), the process ends within this many
seconds whatever holds it: a library's exit hook, a thread in a native call, a flush to a
pipe nobody reads. A supervisor or a pilot's Ctrl-C never needs SIGKILL (issue 34)."""


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config", default=None, type=existing_file,
                        help="TOML configuration file (default: built-in defaults)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="override a configuration key, e.g. --set mavlink.backend=mavsdk (repeatable)")
    parser.add_argument("--journal", default=None,
                        help="journal file (same as --set journal.path=...): created if it does not exist; an "
                             "existing file must be a journal, used by no other service")
    parser.add_argument("--mavlink", default=None, metavar="URL", help="autopilot connection (mavlink.url)")
    parser.add_argument("--backend", default=None, choices=["pymavlink", "mavsdk"], help="MAVLink library (mavlink.backend)")
    parser.add_argument("--listen", default=None, metavar="ENDPOINT", type=zenoh_endpoint,
                        help="zenoh listen endpoint (zenoh.listen)")
    parser.add_argument("--zenoh-config", default=None, metavar="FILE", type=existing_file,
                        help="zenoh configuration file (JSON5) as the session's base: TLS, access control "
                             "(zenoh.config_file; docs/zenoh/service-tls-acl.json5)")
    parser.add_argument("--log-level", default="INFO", choices=["DEBUG", "INFO", "WARNING", "ERROR"])


def run(args: argparse.Namespace) -> int:
    from protocol.text import printable

    from ..service import ConfigError, ServiceError, load_config, parse_overrides
    from ..service.app import run_service

    logging.basicConfig(level=args.log_level, stream=sys.stderr, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    flags = {key: flag for flag, key in (("journal", "journal.path"), ("mavlink", "mavlink.url"),
                                         ("backend", "mavlink.backend"), ("listen", "zenoh.listen"),
                                         ("zenoh_config", "zenoh.config_file"))
             if getattr(args, flag) is not None}
    try:
        overrides = parse_overrides(args.overrides)
        for key, flag in flags.items():
            overrides[key] = getattr(args, flag)
        config = load_config(args.config, overrides)
    except ConfigError as err:
        # name the option the value came from: --mavlink (mavlink.url), --set KEY=..., or the file
        flag = flags.get(err.key)
        where = f"--{flag.replace('_', '-')} ({err.key})" if flag else err.key
        print(f"error: {where}: {printable(err.message, 400)}", file=sys.stderr)
        return 2
    try:
        status = run_service(config, on_stopped=exit_by_deadline)
    except ServiceError as err:
        print(f"error: {err}", file=sys.stderr)
        status = 1
    end_now(status)


def end_now(status: int) -> NoReturn:
    """End the process with ``status`` at once: the service has stopped and closed what it
    owns (the link, the zenoh session, the journal, checkpointed) and logged its last line.
    Only for the end of a ``serve`` process: it does not return to its caller.

    Python's own exit would first join the planner's worker thread, which finishes the job
    it is running however long it takes (the warm-up compiling every kernel: a minute on a
    cold numba cache; a search: its budget), then collect the whole heap at finalization
    (numba's compiled functions and types: 0.25 s after the last line on a quiet machine,
    0.8 s beside two busy cores). Neither does anything for the service, and whoever waits for the exit (a
    supervisor's stop or restart, a pilot's Ctrl-C) waits for both. The exit hooks the
    libraries registered (logging's flush, MAVSDK's server, weakref finalizers) still run;
    numba writes its cache files whole (to a temporary name, then renamed), so a compile
    cut short leaves none half-written."""
    exit_by_deadline(status)
    atexit._run_exitfuncs()  # not the threads' join: that one is threading's, at normal exit only
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def exit_by_deadline(status: int, after_s: float = EXIT_DEADLINE_S) -> None:
    """Arm the process's end: ``status`` in ``after_s`` seconds unless it has ended before.
    Nothing is written then (a write could block where the exit did)."""
    timer = threading.Timer(after_s, os._exit, (status,))
    timer.daemon = True
    timer.start()
