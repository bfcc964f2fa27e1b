"""Telemetry messages built from the simulated aircraft's state (pure functions); where
the autopilots differ, a field of ``behaviour.Behaviour`` or a table keyed by the profile."""

from __future__ import annotations

import math
from typing import Any, Callable

from pymavlink.dialects.v20 import common as mavlink

from protocol.autopilot import ARDUPILOT, PX4
from protocol.geodesy import local_to_global

from .estimator import EKF_FLAGS_GPS, EKF_FLAGS_NO_GPS, Stage
from .flight import Flight, MissionState
from .mission_id import MissionCurrent, px4_mission_id
from .modes import Mode, custom_mode

# A 4S lithium pack: 16.8 V full, 14.0 V at the end of its useful charge.
CELLS = 4
CELL_FULL_V, CELL_EMPTY_V = 4.2, 3.5
CAPACITY_MAH = 5000

_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS | mavlink.MAV_SYS_STATUS_SENSOR_BATTERY
)
# ArduCopter SITL's SYS_STATUS on the ground (V4.7.0-dev): present 0x5371fc2f, enabled
# 0x5361fc2f, health 0x4771fc2f. The geofence (0x100000) is present and healthy but not
# enabled (FENCE_ENABLE 0): a ground station that finds it present and unhealthy reports a
# breach (MAVProxy's "fence breach"). The pre-arm bit (0x10000000) is healthy only when the
# checks pass, the GPS bit only with a fix.
AP_PRESENT, AP_ENABLED, AP_HEALTH = 0x5371FC2F, 0x5361FC2F, 0x4771FC2F
_PREARM = mavlink.MAV_SYS_STATUS_PREARM_CHECK
_GPS = mavlink.MAV_SYS_STATUS_SENSOR_GPS
_AUTO_BITS = (
    mavlink.MAV_MODE_FLAG_AUTO_ENABLED | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
)
_BASE_BITS = {
    Mode.MANUAL: mavlink.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED,
    Mode.GUIDED: mavlink.MAV_MODE_FLAG_GUIDED_ENABLED | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED,
}
SENSORS: dict[str, tuple[int, int, int]] = {
    ARDUPILOT.name: (AP_PRESENT, AP_ENABLED, AP_HEALTH), PX4.name: (_SENSORS, _SENSORS, _SENSORS),
}
"""SYS_STATUS's present, enabled and healthy sensors, by autopilot (on the ground, with a fix)."""
FIRMWARE_TYPE_OFFICIAL = 255


def time_boot_ms(flight: Flight) -> int:
    """Milliseconds of simulated time since the vehicle (re)started (its own clock)."""
    return int(flight.since_boot_s * 1000.0) % (1 << 32)


def heartbeat(flight: Flight) -> Any:
    base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | _BASE_BITS.get(flight.mode, _AUTO_BITS)
    if flight.armed:
        base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    if flight.behaviour.standby_while_landed:
        state = mavlink.MAV_STATE_STANDBY if flight.landed else mavlink.MAV_STATE_ACTIVE
    else:
        state = mavlink.MAV_STATE_ACTIVE if flight.armed else mavlink.MAV_STATE_STANDBY
    if flight.failsafe and not flight.landed:
        state = mavlink.MAV_STATE_CRITICAL
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_QUADROTOR, flight.behaviour.autopilot.mav_autopilot, base,
        custom_mode(flight.flavour, flight.mode), state, 3,
    )


def autopilot_version(flight: Flight, system_id: int) -> Any:
    major, minor, patch = flight.behaviour.firmware_version
    capabilities = (
        mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
        | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
        | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
        | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    )
    version = (major << 24) | (minor << 16) | (patch << 8) | FIRMWARE_TYPE_OFFICIAL
    return mavlink.MAVLink_autopilot_version_message(
        capabilities, version, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x5EED0000 + system_id,
        [0] * 18,
    )


def _global(flight: Flight) -> tuple[int, int, float]:
    lat, lon, alt = local_to_global(flight.origin, *flight.pos)
    return int(round(lat * 1e7)), int(round(lon * 1e7)), alt


def heading_cdeg(flight: Flight) -> int:
    vx, vy, _ = flight.vel
    if math.hypot(vx, vy) < 1e-3:
        return 65535  # unknown
    return int(round(math.degrees(math.atan2(vx, vy)) % 360.0 * 100)) % 36000


