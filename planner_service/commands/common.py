"""Arguments several commands share: the scenario and its overrides."""

from __future__ import annotations

import argparse
import sys

from ..model import PRESETS, Scenario, ScenarioError, preset


def add_scenario_arguments(parser: argparse.ArgumentParser, default: str | None = "paper",
                           default_help: str = "paper") -> None:
    """``--preset`` (``default``: None when the command picks it, ``default_help`` saying how)
    and ``--set``."""
    parser.add_argument("--preset", default=default, choices=sorted(PRESETS),
                        help=f"scenario preset (default: {default_help})")
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="NAME=VALUE",
        help="override a scenario field, e.g. --set speed_mps=10 (repeatable; see docs/MODEL.md)",
    )


def scenario_from_args(args: argparse.Namespace) -> Scenario:
    """The preset with the command line's overrides; exits with a message on a bad one."""
    try:
        return preset(args.preset).with_overrides(list(args.overrides))
    except ScenarioError as err:
        print(f"error: {err}", file=sys.stderr)
        raise SystemExit(2) from None


