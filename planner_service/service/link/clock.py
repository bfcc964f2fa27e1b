"""The vehicle's clock as its position reports show it (GLOBAL_POSITION_INT.time_boot_ms):
how fast it runs against the wall (``ClockRate``) and when it restarted (``ClockWatch``).
No I/O; ``state.VehicleState`` feeds them.

Unsigned, any host on the network can send a report from the autopilot's own ids. One
report proves nothing: a restart (or any new clock) is believed only from several reports of
the new clock, consistent with each other and with the wall time between them, with no report
of the clock kept in between. A reading far ahead of the clock kept (one forged
``time_boot_ms`` of hours) is an outlier, discarded: never a new reference, so the
vehicle's own reports after it do not look like a clock gone back (issue 34, finding 8: one
such datagram made them so and a restart was believed half a second later).

What a real reboot shows: ArduPilot and PX4 restart ``time_boot_ms`` near 0 and it grows at
the vehicle's rate from then on (the stub's ``--state-file`` restart does the same); the link
asks for the streams again after the silence, and GLOBAL_POSITION_INT comes at 10 Hz, so
the readings needed come within about ``RESTART_CONFIRM_S`` of the first.
"""

from __future__ import annotations

RESTART_SLACK_S = 2.0
"""Vehicle seconds (times the vehicle's clock rate) by which a reading may differ from the
clock kept and still belong to it (a reordered datagram, a report delayed)."""
RESTART_CONFIRM_S = 0.5
"""Wall seconds over which the readings of a new clock must go on before it is believed: a
rebooted autopilot streams its position for as long as it runs (an unsigned datagram can
carry two readings, or twenty)."""
RESTART_CONFIRM_READINGS = 3
"""Readings of a new clock, each arriving after the one before, needed to believe it."""
MAX_CLOCK_RATE = 200.0
"""Vehicle seconds per wall second no simulator reaches: the bound on how far ahead a reading
may be while the rate is not measured yet."""
AHEAD_FACTOR = 2.0
"""A clock measured at rate r is taken to run at no more than this times r (a simulator's
pace varies with its host's load)."""


class ClockRate:
    """Vehicle seconds per wall second, measured from the vehicle's own timestamps over a
    window of a few seconds (so the service never assumes the two clocks run alike). None
    until the first window, a shorter one, has passed: a service restarted in the air beside
    a simulator at x80 that took the rate as 1 meanwhile planned its first decisions as if a
    battery reading a second old were a second of flight old, not 80 (a CI run: the
    vehicle's battery failsafe fired on the way home)."""

    FIRST_WINDOW_S = 1.0
    WINDOW_S = 3.0

    def __init__(self) -> None:
        self._anchor: tuple[float, float] | None = None
        self.rate: float | None = None

    def update(self, vehicle_s: float, wall_s: float) -> float | None:
        if self._anchor is None or vehicle_s < self._anchor[0]:
            self._anchor = (vehicle_s, wall_s)
            return self.rate
        dv, dw = vehicle_s - self._anchor[0], wall_s - self._anchor[1]
        if dw >= (self.FIRST_WINDOW_S if self.rate is None else self.WINDOW_S):
            self.rate = max(dv / dw, 0.0)
            self._anchor = (vehicle_s, wall_s)
        return self.rate


def fits(anchor: tuple[float, float], boot_s: float, wall_s: float, rate: float | None,
         slack_s: float = RESTART_SLACK_S) -> bool:
    """Does a reading ``boot_s`` at ``wall_s`` belong to the clock last read at ``anchor``
    (vehicle seconds, wall seconds)? Not more than the slack behind it, and not further
    ahead than the wall time since could carry it at the fastest the clock may run (its
    measured ``rate`` times ``AHEAD_FACTOR``; ``MAX_CLOCK_RATE`` while unknown)."""
    last_boot, last_wall = anchor
    slack = slack_s * max(rate or 1.0, 1.0)
    fastest = MAX_CLOCK_RATE if rate is None else max(rate, 1.0) * AHEAD_FACTOR
    return last_boot - slack <= boot_s <= last_boot + max(wall_s - last_wall, 0.0) * fastest + slack


class ClockWatch:
    """The vehicle's clock (time_boot_ms) and the restarts it shows. ``observe`` says "ok"
    (the reading counts), "outlier" (ignore the message that carried it: one reading of
    another clock, behind or ahead, is only a suspicion), "restart" (a new clock behind the
    one kept is believed) or "jump" (a new clock ahead of it is believed: no restart, a
    simulator sped up, or a link silent longer than the clock's pace could tell).

    A new clock is believed after ``confirm_readings`` readings of it, each fitting the one
    before (``fits``) and arriving after it, spread over ``confirm_s`` of wall time and
    growing, with no reading of the clock kept between them (the vehicle's own stream goes on
    beside a forged one and clears it). Unsigned, the link cannot tell a forged series that
    is all it hears from a restart: a restart only ever ends the service's authority, and
    signing is the fix (docs/OPERATIONS.md)."""

    def __init__(self, slack_s: float = RESTART_SLACK_S, confirm_s: float = RESTART_CONFIRM_S,
                 confirm_readings: int = RESTART_CONFIRM_READINGS) -> None:
        self.slack_s = slack_s
        self.confirm_s = confirm_s
        self.confirm_readings = confirm_readings
        self.boot_s: float | None = None
        """The clock kept: the latest reading that counted."""
        self._at: float = 0.0
        """Wall time of ``boot_s``."""
        self._new: list[tuple[float, float]] = []
        """(vehicle, wall) readings of a suspected new clock, oldest first."""

    def observe(self, boot_s: float, rate: float | None, wall_s: float) -> str:
        if self.boot_s is None or fits((self.boot_s, self._at), boot_s, wall_s, rate, self.slack_s):
            if self.boot_s is None or boot_s >= self.boot_s:
                self.boot_s, self._at = boot_s, wall_s
            self._new.clear()
            return "ok"
        new = self._new
        if new and not (wall_s > new[-1][1] and fits(new[-1], boot_s, wall_s, rate, self.slack_s)):
            new.clear()  # not the same new clock: this reading may begin another
        new.append((boot_s, wall_s))
        if (len(new) < self.confirm_readings or wall_s - new[0][1] < self.confirm_s
                or not new[-1][0] > new[0][0]):
            return "outlier"
        verdict = "restart" if boot_s < self.boot_s else "jump"
        self.boot_s, self._at = boot_s, wall_s
        new.clear()
        return verdict

    def reset(self) -> None:
        self.boot_s, self._at = None, 0.0
        self._new.clear()
