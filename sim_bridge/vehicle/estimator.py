"""When the simulated vehicle knows where it is: the stages of a position estimate after boot.

Observed on ArduCopter SITL (V4.7.0-dev, ``--speedup 5`` and 10, times since boot):
the GPS reports no fix and GLOBAL_POSITION_INT carries lat/lon 0 for the first 9 s
(``GPS 1: detected u-blox``); from then on GLOBAL_POSITION_INT carries the GPS position,
but EKF_STATUS_REPORT has no absolute horizontal position (flags 0xa7) and no home is set;
at 20 s the EKF has an origin (``EKF3 IMU0 origin set``, HOME_POSITION and
GPS_GLOBAL_ORIGIN sent once, unasked); at 41 s ``EKF3 IMU0 is using GPS`` (flags 0x33f)
and only then do arming in a position mode and AUTO work. The stub keeps those proportions
of one delay, ``gps_delay_s`` (the time to ``is using GPS``).
"""

from __future__ import annotations

import enum

GPS_FIX_FRACTION = 9.0 / 41.0
ORIGIN_FRACTION = 20.0 / 41.0
DEFAULT_GPS_DELAY_S = 40.0
"""Near ArduCopter SITL's 41 s to ``EKF3 IMU0 is using GPS``."""

EKF_FLAGS_NO_GPS = 0xA7
"""ATTITUDE | VELOCITY_HORIZ | VELOCITY_VERT | POS_VERT_ABS | CONST_POS_MODE, as SITL
reports before the EKF uses GPS."""
EKF_FLAGS_GPS = 0x33F
"""Attitude, velocities, relative and absolute horizontal position, vertical position and
the predicted positions: SITL's flags once ``is using GPS``."""


class Stage(enum.IntEnum):
    """How much the vehicle knows, in order."""

    NO_GPS = 0
    """No GPS fix: no position at all (GLOBAL_POSITION_INT lat/lon 0)."""
    GPS = 1
    """A GPS fix, but no estimator origin: no home, no navigation."""
    ORIGIN = 2
    """The estimator has an origin and home is set; still no position estimate."""
    NAVIGATING = 3
    """The estimator uses GPS: a valid position, arming and AUTO allowed."""


def stage_at(since_boot_s: float, gps_delay_s: float) -> Stage:
    """The stage ``since_boot_s`` simulated seconds after boot."""
    if since_boot_s >= gps_delay_s:
        return Stage.NAVIGATING
    if since_boot_s >= ORIGIN_FRACTION * gps_delay_s:
        return Stage.ORIGIN
    if since_boot_s >= GPS_FIX_FRACTION * gps_delay_s:
        return Stage.GPS
    return Stage.NO_GPS