def global_position_int(flight: Flight) -> Any | None:
    """ArduPilot: lat/lon/alt 0 until the GPS has a fix, then the GPS position (SITL reports
    it before the EKF has an origin); PX4 publishes no global position until it is valid."""
    if not flight.behaviour.gps_position_before_estimate and not flight.position_ok:
        return None
    if flight.stage < Stage.GPS:
        return mavlink.MAVLink_global_position_int_message(time_boot_ms(flight), 0, 0, 0, 0, 0, 0, 0, 65535)
    lat, lon, alt = _global(flight)
    vx, vy, vz = flight.vel
    # NED velocities in cm/s: north = local y, east = local x, down = -z.
    return mavlink.MAVLink_global_position_int_message(
        time_boot_ms(flight), lat, lon, int(round(alt * 1000)), int(round(flight.pos[2] * 1000)),
        int(round(vy * 100)), int(round(vx * 100)), int(round(-vz * 100)), heading_cdeg(flight),
    )


def local_position_ned(flight: Flight) -> Any | None:
    """Relative to the estimator's origin: none before it has one."""
    if flight.stage < flight.behaviour.local_position_from:
        return None
    x, y, z = flight.pos
    vx, vy, vz = flight.vel
    return mavlink.MAVLink_local_position_ned_message(time_boot_ms(flight), y, x, -z, vy, vx, -vz)


def attitude(flight: Flight) -> Any:
    hdg = heading_cdeg(flight)
    yaw = 0.0 if hdg == 65535 else math.radians(hdg / 100.0)
    if yaw > math.pi:
        yaw -= 2 * math.pi
    return mavlink.MAVLink_attitude_message(time_boot_ms(flight), 0.0, 0.0, yaw, 0.0, 0.0, 0.0)


def gps_raw_int(flight: Flight) -> Any:
    """No fix (lat/lon 0, no satellites) until the GPS stage, then a 3-D fix."""
    if flight.stage < Stage.GPS:
        return mavlink.MAVLink_gps_raw_int_message(
            int(flight.since_boot_s * 1e6), mavlink.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, 65535, 65535, 0, 65535, 0)
    lat, lon, alt = _global(flight)
    speed = math.hypot(flight.vel[0], flight.vel[1])
    return mavlink.MAVLink_gps_raw_int_message(
        int(flight.since_boot_s * 1e6), mavlink.GPS_FIX_TYPE_3D_FIX, lat, lon, int(round(alt * 1000)), 80, 120,
        int(round(speed * 100)), 65535, 14,
    )


def vfr_hud(flight: Flight, throttle_pct: int) -> Any:
    _, _, alt = _global(flight)
    speed = math.hypot(flight.vel[0], flight.vel[1])
    hdg = heading_cdeg(flight)
    return mavlink.MAVLink_vfr_hud_message(speed, speed, 0 if hdg == 65535 else hdg // 100, throttle_pct,
                                           alt, flight.vel[2])


def system_time(flight: Flight, unix_time_s: float) -> Any:
    return mavlink.MAVLink_system_time_message(int(unix_time_s * 1e6), time_boot_ms(flight))


def ekf_status_report(flight: Flight) -> Any:
    """ArduPilot's EKF flags, as SITL reports them before and after ``is using GPS``."""
    from pymavlink.dialects.v20 import ardupilotmega  # imported on first use: a large module

    flags = EKF_FLAGS_GPS if flight.position_ok else EKF_FLAGS_NO_GPS
    return ardupilotmega.MAVLink_ekf_status_report_message(flags, 0.02, 0.03, 0.01, 0.02, 0.0, 0.0)


def gps_global_origin(flight: Flight) -> Any | None:
    if not flight.home_set:
        return None
    o = flight.origin
    return mavlink.MAVLink_gps_global_origin_message(
        int(round(o.lat_deg * 1e7)), int(round(o.lon_deg * 1e7)), int(round(o.alt_m * 1000)),
        int(flight.since_boot_s * 1e6))


def _voltage_v(flight: Flight) -> float:
    return CELLS * (CELL_EMPTY_V + (CELL_FULL_V - CELL_EMPTY_V) * flight.battery_fraction)


def _current_a(flight: Flight, power_w: float) -> float:
    return power_w / _voltage_v(flight)


def sys_status(flight: Flight, power_w: float) -> Any:
    volts = _voltage_v(flight)
    present, enabled, health = SENSORS[flight.behaviour.autopilot.name]
    if flight.behaviour.prearm_in_sys_status:
        health = (health | _PREARM) if flight.position_ok and not flight.failsafe else (health & ~_PREARM)
    if flight.stage < Stage.GPS:
        health &= ~_GPS
    return mavlink.MAVLink_sys_status_message(
        present, enabled, health, 100, int(volts * 1000), int(_current_a(flight, power_w) * 100),
        int(round(flight.battery_fraction * 100)), 0, 0, 0, 0, 0, 0,
    )


