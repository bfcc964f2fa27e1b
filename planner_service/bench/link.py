"""Mission upload time over a lossy MAVLink link: the service's own pymavlink link uploads a
typical mission (8 hovering points, 11 items) N times to the vehicle stub through the
lossy proxy, at each loss rate (each way), with the same delay at every rate so that the
ratio to the clean link isolates the loss. Real processes on loopback: ``sim_bridge
vehicle`` and ``sim_bridge lossy-proxy``; the link's settings are the service's defaults
(``mavlink.item_timeout_s`` 0.5 s as the longest wait, ``retries`` 10)."""

from __future__ import annotations

import asyncio
import socket
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

from protocol import GeoOrigin, HoverPoint, encode_path

from ..service.config import MavlinkConfig
from ..service.errors import LinkError
from ..service.link import LinkSettings
from ..harness.processes import Child, free_port
from .e2e import percentile

RATES = (0.0, 0.05, 0.2)
DELAY_MS = 20.0
JITTER_MS = 20.0


def typical_missions() -> tuple[list, list]:
    """Two missions of 8 points (11 items with ArduPilot's home, the takeoff and the return):
    uploaded in turn, so every upload changes what the vehicle holds."""
    a = [HoverPoint(60.0 + 45.0 * i, 440.0 - 40.0 * i, 50.0, 12.0 + i) for i in range(8)]
    b = [HoverPoint(440.0 - 45.0 * i, 60.0 + 40.0 * i, 50.0, 20.0 - i) for i in range(8)]
    return encode_path(a, GeoOrigin(), "ardupilot"), encode_path(b, GeoOrigin(), "ardupilot")


def run_link_bench(uploads: int = 50, rates: tuple[float, ...] = RATES, seed: int = 1,
                   progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Upload time (median, p90, max) and failures at each loss rate; ``ratio``: median
    over the clean link's median (the first rate should be 0)."""
    if uploads < 1 or not rates or any(not 0.0 <= r < 1.0 for r in rates):
        raise ValueError("uploads must be at least 1 and every loss rate in [0, 1)")
    say = progress or (lambda _: None)
    with tempfile.TemporaryDirectory(prefix="uav-link-") as tmp:
        folder = Path(tmp)
        children: list[Child] = []
        try:
            vehicle_port = free_port(socket.SOCK_DGRAM)
            vehicle = Child("sim_bridge", ["vehicle", "--mavlink", f"udpin:127.0.0.1:{vehicle_port}"],
                            folder / "vehicle.log")
            children.append(vehicle)
            vehicle.wait_ready("listening")
            rows = []
            for rate in rates:
                say(f"link: {uploads} uploads at {rate:.0%} loss each way")
                port = free_port(socket.SOCK_DGRAM)
                proxy = Child("sim_bridge", ["lossy-proxy", "--listen", f"127.0.0.1:{port}", "--forward",
                                             f"127.0.0.1:{vehicle_port}", "--drop", str(rate), "--delay-ms",
                                             str(DELAY_MS), "--jitter-ms", str(JITTER_MS), "--seed", str(seed)],
                              folder / f"proxy-{rate}.log")
                children.append(proxy)
                proxy.wait_ready("lossy proxy")
                rows.append({"loss": rate, **asyncio.run(_uploads(port, uploads))})
                proxy.stop()
        finally:
            for child in reversed(children):
                child.stop()
    clean = rows[0]["median_ms"] if rows[0]["loss"] == 0.0 and rows[0]["median_ms"] else None
    for row in rows:
        row["ratio"] = row["median_ms"] / clean if clean and row["median_ms"] is not None else None
    return {"uploads": uploads, "items": len(typical_missions()[0]), "delay_ms": DELAY_MS, "jitter_ms": JITTER_MS,
            "item_timeout_s": MavlinkConfig().item_timeout_s, "retries": MavlinkConfig().retries, "rates": rows}


async def _uploads(port: int, count: int) -> dict[str, Any]:
    from ..service.link.mavlink_link import PymavlinkLink

    m = MavlinkConfig()
    link = PymavlinkLink(LinkSettings(f"udpout:127.0.0.1:{port}", "ardupilot", m.item_timeout_s, m.retries,
                                      m.link_timeout_s, m.source_system, m.source_component), lambda ev: None)
    missions = typical_missions()
    times_ms: list[float] = []
    failures: list[str] = []
    try:
        await link.connect(10.0)
        for i in range(count):
            t0 = time.perf_counter()
            try:
                await link.upload(missions[i % 2])
            except LinkError as err:
                failures.append(err.result)
                continue
            times_ms.append((time.perf_counter() - t0) * 1e3)
    finally:
        await link.close()
    return {
        "accepted": len(times_ms), "failures": len(failures), "failure_results": failures[:5],
        "median_ms": statistics.median(times_ms) if times_ms else None,
        "p90_ms": percentile(times_ms, 90) if times_ms else None,
        "max_ms": max(times_ms) if times_ms else None,
        "retry_wait_ms": link.timer.timeout_s * 1e3,
    }


def format_link(r: dict[str, Any]) -> str:
    lines = [f"mission upload over a lossy link ({r['items']} items, {r['uploads']} uploads per rate, "
             f"{r['delay_ms']:g} +- {r['jitter_ms']:g} ms each way, item_timeout_s {r['item_timeout_s']:g} "
             f"as the longest wait, retries {r['retries']}):",
             f"{'loss each way':>14} {'median ms':>10} {'p90 ms':>8} {'max ms':>8} {'failures':>9} {'x clean':>8} "
             f"{'retry wait ms':>14}"]
    for row in r["rates"]:
        def ms(v: float | None) -> str:
            return "-" if v is None else f"{v:.0f}"
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.1f}"
        lines.append(f"{row['loss']:>13.0%} {ms(row['median_ms']):>10} {ms(row['p90_ms']):>8} {ms(row['max_ms']):>8} "
                     f"{row['failures']:>9} {ratio:>8} {row['retry_wait_ms']:>14.0f}")
    return "\n".join(lines)
