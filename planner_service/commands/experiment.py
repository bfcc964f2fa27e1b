"""The `experiment` command (not yet built)."""

from __future__ import annotations

import argparse

from .common import not_yet_built

HELP = "experiment (not yet built)"


def configure(parser: argparse.ArgumentParser) -> None:
    pass


def run(args: argparse.Namespace) -> int:
    return not_yet_built("experiment")
