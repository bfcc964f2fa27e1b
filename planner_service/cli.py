"""``python -m planner_service``: one subcommand per module in ``commands/``."""

from __future__ import annotations

import importlib
import sys

from protocol.arguments import OneLineParser
from protocol.closed_stdout import quiet_on_closed_stdout

COMMANDS = ("serve", "demo", "plan", "experiment", "bench", "submit", "keygen", "fleet-key", "operator", "export", "warm")


def build_parser() -> OneLineParser:
    """Every error of the command line is one line naming the option, exit status 2."""
    parser = OneLineParser(
        prog="python -m planner_service",
        description="Flight-side MCTS path planner for UAV-aided wireless systems.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMANDS:
        module = importlib.import_module(f"planner_service.commands.{name.replace('-', '_')}")
        cmd = sub.add_parser(name, help=module.HELP, description=module.__doc__)
        module.configure(cmd)
        cmd.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command; a reader of stdout that went away (``| head -1``) ends it quietly,
    exit status 141 (``protocol.closed_stdout``)."""
    return quiet_on_closed_stdout(lambda: _run(argv))


def _run(argv: list[str] | None) -> int:
    args = build_parser().parse_args(argv)
    return int(args._run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
