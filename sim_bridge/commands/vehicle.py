"""The `vehicle` command (not yet built)."""

from __future__ import annotations

import argparse
import sys

HELP = "vehicle (not yet built)"


def configure(parser: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> int:
    print("vehicle: not yet built", file=sys.stderr)
    return 2
