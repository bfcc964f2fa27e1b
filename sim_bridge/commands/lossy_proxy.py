"""The `lossy-proxy` command (not yet built)."""

from __future__ import annotations

import argparse
import sys

HELP = "lossy-proxy (not yet built)"


def configure(parser: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> int:
    print("lossy-proxy: not yet built", file=sys.stderr)
    return 2
