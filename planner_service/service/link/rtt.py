"""How long to wait for the autopilot's answer before repeating a message: the round trip
measured on the link, as TCP does (Jacobson/Karels, RFC 6298): a smoothed round-trip time
and its variation, the wait their sum with four variations, bounded by ``floor_s`` and
``ceiling_s`` (``mavlink.item_timeout_s``). Only exchanges answered at the first try are
measured (Karn's rule: after a repeat the answer may be to either copy). Pure.

On a lossy link each lost message costs one wait: with a fixed 0.5 s and a 50 ms round
trip, 20 % loss each way makes an upload several times slower than it need be.
"""

from __future__ import annotations

ALPHA = 1 / 8
BETA = 1 / 4
K = 4.0


class RetryTimer:
    def __init__(self, ceiling_s: float, floor_s: float = 0.1) -> None:
        if not 0 < floor_s <= ceiling_s:
            raise ValueError(f"need 0 < floor_s <= ceiling_s, got {floor_s}, {ceiling_s}")
        self.ceiling_s = ceiling_s
        self.floor_s = floor_s
        self.srtt_s: float | None = None
        self.rttvar_s = 0.0

    def sample(self, rtt_s: float) -> None:
        """A round trip answered at the first try."""
        if rtt_s < 0:
            return
        if self.srtt_s is None:
            self.srtt_s, self.rttvar_s = rtt_s, rtt_s / 2
        else:
            self.rttvar_s = (1 - BETA) * self.rttvar_s + BETA * abs(self.srtt_s - rtt_s)
            self.srtt_s = (1 - ALPHA) * self.srtt_s + ALPHA * rtt_s

    @property
    def timeout_s(self) -> float:
        """The wait before repeating: the ceiling until a round trip was measured."""
        if self.srtt_s is None:
            return self.ceiling_s
        return min(max(self.srtt_s + K * self.rttvar_s, self.floor_s), self.ceiling_s)
