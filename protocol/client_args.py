"""The command-line options every client of the service shares (``submit``, ``sim_bridge
users``). Kept apart from ``client.py`` so that building a parser does not import zenoh."""

from __future__ import annotations

import argparse

from .arguments import existing_file, key_chunk, zenoh_endpoint

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
"""Where a client looks for the service when told nothing (the service's default listen)."""


def add_client_arguments(parser: argparse.ArgumentParser) -> None:
    """The command-line options of every client of the service: ``--connect``,
    ``--zenoh-config``, ``--prefix``, ``--vehicle`` (``args.connect`` None means
    ``[DEFAULT_ENDPOINT]``). Each is checked as it is parsed (an endpoint's form, the
    file's existence, the key chunks), so a bad one is a one-line usage error."""
    parser.add_argument("--connect", action="append", default=None, metavar="ENDPOINT", type=zenoh_endpoint,
                        help=f"zenoh endpoint of the service (default {DEFAULT_ENDPOINT}; repeatable)")
    parser.add_argument("--zenoh-config", default=None, metavar="FILE", type=existing_file,
                        help="zenoh configuration file (JSON5) as the session's base, e.g. TLS certificates "
                             "(docs/zenoh/user-tls.json5); --connect is applied on top")
    parser.add_argument("--prefix", default="uavmec", type=key_chunk, help="key prefix (default uavmec)")
    parser.add_argument("--vehicle", default="uav1", type=key_chunk, help="vehicle id (default uav1)")
