"""Create a MAVLink 2 signing key file: 32 random bytes as 64 hex characters, mode 0600,
never overwriting an existing file. Give the same file to the service
(``mavlink.signing_key_file``) and the vehicle stub (``--signing-key``).

With ``--passphrase`` the key is the SHA-256 of a passphrase read from standard input
(one line, ASCII), which is what MAVProxy's ``signing setup PASSPHRASE`` puts on an
ArduPilot vehicle: the same passphrase there gives the same key here."""

from __future__ import annotations

import argparse
import sys

HELP = "create a MAVLink 2 signing key file (mode 0600)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", metavar="PATH", help="the key file to create (refused if it exists)")
    parser.add_argument("--passphrase", action="store_true",
                        help="derive the key from a passphrase read from stdin (SHA-256, as MAVProxy and Mission "
                             "Planner do) instead of drawing a random one")


def run(args: argparse.Namespace) -> int:
    from protocol.errors import SigningError
    from protocol.signing import key_from_passphrase, write_key

    try:
        key = None
        if args.passphrase:
            # Read from stdin, never from argv: a command line is visible to every user (ps).
            passphrase = sys.stdin.readline().rstrip("\r\n")
            if not passphrase:
                print("keygen: the passphrase on stdin is empty", file=sys.stderr)
                return 2
            key = key_from_passphrase(passphrase)
        write_key(args.path, key)
    except SigningError as err:
        print(f"keygen: {err}", file=sys.stderr)
        return 2
    print(f"wrote a {'passphrase' if args.passphrase else 'random'} signing key to {args.path} (mode 0600)")
    return 0
