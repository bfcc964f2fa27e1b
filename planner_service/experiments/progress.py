"""A progress bar on stderr, by hand (one class; not worth a dependency)."""

from __future__ import annotations

import sys
import time
from typing import Callable, TextIO


def _clock() -> float:
    return time.monotonic()


class Progress:
    """``label [#####.....] done/total pct elapsed, ~left``.

    Items may carry a weight (an estimate of their cost): the bar, the percentage and the
    time left then follow the weights, while done/total still counts items, because an
    experiment's first jobs (the longest) would otherwise predict hours.
    On a terminal the line redraws in place (at most every 0.2 s); in a log (not a tty) a
    line is printed at every tenth of the work, so that CI logs stay short.
    """

    def __init__(self, total: int, label: str = "", stream: TextIO | None = None,
                 clock: Callable[[], float] = _clock, width: int = 30) -> None:
        self.total = max(int(total), 0)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.clock = clock
        self.width = width
        self.done = 0
        self.total_weight = 0.0
        self.done_weight = 0.0
        self.start = clock()
        self._last_draw = -1.0
        self._last_decile = -1
        self._tty = bool(getattr(self.stream, "isatty", lambda: False)())

    def update(self, n: int = 1, weight: float = 0.0) -> None:
        self.done = min(self.done + n, self.total)
        self.done_weight += weight
        now = self.clock()
        if self._tty:
            if now - self._last_draw >= 0.2 or self.done == self.total:
                self._last_draw = now
                self.stream.write("\r" + self.line(now))
                self.stream.flush()
        else:
            decile = int(10 * self.fraction())
            if decile != self._last_decile:
                self._last_decile = decile
                self.stream.write(self.line(now) + "\n")
                self.stream.flush()

    def close(self) -> None:
        if self._tty:
            self.stream.write("\r" + self.line(self.clock()) + "\n")
            self.stream.flush()

    def fraction(self) -> float:
        if self.done >= self.total:
            return 1.0
        if self.total_weight > 0:
            return min(self.done_weight / self.total_weight, 1.0)
        return self.done / self.total

    def line(self, now: float) -> str:
        frac = self.fraction()
        filled = int(round(frac * self.width))
        elapsed = now - self.start
        left = elapsed * (1 - frac) / frac if frac > 0 else float("nan")
        eta = f", ~{_fmt(left)} left" if 0 < frac < 1 else ""
        bar = "#" * filled + "." * (self.width - filled)
        return f"{self.label} [{bar}] {self.done}/{self.total} {100 * frac:3.0f}% {_fmt(elapsed)}{eta}"


def _fmt(seconds: float) -> str:
    if seconds != seconds:  # nan
        return "?"
    s = int(round(seconds))
    return f"{s // 60}:{s % 60:02d}"


__all__ = ["Progress"]
