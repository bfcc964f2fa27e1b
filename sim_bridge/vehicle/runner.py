"""The vehicle's loop: read MAVLink, step the simulated flight, stream telemetry.

One thread, one ``selectors`` loop: a tick every ``tick_s`` of wall time advances simulated
time by ``tick_s * speedup``. Protocol timeouts (mission re-requests) and telemetry rates
run on wall time, since they concern the link, not the flight.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from pathlib import Path
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable

from pymavlink.dialects.v20 import common as mavlink

from planner_service.model import Scenario
from protocol.geodesy import GeoOrigin, local_to_global
from protocol.errors import SigningError
from protocol.mission import GLOBAL_FRAMES, NAV_POSITION_COMMANDS, MissionItem, f32, item_local, mission_digest
from protocol.signing import Signer, TimestampStore, default_timestamp_path, load_key

from . import telemetry as tm
from .commands import Commands
from .errors import VehicleError
from .flight import Flight, FlightEvent
from .link import Link, Received
from .mission_store import MissionStore
from .state_file import SAVE_INTERVAL_S, load_state, save_state
from .modes import mode_from_custom, mode_name

log = logging.getLogger(__name__)

M = mavlink
DEFAULT_INTERVALS_S: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 0.25,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 0.25,
    M.MAVLINK_MSG_ID_ATTITUDE: 0.25,
    M.MAVLINK_MSG_ID_SYS_STATUS: 0.5,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 0.5,
    M.MAVLINK_MSG_ID_MISSION_CURRENT: 0.5,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 5.0,
}
MIN_INTERVAL_S = 0.02
MAX_STEP_TICKS = 5
SIGNING_TICK_S = 1.0
"""How often the signing timestamp is brought up to the clock (and its reservation stored)."""


@dataclass(frozen=True)
class VehicleConfig:
    """Everything the vehicle stub is started with."""

    url: str = "udpin:127.0.0.1:14550"
    flavour: str = "ardupilot"
    scenario: Scenario = field(default_factory=Scenario)
    origin: GeoOrigin = field(default_factory=GeoOrigin)
    speedup: float = 1.0
    system_id: int = 1
    component_id: int = 1
    tick_s: float = 0.02
    item_timeout_s: float = 1.0
    max_retries: int = 5
    fence_margin_m: float = 100.0
    """Geofence: the scenario's area grown by this margin; waypoints outside are refused."""
    max_altitude_m: float = 150.0
    max_mission_items: int = 512
    """Mission capacity: a MISSION_COUNT above it is answered MAV_MISSION_NO_SPACE."""
    signing_key_file: str | None = None
    """Enforce MAVLink 2 signing with the key in this file (``protocol.signing.load_key``)."""
    signing_timestamp_file: str | None = None
    """Where the signing timestamp is kept; default beside the key (KEY.vehicle-timestamp)."""
    state_file: str | None = None
    """Save the flight here a few times a second and resume from it at start (a restart
    in the air comes back holding position, its mission lost)."""
    recharge_s: float | None = None
    """Battery swap: simulated seconds on the ground, disarmed, until the battery is full
    again; None: never (one sortie's battery)."""

    def __post_init__(self) -> None:
        if self.flavour not in ("ardupilot", "px4"):
            raise VehicleError("flavour", f"{self.flavour!r} is not ardupilot or px4")
        if not self.speedup > 0:
            raise VehicleError("speedup", f"must be positive, got {self.speedup}")
        if not 1 <= self.system_id <= 255:
            raise VehicleError("system_id", "must lie in 1..255")
        if not self.tick_s > 0 or not self.item_timeout_s > 0 or self.max_retries < 0:
            raise VehicleError("timing", "tick_s and item_timeout_s must be positive, max_retries >= 0")
        if not 1 <= self.max_mission_items <= 65535:
            raise VehicleError("max_mission_items", f"must lie in 1..65535, got {self.max_mission_items}")
        if self.recharge_s is not None and not (math.isfinite(self.recharge_s) and self.recharge_s >= 0):
            raise VehicleError("recharge_s", f"must be a finite number of seconds >= 0, got {self.recharge_s}")


