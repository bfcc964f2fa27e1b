"""The vehicle as the link knows it (``Telemetry``) and the pure judgements made of what
the autopilot reports: does it have a position, is it airborne, how full is its battery
(its clock and restarts: ``clock``). No I/O; the backends feed them.

A position counts only when the autopilot has one (``assess_position``): a 3-D GPS fix,
an estimator that reports an absolute horizontal position (ArduPilot's EKF_STATUS_REPORT,
PX4's ESTIMATOR_STATUS), home set, and never latitude/longitude 0/0. ArduCopter reports
lat/lon 0 for its first seconds and the GPS's own position (not the EKF's) until the EKF
uses the GPS, which is when arming and AUTO become possible (observed on SITL: EKF flags
0xa7, constant-position mode, until "EKF3 IMU0 is using GPS", then 0x33f). A criterion
whose message the autopilot refuses to send is skipped (the message is named in
``Telemetry.missing``); one that is only late blocks, naming what it waits for.
"""

from __future__ import annotations

from dataclasses import dataclass

from .clock import ClockRate, ClockWatch

__all__ = ["ClockRate", "ClockWatch", "PositionInputs", "Telemetry", "assess_position", "battery_fraction",
           "derived_airborne", "energy_used_j"]

GPS_FIX_3D = 3
"""GPS_FIX_TYPE_3D_FIX: 3-D fix or better (DGPS 4, RTK 5-6)."""
EST_POS_HORIZ_ABS = 16
"""EKF_POS_HORIZ_ABS (ArduPilot's EKF_STATUS_REPORT) = ESTIMATOR_POS_HORIZ_ABS (PX4)."""
EST_BAD = 1024
"""EKF_UNINITIALIZED (ArduPilot) / ESTIMATOR_GPS_GLITCH (PX4): no usable position either way."""
AIRBORNE_ALT_M = 1.0
"""Derived landed state: armed and this far above home, or climbing, is airborne..."""
AIRBORNE_CLIMB_MPS = 0.5
LANDED_ALT_M = 0.5
"""...and airborne until below this height with the climb (either way) under ``LANDED_CLIMB_MPS``."""
LANDED_CLIMB_MPS = 0.3
@dataclass(frozen=True)
class Telemetry:
    """The vehicle as last reported by its autopilot (only its own system and component count)."""

    connected: bool = False
    position_ok: bool = False
    """The autopilot has a position (``assess_position``): plan on it, arm on it."""
    waiting_for: str = "autopilot: no heartbeat yet"
    """What the position waits for ('' when ``position_ok``)."""
    lat_deg: float = 0.0
    lon_deg: float = 0.0
    rel_alt_m: float = 0.0
    climb_mps: float = 0.0
    """Upwards speed (GLOBAL_POSITION_INT.vz, which is down positive)."""
    position_boot_s: float | None = None
    """The vehicle's own time of the last position (time_boot_ms / 1000), to judge holds in
    vehicle time; None before one came."""
    position_at: float = 0.0
    """``time.monotonic()`` when the position was last reported."""
    gps_fix: int = -1
    """GPS_RAW_INT.fix_type (GPS_FIX_TYPE); -1: not reported."""
    home_set: bool = False
    battery_fraction: float | None = None
    """Remaining charge 0..1; None: unknown (not reported, -1 or impossible), never taken as full."""
    energy_used_j: float | None = None
    """From BATTERY_STATUS.energy_consumed (hJ) when the autopilot reports it."""
    battery_at: float = 0.0
    """``time.monotonic()`` when the battery was last reported."""
    armed: bool = False
    airborne: bool = False
    landed_known: bool = False
    """The vehicle has said (or the link derived) whether it is in the air."""
    landed_source: str = ""
    """Where ``airborne`` comes from: "EXTENDED_SYS_STATE", or "derived (armed, relative
    altitude, climb)" where the autopilot gives no landed state; '' before either."""
    mode: str = ""
    mission_seq: int = 0
    """The item flown, as MISSION_CURRENT names it; -1: the last report named none
    (``progress``)."""
    mission_total: int = -1
    """Items of the mission held, as MISSION_CURRENT counts them (ArduPilot: less home);
    0: none; -1: not said (yet, or since an upload or a restart)."""
    mission_id: int = 0
    """MISSION_CURRENT's id of the mission held (PX4: a CRC32 of its items); 0: not said."""
    time_rate: float | None = None
    """Vehicle seconds per wall second (a simulator may run faster), from its timestamps;
    None until measured (``ClockRate``)."""
    boot_s: float | None = None
    """The vehicle's clock at its latest report (time_boot_ms / 1000)."""
    missing: tuple[str, ...] = ()
    """Messages the link asked for that do not arrive (refused or silent)."""


