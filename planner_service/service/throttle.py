"""A token bucket, for the service's rate bounds (accepted requests, refusal events).

Pure: the caller passes the time, so tests pin it. Give it a monotonic clock: a clock going
back adds no tokens, and the bucket counts on from where it went (it does not wait for the
clock to catch up again), so a wall clock stepped back an hour refuses nothing for an hour.
"""

from __future__ import annotations


class RateLimit:
    """``rate_per_s`` tokens a second, at most ``burst`` held (default: one second's worth)."""

    def __init__(self, rate_per_s: float, now_s: float, burst: float | None = None) -> None:
        if not rate_per_s > 0:
            raise ValueError(f"rate_per_s must be positive, got {rate_per_s}")
        self.rate_per_s = rate_per_s
        self.burst = max(burst if burst is not None else rate_per_s, 1.0)
        self.tokens = self.burst
        self._t = now_s

    def take(self, now_s: float) -> bool:
        """Spend one token if there is one."""
        self.tokens = min(self.burst, self.tokens + max(now_s - self._t, 0.0) * self.rate_per_s)
        self._t = now_s
        if self.tokens < 1.0:
            return False
        self.tokens -= 1.0
        return True
