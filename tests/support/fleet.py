"""What the fleet membership tests share: a member's announcement at the tests' origin, and a
wait on a condition with a deadline (polled: zenoh calls back on its own threads)."""

from __future__ import annotations

import time
from typing import Callable

from protocol.messages import FleetMember


def member(vehicle: str, layer_m: float, gap_m: float = 10.0) -> FleetMember:
    return FleetMember(vehicle=vehicle, layer_m=layer_m, min_gap_m=gap_m, origin_lat_deg=47.397742,
                       origin_lon_deg=8.545594, origin_alt_m=488.0)


def wait_until(check: Callable[[], bool], timeout_s: float, what: str | Callable[[], str]) -> None:
    """Until ``check()``, or fail naming ``what`` (a callable: said as it stands at the end)."""
    deadline = time.monotonic() + timeout_s
    while not check():
        assert time.monotonic() < deadline, f"not within {timeout_s} s: {what() if callable(what) else what}"
        time.sleep(0.02)