def battery_status(flight: Flight, power_w: float) -> Any:
    cell_mv = int(_voltage_v(flight) / CELLS * 1000)
    used_j = flight.scenario.battery_j - flight.energy_j
    consumed_mah = int(CAPACITY_MAH * (1.0 - flight.battery_fraction))
    return mavlink.MAVLink_battery_status_message(
        0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767,
        [cell_mv] * CELLS + [65535] * 6, int(_current_a(flight, power_w) * 100), consumed_mah,
        int(used_j / 100.0), int(round(flight.battery_fraction * 100)),
    )


def extended_sys_state(flight: Flight) -> Any:
    """PX4 SITL says TAKEOFF for the whole climb to a first item from the ground and LANDING
    for a mission's LAND item (measured: 1, 3, 2, 4, 1)."""
    landing_item = flight.loaded is not None and flight.loaded.command == mavlink.MAV_CMD_NAV_LAND
    if flight.landed:
        landed = mavlink.MAV_LANDED_STATE_ON_GROUND
    elif flight.vel[2] > 0.1 and (flight.pos[2] < 5.0 or flight.climb_out is not None):
        landed = mavlink.MAV_LANDED_STATE_TAKEOFF
    elif flight.vel[2] < -0.1 and (flight.mode in (Mode.LAND, Mode.RTL) or landing_item):
        landed = mavlink.MAV_LANDED_STATE_LANDING
    else:
        landed = mavlink.MAV_LANDED_STATE_IN_AIR
    return mavlink.MAVLink_extended_sys_state_message(mavlink.MAV_VTOL_STATE_MC, landed)


def mission_state(flight: Flight) -> int:
    if not flight.mission_present:
        return mavlink.MISSION_STATE_NO_MISSION
    if flight.state is MissionState.COMPLETE:
        return mavlink.MISSION_STATE_COMPLETE
    if flight.state is MissionState.RUNNING:
        if flight.paused:
            return mavlink.MISSION_STATE_PAUSED
        return mavlink.MISSION_STATE_ACTIVE if flight.mode is Mode.AUTO else mavlink.MISSION_STATE_PAUSED
    if not flight.behaviour.stopped_mission_paused or not flight.started:
        return mavlink.MISSION_STATE_NOT_STARTED
    return mavlink.MISSION_STATE_PAUSED


NO_ITEM = 0xFFFF
"""MISSION_CURRENT.seq naming no item (PX4, ``events.CurrentUnnamed``)."""


def mission_current(flight: Flight, seq: int | None = None, state: int | None = None) -> Any:
    """MISSION_CURRENT now, or as it was when an event of this step happened (``seq`` and
    ``state``): at a high speed-up one step can pass several items, and each report must
    say what was current then, or a ground station sees progress jump back and forth.

    ArduPilot (GCS_MAVLINK::send_mission_current): ``total`` leaves home out (items - 1),
    ``seq`` is the navigation index (0 when none is loaded, e.g. after disarming);
    ``mission_mode`` 1 in AUTO. PX4: ``total`` is the item count, UINT16_MAX with none."""
    seq = flight.current if seq is None else seq
    state = mission_state(flight) if state is None else state
    return MISSION_CURRENT[flight.behaviour.autopilot.name](flight, seq, state)


def _ardupilot_mission_current(flight: Flight, seq: int, state: int) -> Any:
    mode = 1 if flight.mode is Mode.AUTO else 0
    total = max(len(flight.mission) - 1, 0)
    return mavlink.MAVLink_mission_current_message(seq, total, state, mode)


def _px4_mission_current(flight: Flight, seq: int, state: int) -> Any:
    mode = 1 if flight.mode is Mode.AUTO else 2
    total = len(flight.mission) if flight.mission else 0xFFFF  # UINT16_MAX: no mission (MAVLink)
    if seq != NO_ITEM:
        seq = min(seq, max(len(flight.mission) - 1, 0))
    # PX4 names its mission (MavlinkMissionManager::send_mission_current): mission_id
    return MissionCurrent(seq, total, state, mode, px4_mission_id(flight.mission))


MISSION_CURRENT: dict[str, Callable[[Flight, int, int], Any]] = {
    ARDUPILOT.name: _ardupilot_mission_current, PX4.name: _px4_mission_current,
}
"""MISSION_CURRENT of (flight, seq, state), by autopilot: their fields differ (docstring of
``mission_current``)."""


def home_position(flight: Flight) -> Any | None:
    """None until home is set (neither autopilot sends one before)."""
    if not flight.home_set:
        return None
    x, y, z = flight.home
    lat, lon, alt = local_to_global(flight.origin, x, y, z)
    return mavlink.MAVLink_home_position_message(
        int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)), y, x, -z,
        [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, int(flight.since_boot_s * 1e6),
    )


def statustext(severity: int, text: str) -> Any:
    return mavlink.MAVLink_statustext_message(severity, text.encode("ascii", "replace")[:50])