class Vehicle:
    """The SITL-stub: a ``Flight`` behind a MAVLink ``Link``."""

    def __init__(self, config: VehicleConfig, clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config
        self.clock = clock
        self.flight = Flight(config.scenario, config.origin, config.flavour, recharge_s=config.recharge_s)
        self.signer = self._signer(config)
        try:
            self.link = Link(config.url, config.system_id, config.component_id, clock, self.signer)
        except VehicleError:
            if self.signer is not None:
                self.signer.close()
            raise
        self.store = MissionStore(
            self._send_to, clock, check=self._check_mission, on_commit=self._on_commit,
            on_set_current=self._on_set_current, item_timeout_s=config.item_timeout_s,
            max_retries=config.max_retries, capacity=config.max_mission_items,
        )
        self.commands = Commands(self.flight, self._message_for, self._set_interval)
        self.intervals = dict(DEFAULT_INTERVALS_S)
        self._due: dict[int, float] = {}
        self._last_tick = clock()
        self._power_w = 0.0
        self._state_path = Path(config.state_file) if config.state_file else None
        self._saved_at = -float("inf")
        if self._state_path is not None:
            snap = load_state(self._state_path)
            if snap is not None:
                self.flight.resume(snap)
                f = self.flight
                log.info("restarted from %s: %s at (%.0f, %.0f, %.0f) m, battery %.1f%%, mode %s, mission lost",
                         self._state_path, "airborne" if not f.landed else "on the ground", *f.pos,
                         100 * f.battery_fraction, mode_name(config.flavour, f.mode))
        self._last_mode = self.flight.mode
        self._last_armed = self.flight.armed
        self._signing_due = clock() + SIGNING_TICK_S

    @staticmethod
    def _signer(config: VehicleConfig) -> Signer | None:
        """The signing state, or None without a key (``SigningError`` names a bad file)."""
        if not config.signing_key_file:
            return None
        key = load_key(config.signing_key_file)
        stamps = config.signing_timestamp_file or default_timestamp_path(config.signing_key_file, "vehicle")
        return Signer(key, TimestampStore(stamps))

    # --- loop ------------------------------------------------------------------------------
    def run(self, stop: threading.Event) -> None:
        """Serve until ``stop`` is set."""
        log.info("vehicle (%s) listening on %s, speed-up %g%s", self.config.flavour, self.config.url,
                 self.config.speedup, ", signing enforced" if self.signer is not None else "")
        try:
            while not stop.is_set():
                wait = self._last_tick + self.config.tick_s - self.clock()
                for received in self.link.wait(wait):
                    self._safely(self.handle, received)
                if self.clock() >= self._last_tick + self.config.tick_s:
                    self._safely(self.tick)
        finally:
            self.link.close()
            self._safely(self._save_state, True)
            if self.signer is not None:
                log.info("signing: %s", self.signer.stats.summary())
                try:
                    self.signer.close()
                except SigningError as err:
                    log.error("signing timestamp not stored: %s", err)

    def _safely(self, fn: Callable[..., None], *args: Any) -> None:
        try:
            fn(*args)
        except Exception:  # one bad message or bug must not take the vehicle down mid-flight
            log.exception("error in %s", getattr(fn, "__name__", fn))

    def tick(self) -> None:
        now = self.clock()
        dt_wall = now - self._last_tick
        self._last_tick = now
        if dt_wall > MAX_STEP_TICKS * self.config.tick_s:
            # The process was starved (2 cores shared with the ground station): let
            # simulated time lag rather than jump a whole mission in one step.
            log.debug("late tick: %.3f s of wall time; simulating %.3f", dt_wall, MAX_STEP_TICKS * self.config.tick_s)
            dt_wall = MAX_STEP_TICKS * self.config.tick_s
        before = self.flight.energy_j
        was_landed = self.flight.landed
        dt_sim = dt_wall * self.config.speedup
        events = self.flight.step(dt_sim)
        if dt_sim > 0:
            self._power_w = (before - self.flight.energy_j) / dt_sim
        if was_landed and not self.flight.landed:
            # Report the takeoff at once, as the landing is: at a high speed-up a short
            # flight can begin and end between two periodic reports.
            self._send_to(tm.extended_sys_state(self.flight), None)
        for event in events:
            self._report(event)
        if self.flight.mode is not self._last_mode or self.flight.armed != self._last_armed:
            self._last_mode, self._last_armed = self.flight.mode, self.flight.armed
            self._send_to(tm.heartbeat(self.flight), None)
        self.store.tick()
        if self.signer is not None and now >= self._signing_due:
            self._signing_due = now + SIGNING_TICK_S
            try:
                self.signer.tick()
            except SigningError as err:  # a full disk must not stop the telemetry below
                log.error("signing timestamp not stored (a restart could reuse timestamps): %s", err)
        self._stream(now)
        self._save_state()

    def _save_state(self, force: bool = False) -> None:
        """The flight to the state file, every ``SAVE_INTERVAL_S`` of wall time."""
        now = self.clock()
        if self._state_path is None or (not force and now < self._saved_at + SAVE_INTERVAL_S):
            return
        self._saved_at = now
        save_state(self._state_path, self.flight.snapshot())

    def _stream(self, now: float) -> None:
        for msg_id, interval in self.intervals.items():
            if interval <= 0 or now < self._due.get(msg_id, 0.0):
                continue
            self._due[msg_id] = now + interval
            message = self._message_for(msg_id)
            if message is not None:
                self._send_to(message, None)

    def _report(self, event: FlightEvent) -> None:
        if event.kind == "reached":
            log.info("mission item %d reached", event.seq)
            self._send_to(mavlink.MAVLink_mission_item_reached_message(event.seq), None)
        elif event.kind == "current":
            self._send_to(tm.mission_current(self.flight, event.seq, M.MISSION_STATE_ACTIVE), None)
        elif event.kind == "mission_done":
            self._send_to(tm.mission_current(self.flight, event.seq, M.MISSION_STATE_COMPLETE), None)
            self._send_to(tm.statustext(M.MAV_SEVERITY_INFO, "Mission complete"), None)
        elif event.kind == "battery_swapped":
            log.info("%s at t=%.1f s (sim): battery %.1f%%", event.text, self.flight.time_s,
                     100 * self.flight.battery_fraction)
            self._send_to(tm.statustext(M.MAV_SEVERITY_INFO, "Battery swapped: full"), None)
            self._send_to(tm.battery_status(self.flight, 0.0), None)
        elif event.kind == "battery_low":
            log.warning("%s", event.text)
            self._send_to(tm.statustext(M.MAV_SEVERITY_CRITICAL, event.text), None)
        elif event.kind in ("landed", "disarmed"):
            log.info("%s at t=%.1f s (sim), battery %.1f%%", event.kind, self.flight.time_s,
                     100 * self.flight.battery_fraction)
            self._send_to(tm.extended_sys_state(self.flight), None)

    # --- input -----------------------------------------------------------------------------
    def handle(self, received: Received) -> None:
        msg, peer = received.msg, received.peer
        if received.new_peer:
            # Greet a new peer at once: MAVSDK then sees the vehicle in milliseconds.
            log.info("new peer %s (system %d)", peer, msg.get_srcSystem())
            self._send_to(tm.heartbeat(self.flight), peer)
        target = getattr(msg, "target_system", None)
        if target not in (None, 0, self.config.system_id):
            return
        if self.store.handle(msg, peer):
            return
        kind = msg.get_type()
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._command(msg, peer)
        elif kind == "SET_MODE":
            mode = mode_from_custom(self.config.flavour, msg.custom_mode)
            if mode is not None:
                self.flight.set_mode(mode)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            self._send_to(mavlink.MAVLink_timesync_message(time.monotonic_ns(), msg.ts1), peer)
        elif kind == "PARAM_REQUEST_LIST":
            # No parameters are simulated; say so rather than leave the requester waiting.
            self._send_to(mavlink.MAVLink_param_value_message(b"SYSID_THISMAV", float(self.config.system_id),
                                                              M.MAV_PARAM_TYPE_INT32, 1, 0), peer)

    def _command(self, msg: Any, peer: Hashable) -> None:
        outcome = self.commands.execute(msg)
        if outcome.result != M.MAV_RESULT_ACCEPTED:
            log.info("command %d refused (%d): %s", msg.command, outcome.result, outcome.reason)
        else:
            log.info("command %d accepted; mode %s, armed %s", msg.command,
                     mode_name(self.config.flavour, self.flight.mode), self.flight.armed)
        self._send_to(mavlink.MAVLink_command_ack_message(
            msg.command, outcome.result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), peer)
        for follow_up in outcome.follow_up:
            self._send_to(follow_up, peer)
        if outcome.result == M.MAV_RESULT_ACCEPTED:
            self._send_to(tm.heartbeat(self.flight), None)

    # --- hooks ------------------------------------------------------------------------------
    def _send_to(self, message: Any, peer: Hashable | None) -> None:
        self.link.send(message, peer)

    def _message_for(self, msg_id: int) -> Any | None:
        f = self.flight
        builders: dict[int, Callable[[], Any]] = {
            M.MAVLINK_MSG_ID_HEARTBEAT: lambda: tm.heartbeat(f),
            M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: lambda: tm.global_position_int(f),
            M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: lambda: tm.local_position_ned(f),
            M.MAVLINK_MSG_ID_ATTITUDE: lambda: tm.attitude(f),
            M.MAVLINK_MSG_ID_SYS_STATUS: lambda: tm.sys_status(f, self._power_w),
            M.MAVLINK_MSG_ID_BATTERY_STATUS: lambda: tm.battery_status(f, self._power_w),
            M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: lambda: tm.extended_sys_state(f),
            M.MAVLINK_MSG_ID_MISSION_CURRENT: lambda: tm.mission_current(f),
            M.MAVLINK_MSG_ID_GPS_RAW_INT: lambda: tm.gps_raw_int(f),
            M.MAVLINK_MSG_ID_HOME_POSITION: lambda: tm.home_position(f),
            M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: lambda: tm.autopilot_version(f, self.config.system_id),
        }
        builder = builders.get(msg_id)
        return builder() if builder else None

    def _set_interval(self, msg_id: int, interval_us: float) -> bool:
        if msg_id not in DEFAULT_INTERVALS_S:
            return False
        if interval_us < 0:
            self.intervals[msg_id] = 0.0
        elif interval_us == 0:
            self.intervals[msg_id] = DEFAULT_INTERVALS_S[msg_id]
        else:
            self.intervals[msg_id] = max(MIN_INTERVAL_S, interval_us / 1e6)
        self._due.pop(msg_id, None)
        return True

    def _on_commit(self, items: list[MissionItem]) -> list[MissionItem]:
        log.info("mission of %d items accepted (digest %s)", len(items), mission_digest(items, self.config.flavour))
        if self.config.flavour == "ardupilot" and items:
            # ArduPilot keeps home in item 0 whatever was uploaded there (a download
            # returns home): the pitfall the flavour exists to reproduce.
            items[0] = self._home_item(items[0])
        self.flight.set_mission(items)
        self._send_to(tm.mission_current(self.flight), None)
        return items

    def _home_item(self, uploaded: MissionItem) -> MissionItem:
        lat, lon, alt = local_to_global(self.config.origin, *self.flight.home)
        return MissionItem(
            seq=0, frame=M.MAV_FRAME_GLOBAL, command=M.MAV_CMD_NAV_WAYPOINT, current=uploaded.current,
            x=int(round(lat * 1e7)), y=int(round(lon * 1e7)), z=f32(alt),
        )

    def _on_set_current(self, seq: int) -> bool:
        ok = self.flight.set_current(seq)
        if ok:
            self._send_to(tm.mission_current(self.flight), None)
        return ok

    def _check_mission(self, items: list[MissionItem]) -> tuple[int, str] | None:
        """The geofence: the scenario's area grown by ``fence_margin_m``, altitude limit."""
        side = self.config.scenario.area_side_m
        margin = self.config.fence_margin_m
        first = 1 if self.config.flavour == "ardupilot" else 0
        for item in items[first:]:
            positional = item.command in NAV_POSITION_COMMANDS or item.command == M.MAV_CMD_NAV_LOITER_TIME
            if not positional or item.frame not in GLOBAL_FRAMES:
                continue
            if item.command == M.MAV_CMD_NAV_LAND and item.x == 0 and item.y == 0:
                continue  # land where it is
            x, y, z = item_local(item, self.config.origin)
            if not -margin <= x <= side + margin:
                return M.MAV_MISSION_INVALID_PARAM5_X, f"item {item.seq}: x {x:.0f} m outside the geofence"
            if not -margin <= y <= side + margin:
                return M.MAV_MISSION_INVALID_PARAM6_Y, f"item {item.seq}: y {y:.0f} m outside the geofence"
            if not 0.0 <= z <= self.config.max_altitude_m:
                return M.MAV_MISSION_INVALID_PARAM7, f"item {item.seq}: altitude {z:.0f} m out of limits"
        return None
