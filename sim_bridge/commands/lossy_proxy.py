"""A lossy UDP proxy between a ground station and a vehicle: drops, duplicates, delays and
reorders datagrams both ways (seeded), to test that links survive. Runs until killed."""

from __future__ import annotations

import argparse
import asyncio
import logging
import random
import signal
import sys

from protocol.arguments import non_negative_float, probability

HELP = "run a lossy UDP proxy between a ground station and a vehicle"


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", required=True, metavar="HOST:PORT", help="where ground stations send")
    parser.add_argument("--forward", required=True, metavar="HOST:PORT", help="the vehicle's address")
    parser.add_argument("--drop", type=probability, default=0.0,
                        help="probability of dropping a datagram (each way)")
    parser.add_argument("--dup", type=probability, default=0.0, help="probability of duplicating a datagram")
    parser.add_argument("--delay-ms", type=non_negative_float, default=0.0, help="mean one-way delay in milliseconds")
    parser.add_argument("--jitter-ms", type=non_negative_float, default=None,
                        help="delay spread (uniform +-, default half the delay): reorders datagrams")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random draw (default 0)")
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(stream=sys.stderr, level=args.log_level,
                        format="%(asctime)s proxy %(levelname)s: %(message)s")
    from sim_bridge.proxy import Impairment, LossyProxy, ProxyError, parse_address

    try:
        proxy = LossyProxy(
            parse_address(args.listen, "--listen"), parse_address(args.forward, "--forward"),
            Impairment(drop=args.drop, dup=args.dup, delay_ms=args.delay_ms, jitter_ms=args.jitter_ms),
            random.Random(args.seed),
        )
    except ProxyError as exc:
        print(f"lossy-proxy: {exc}", file=sys.stderr)
        return 2

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        await proxy.serve(stop)

    try:
        asyncio.run(main())
    except ProxyError as exc:
        print(f"lossy-proxy: {exc}", file=sys.stderr)
        return 2
    return 0
