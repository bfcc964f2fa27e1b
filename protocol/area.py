"""The service area: the bounds every position on the wire and in a mission must respect."""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import ProtocolError


@dataclass(frozen=True)
class Area:
    """A square ``[0, side_m]^2`` in local metres (x east, y north) and altitude limits.

    ``max_altitude_m`` bounds every z (users' terrain and the UAV alike);
    ``min_flight_altitude_m`` is the lowest a mission waypoint may be, so that a plan
    never asks the aircraft to hover at ground level.
    """

    side_m: float = 500.0
    max_altitude_m: float = 150.0
    min_flight_altitude_m: float = 5.0

    def __post_init__(self) -> None:
        for name in ("side_m", "max_altitude_m", "min_flight_altitude_m"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ProtocolError(name, f"must be a finite non-negative number, got {value!r}")
        if self.side_m <= 0:
            raise ProtocolError("side_m", "must be positive")
        if self.min_flight_altitude_m > self.max_altitude_m:
            raise ProtocolError("min_flight_altitude_m", "must not exceed max_altitude_m")

    def contains_xy(self, x_m: float, y_m: float) -> bool:
        """Is (x, y) inside the square, edges included?"""
        return 0.0 <= x_m <= self.side_m and 0.0 <= y_m <= self.side_m
