"""Enrol a vehicle in a fleet: create its fleet signing key (Ed25519, mode 0600, never
overwriting a file) and add its public key to the fleet's roster file (created if missing).

Give the key to that vehicle's service alone (``fleet.key_file``) and the roster to every
member (``fleet.roster_file``) and to ``operator watch --fleet-roster``: a member reads the
fleet's messages only from the vehicles enrolled there (docs/OPERATIONS.md, "A fleet")."""

from __future__ import annotations

import argparse
import sys

HELP = "enrol a vehicle in a fleet: its signing key (mode 0600) and its line in the fleet's roster"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("key", metavar="KEY", help="the vehicle's key file to create (refused if it exists)")
    parser.add_argument("--vehicle", required=True, help="the vehicle id it signs for (zenoh.vehicle)")
    parser.add_argument("--roster", required=True, metavar="FILE",
                        help="the fleet's roster: its public key is added (refused if the vehicle is already there)")


def run(args: argparse.Namespace) -> int:
    from protocol.errors import SigningError
    from protocol.fleet_signing import make_vehicle_key

    try:
        line = make_vehicle_key(args.key, args.roster, args.vehicle)
    except SigningError as err:
        print(f"fleet-key: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.vehicle}'s fleet key to {args.key} (mode 0600); enrolled in {args.roster}: {line}")
    return 0
