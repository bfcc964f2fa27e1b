"""``python -m sim_bridge``: the software vehicle, simulated users, a lossy link, a router and
emulated radio links."""

from __future__ import annotations

import importlib
import sys

from protocol.arguments import OneLineParser
from protocol.closed_stdout import quiet_on_closed_stdout

COMMANDS = {
    "vehicle": "sim_bridge.commands.vehicle",
    "users": "sim_bridge.commands.users",
    "lossy-proxy": "sim_bridge.commands.lossy_proxy",
    "router": "sim_bridge.commands.router",
    "wire": "sim_bridge.commands.wire",
}


def build_parser() -> OneLineParser:
    """Every error of the command line is one line naming the option, exit status 2."""
    parser = OneLineParser(
        prog="python -m sim_bridge",
        description="Simulated counterparts of the planner: a MAVLink vehicle (SITL-stub), "
        "ground users over zenoh, a lossy UDP link, a zenoh router, and emulated radio links between network namespaces.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, path in COMMANDS.items():
        module = importlib.import_module(path)
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
