"""Emulated radio links between network namespaces (netem in user space: this kernel has no
netem). Each ``--link`` joins two TUN devices made beforehand, carrying every IP packet after
its delay +- jitter and dropping it with its loss; lines on stdin cut and restore a link
while it runs (``cut NAME``, ``restore NAME``). Needs root (entering the namespaces). Runs
until SIGINT or SIGTERM; its figures (packets, bytes, drops, packets delivered late per link
and direction) go to ``--stats-file`` every second and at the end (``at``: the machine's
monotonic clock)."""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import os
import random
import signal
import sys
import time
from pathlib import Path

HELP = "carry IP packets between network namespaces with delay, jitter and loss (netem in user space)"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--link", action="append", required=True, metavar="NAME=NS_A:DEV_A,NS_B:DEV_B,DELAY_MS,JITTER_MS,LOSS",
                        help="a link between TUN device DEV_A in namespace NS_A and DEV_B in NS_B (- : this "
                             "process's namespace), each way DELAY_MS +- JITTER_MS (uniform) and dropped with "
                             "probability LOSS (repeatable)")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    parser.add_argument("--stats-file", default=None, metavar="PATH", help="JSON figures per link, every second")
    parser.add_argument("--nice", type=int, default=0, metavar="N",
                        help="run at this niceness (negative: ahead of the processes it carries for, as a "
                             "radio does not wait for their CPU; needs root; default 0)")
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(stream=sys.stderr, level=args.log_level, format="%(asctime)s wire %(levelname)s: %(message)s")
    from sim_bridge.wire import WireError, WireLink, attach_tun, parse_link

    if args.nice:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, args.nice)
        except OSError as err:
            print(f"wire: --nice {args.nice}: {err}", file=sys.stderr)
            return 2
    rng = random.Random(args.seed)
    try:
        specs = [parse_link(text) for text in args.link]
        links = {s.name: WireLink(s, attach_tun(s.a), attach_tun(s.b), random.Random(rng.random())) for s in specs}
    except WireError as err:
        print(f"wire: {err}", file=sys.stderr)
        return 2
    asyncio.run(_serve(links, Path(args.stats_file) if args.stats_file else None))
    return 0


async def _serve(links: dict, stats_file: Path | None) -> None:
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    for link in links.values():
        link.start(loop)
    try:
        loop.add_reader(sys.stdin.fileno(), _command, links)
    except (PermissionError, ValueError):  # stdin a file or /dev/null: nobody will cut a link
        pass
    logging.info("wire ready: %d links (%s)", len(links), ", ".join(
        f"{n} {l.impairment.delay_ms:g}+-{l.impairment.spread_s * 1000:g} ms loss {l.impairment.drop:g}"
        for n, l in links.items()))
    while not stop.is_set():
        _write_stats(links, stats_file)
        try:
            await asyncio.wait_for(stop.wait(), 1.0)
        except asyncio.TimeoutError:
            pass
    _write_stats(links, stats_file)
    logging.info("wire figures: %s", json.dumps({n: l.figures() for n, l in links.items()}))


def _command(links: dict) -> None:
    line = sys.stdin.readline()
    if not line:  # stdin closed: nobody will cut a link any more
        asyncio.get_running_loop().remove_reader(sys.stdin.fileno())
        return
    verb, _, name = line.strip().partition(" ")
    link = links.get(name)
    if verb not in ("cut", "restore") or link is None:
        logging.warning("wire: %r is not 'cut NAME' or 'restore NAME' of a link (%s)", line.strip(), ", ".join(links))
        return
    link.is_cut = verb == "cut"
    logging.info("link %s %s", name, "cut" if link.is_cut else "restored")


def _write_stats(links: dict, path: Path | None) -> None:
    if path is None:
        return
    tmp = path.with_suffix(".tmp")
    # when, on the machine's monotonic clock (one for every process): a reader takes rates
    tmp.write_text(json.dumps({"at": time.monotonic(), "links": {n: l.figures() for n, l in links.items()}}))
    os.replace(tmp, path)