@dataclass(frozen=True)
class PositionInputs:
    """What ``assess_position`` looks at. For each criterion ``None`` means not reported
    yet; ``*_available`` False means the autopilot will not send it (refused)."""

    lat_e7: int | None = None
    lon_e7: int | None = None
    position_fresh: bool = True
    """GLOBAL_POSITION_INT still arrives (False: the last position is stale)."""
    gps_fix: int | None = None
    gps_available: bool = True
    estimator_flags: int | None = None
    estimator_available: bool = True
    estimator_name: str = "EKF_STATUS_REPORT"
    estimator_unaided_flags: int = 0
    """Flags that say the estimator has no GPS even with an absolute position (the profile's
    ``estimator_unaided_flags``)."""
    home_set: bool = False
    home_available: bool = True


def assess_position(p: PositionInputs) -> str:
    """'' when the autopilot has a position, else the first thing it waits for."""
    if p.lat_e7 is None or p.lon_e7 is None:
        return "telemetry: no GLOBAL_POSITION_INT yet"
    if not p.position_fresh:
        return "telemetry: GLOBAL_POSITION_INT stopped arriving"
    if p.gps_available:
        if p.gps_fix is None:
            return "GPS: no GPS_RAW_INT yet"
        if p.gps_fix < GPS_FIX_3D:
            return f"GPS: no 3D fix (fix type {p.gps_fix})"
    if p.estimator_available:
        flags = p.estimator_flags
        if flags is None:
            return f"position estimate: no {p.estimator_name} yet"
        if flags & EST_BAD:
            return f"position estimate: estimator uninitialised or GPS glitching (flags 0x{flags:04x})"
        if not flags & EST_POS_HORIZ_ABS or flags & p.estimator_unaided_flags:
            return f"position estimate: EKF has no GPS position yet (flags 0x{flags:04x})"
    if p.home_available and not p.home_set:
        return "home position: not set yet"
    if p.lat_e7 == 0 and p.lon_e7 == 0:
        return "position: latitude/longitude 0/0 (no estimate)"
    return ""


def battery_fraction(remaining_percent: int) -> float | None:
    """SYS_STATUS / BATTERY_STATUS battery_remaining (%) as a fraction; None for -1 (not
    known) and anything outside 0..100 (a corrupt or impossible reading): unknown, never full."""
    if not 0 <= remaining_percent <= 100:
        return None
    return remaining_percent / 100.0


def energy_used_j(energy_consumed_hj: int) -> float | None:
    """BATTERY_STATUS.energy_consumed (hJ) in joules; None where not reported (-1)."""
    return energy_consumed_hj * 100.0 if energy_consumed_hj >= 0 else None


def derived_airborne(armed: bool, rel_alt_m: float, climb_mps: float, was_airborne: bool) -> bool:
    """The landed state where the autopilot reports none: disarmed is on the ground; armed,
    airborne once above ``AIRBORNE_ALT_M`` or climbing, and until back below
    ``LANDED_ALT_M`` and still (a hysteresis, so hovering low does not flicker)."""
    if not armed:
        return False
    if was_airborne:
        return rel_alt_m > LANDED_ALT_M or abs(climb_mps) > LANDED_CLIMB_MPS
    return rel_alt_m > AIRBORNE_ALT_M or climb_mps > AIRBORNE_CLIMB_MPS
