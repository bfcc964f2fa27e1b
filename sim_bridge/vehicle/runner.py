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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Hashable, assert_never

from pymavlink.dialects.v20 import common as mavlink

from planner_service.model import Scenario
from protocol.errors import SigningError
from protocol.geodesy import GeoOrigin, local_to_global
from protocol.mission import GLOBAL_FRAMES, NAV_POSITION_COMMANDS, MissionItem, f32, item_local, mission_digest
from protocol.signing import Signer, TimestampStore, default_timestamp_path, load_key

from . import telemetry as tm
from .commands import Commands
from .errors import VehicleError
from .behaviour import BEHAVIOURS, behaviour_for
from .estimator import DEFAULT_GPS_DELAY_S
from .events import (
    Armed, BatteryLow, BatterySwapped, CommandStarted, CurrentChanged, CurrentUnnamed, Disarmed, FlightEvent, GpsFix, HomeSet,
    TouchedDown, MissionDone, MissionRestarted, MissionRestartFailed, ModeChangedItself, OriginSet, ItemComplete, UsingGps,
)
from .flight import Flight, MissionState, Refusal
from .link import Link, Received
from .mission_store import MissionStore, StoreHooks
from .modes import mode_from_custom, mode_name, requested_name
from .params import ParamTable, vehicle_params
from .state_file import SAVE_INTERVAL_S, load_state, save_state
from .track import Track
from .stored_items import Problem, ardupilot_stored
from .streams import DEFAULT_MAX_STREAM_HZ, PeerStreams

log = logging.getLogger(__name__)

M = mavlink
MAX_STEP_TICKS = 5
SIGNING_TICK_S = 1.0
"""How often the signing timestamp is brought up to the clock (and its reservation stored)."""
# TIMESYNC, pre-arm reports and MISSION_ITEM_REACHED repeats are timed by the behaviour
# (behaviour.py) in wall-clock time, as the telemetry rates, so that a high speed-up does
# not flood the link and the logs.


MIN_ITEM_TIMEOUT_S = 0.1
"""The shortest wall-clock wait for a mission item (a link's round trip is not sped up)."""

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
    """Wait for the next mission item before asking again, in the vehicle's time (ArduPilot's
    1 s, its scheduler's clock): ``item_timeout_s / speedup`` of wall time, at least
    ``MIN_ITEM_TIMEOUT_S``, as SITL behaves at a speed-up."""
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
    track_file: str | None = None
    """Append the flight, one CSV line a tick, to this file (``track.py``)."""
    """Save the flight here a few times a second and resume from it at start (a restart
    in the air comes back holding position, its mission lost)."""
    recharge_s: float | None = None
    """Battery swap: simulated seconds on the ground, disarmed, until the battery is full
    again; None: never (one sortie's battery)."""
    gps_delay_s: float = DEFAULT_GPS_DELAY_S
    """Simulated seconds after boot until the estimator navigates with GPS (no position,
    no arming in a position mode before; estimator.py)."""
    max_stream_hz: float = DEFAULT_MAX_STREAM_HZ
    """The most a streamed message is sent per wall second (``streams.PeerStreams``)."""
    disarm_delay_s: float = 10.0
    """Armed on the ground this many simulated seconds without taking off, the motors stop
    (ArduPilot's DISARM_DELAY, PX4's COM_DISARM_PRFLT); 0: never."""

    def __post_init__(self) -> None:
        if self.flavour not in BEHAVIOURS:
            raise VehicleError("flavour", f"{self.flavour!r} is not one of {tuple(BEHAVIOURS)}")
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
        if not (math.isfinite(self.max_stream_hz) and self.max_stream_hz > 0):
            raise VehicleError("max_stream_hz", f"must be a positive number of Hz, got {self.max_stream_hz}")
        for name in ("gps_delay_s", "disarm_delay_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise VehicleError(name, f"must be a finite number of seconds >= 0, got {value}")


class Vehicle:
    """The SITL-stub: a ``Flight`` behind a MAVLink ``Link``."""

    def __init__(self, config: VehicleConfig, clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config
        self.clock = clock
        self.behaviour = b = behaviour_for(config.flavour)
        autopilot = b.autopilot
        self.flight = Flight(config.scenario, config.origin, config.flavour, recharge_s=config.recharge_s,
                             gps_delay_s=config.gps_delay_s, disarm_delay_s=config.disarm_delay_s)
        self.signer = self._signer(config)
        try:
            self.link = Link(config.url, config.system_id, config.component_id, clock, self.signer)
        except VehicleError:
            if self.signer is not None:
                self.signer.close()
            raise
        hooks = StoreHooks(
            problem=self._item_problem, stored=ardupilot_stored if autopilot.compacts_items else (lambda item: item),
            on_change=self.flight.mission_changed, on_commit=self.flight.replace_mission,
            on_accepted=self._on_accepted, on_set_current=self._on_set_current, current_flag=self._current_flag,
            home_item=self._home_item if autopilot.home_slots else (lambda: None), can_clear=self._can_clear,
            text=lambda text, peer: self._send_to(tm.statustext(M.MAV_SEVERITY_INFO, text), peer),
        )
        self.store = MissionStore(
            self._send_to, clock, flavour=config.flavour, hooks=hooks,
            item_timeout_s=max(config.item_timeout_s / config.speedup, MIN_ITEM_TIMEOUT_S),
            max_retries=config.max_retries, capacity=config.max_mission_items,
        )
        self.streams: dict[Hashable, PeerStreams] = {}
        self.commands = Commands(self.flight, self._message_for, self._set_interval, self._knows)
        self.params: ParamTable = vehicle_params(
            config.flavour, config.system_id, lambda: self.flight.speed_mps, self.flight.climb_mps,
            self.flight.rtl_min_alt_m, config.disarm_delay_s, lambda: len(self.store.items))
        self._last_tick = clock()
        self._power_w = 0.0
        self._state_path = Path(config.state_file) if config.state_file else None
        self.track = Track(Path(config.track_file)) if config.track_file else None
        self._saved_at = -float("inf")
        if self._state_path is not None:
            snap = load_state(self._state_path)
            if snap is not None:
                self.flight.resume(snap)
                if self.flight.home_set:
                    self.store.home_known()
                f = self.flight
                log.info("restarted from %s: %s at (%.0f, %.0f, %.0f) m, battery %.1f%%, mode %s, mission lost",
                         self._state_path, "airborne" if not f.landed else "on the ground", *f.pos,
                         100 * f.battery_fraction, mode_name(config.flavour, f.mode))
        self._last_mode = self.flight.mode
        self._last_armed = self.flight.armed
        self._signing_due = clock() + SIGNING_TICK_S
        self._timesync_due = clock() + (b.timesync_interval_s or 0.0)
        self._reached_repeat: tuple[int, int, float] | None = None
        """PX4: (seq, repeats left, next wall time) of MISSION_ITEM_REACHED."""
        self._prearm_due = clock() + (b.prearm_report_s or 0.0)

    @staticmethod
    def _signer(config: VehicleConfig) -> Signer | None:
        """The signing state, or None without a key (``SigningError`` names a bad file)."""
        if not config.signing_key_file:
            return None
        key = load_key(config.signing_key_file)
        stamps = config.signing_timestamp_file or default_timestamp_path(config.signing_key_file, "vehicle")
        return Signer(key, TimestampStore(stamps))

    # --- loop ------------------------------------------------------------------------------
    def run(self, stop: threading.Event, on_listening: Callable[[], None] | None = None) -> None:
        """Serve until ``stop`` is set; ``on_listening`` is called once the "listening" line
        is logged (several vehicles in one process announce themselves all up after it)."""
        log.info("vehicle (%s) listening on %s, speed-up %g, position after %g s%s", self.config.flavour,
                 self.config.url, self.config.speedup, self.config.gps_delay_s,
                 ", signing enforced" if self.signer is not None else "")
        if on_listening is not None:
            on_listening()
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
            if self.track is not None:
                self._safely(self.track.close)
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
            # Report the takeoff at once, as the landing is, to the peers that stream it:
            # rates are wall-clock here, and at a high speed-up a short flight could begin
            # and end between two periodic reports.
            self._send_streamed(M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, tm.extended_sys_state(self.flight))
        self._report_all(events)
        if self.track is not None:
            self.track.write(self.flight)
        self.store.tick()
        if self.signer is not None and now >= self._signing_due:
            self._signing_due = now + SIGNING_TICK_S
            try:
                self.signer.tick()
            except SigningError as err:  # a full disk must not stop the telemetry below
                log.error("signing timestamp not stored (a restart could reuse timestamps): %s", err)
        self._stream(now)
        self._periodic(now)
        self._save_state()

    def _save_state(self, force: bool = False) -> None:
        """The flight to the state file, every ``SAVE_INTERVAL_S`` of wall time."""
        now = self.clock()
        if self._state_path is None or (not force and now < self._saved_at + SAVE_INTERVAL_S):
            return
        self._saved_at = now
        save_state(self._state_path, self.flight.snapshot())

    # --- streams ------------------------------------------------------------------------------
    def _peer_streams(self, peer: Hashable) -> PeerStreams:
        table = self.streams.get(peer)
        if table is None:
            table = self.streams[peer] = PeerStreams(self.config.flavour, self.config.speedup,
                                                     self.config.max_stream_hz)
        return table

    def _stream(self, now: float) -> None:
        peers = self.link.peers
        for gone in set(self.streams) - set(peers):
            del self.streams[gone]
        built: dict[int, Any] = {}
        for peer in peers:
            for msg_id in self._peer_streams(peer).due_now(now):
                if msg_id not in built:
                    built[msg_id] = self._message_for(msg_id)
                if built[msg_id] is not None:
                    self._send_to(built[msg_id], peer)

    def _send_streamed(self, msg_id: int, message: Any) -> None:
        """An extra report of a streamed message, to the peers that stream it."""
        for peer in self.link.peers:
            if self._peer_streams(peer).enabled(msg_id):
                self._send_to(message, peer)

    def _periodic(self, now: float) -> None:
        b = self.behaviour
        if b.timesync_interval_s is not None and now >= self._timesync_due:
            self._timesync_due = now + b.timesync_interval_s
            self._send_to(M.MAVLink_timesync_message(0, time.monotonic_ns()), None)
        f = self.flight
        if b.prearm_report_s is not None and now >= self._prearm_due:
            self._prearm_due = now + b.prearm_report_s
            if not f.armed:
                for reason in f.arm_checks():
                    self._text(M.MAV_SEVERITY_CRITICAL, f"PreArm: {reason}")
        if self._reached_repeat is not None and now >= self._reached_repeat[2]:
            seq, left, _ = self._reached_repeat
            self._send_to(M.MAVLink_mission_item_reached_message(seq), None)
            self._reached_repeat = (seq, left - 1, now + 1.0) if left > 1 else None

    def _set_interval(self, peer: Hashable, msg_id: int, interval_us: float) -> bool:
        if peer is None:
            return False
        return self._peer_streams(peer).set_interval(msg_id, interval_us)

    def _knows(self, msg_id: int) -> bool:
        return msg_id in PeerStreams(self.config.flavour).streamable

    # --- events -------------------------------------------------------------------------------
    def _report_all(self, events: list[FlightEvent]) -> None:
        for event in events:
            self._report(event)
        if self.flight.mode is not self._last_mode or self.flight.armed != self._last_armed:
            self._last_mode, self._last_armed = self.flight.mode, self.flight.armed
            self._send_to(tm.heartbeat(self.flight), None)

    def _text(self, severity: int, text: str, peer: Hashable = None) -> None:
        self._send_to(tm.statustext(severity, text), peer)

    def _report(self, event: FlightEvent) -> None:
        f = self.flight
        b = self.behaviour
        match event:
            case ItemComplete(seq=seq, command=command):
                log.info("mission item %d reached", seq)
                self._send_to(M.MAVLink_mission_item_reached_message(seq), None)
                if b.waypoint_reached_text is not None and command == M.MAV_CMD_NAV_WAYPOINT:
                    self._text(M.MAV_SEVERITY_INFO, b.waypoint_reached_text.format(seq=seq))
                if b.reached_repeats:
                    self._reached_repeat = (seq, b.reached_repeats, self.clock() + 1.0)
            case CurrentChanged(seq=seq):
                self._mission_current(tm.mission_current(f, seq))
            case CurrentUnnamed():
                self._mission_current(tm.mission_current(f, tm.NO_ITEM))
            case MissionDone(seq=seq):
                log.info("mission complete at item %d", seq)
                self._mission_current(tm.mission_current(f, seq, M.MISSION_STATE_COMPLETE))
                if b.mission_done_text is not None:
                    self._text(M.MAV_SEVERITY_INFO, b.mission_done_text)
            case CommandStarted(seq=seq, name=name):
                if b.command_started_text is not None:
                    self._text(M.MAV_SEVERITY_INFO, b.command_started_text.format(seq=seq, name=name))
            case MissionRestarted(seq=seq):
                log.info("mission changed in flight: command %d restarted", seq)
                if b.restarted_text is not None:
                    self._text(M.MAV_SEVERITY_CRITICAL, b.restarted_text)
            case MissionRestartFailed(seq=seq):
                log.info("mission changed in flight: item %d is gone, the command in progress goes on", seq)
                self._text(M.MAV_SEVERITY_CRITICAL, "Auto mission changed but failed to restart command")
            case ModeChangedItself():
                log.info("mode %s", mode_name(self.config.flavour, f.mode))
            case TouchedDown():
                log.info("landed at t=%.1f s (sim), battery %.1f%%", f.time_s, 100 * f.battery_fraction)
                self._send_streamed(M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, tm.extended_sys_state(f))
            case Armed():
                log.info("armed at t=%.1f s (sim)", f.time_s)
                if b.arming_text is not None:
                    self._text(M.MAV_SEVERITY_INFO, b.arming_text)
            case Disarmed(why=why):
                log.info("disarmed (%s) at t=%.1f s (sim), battery %.1f%%", why, f.time_s, 100 * f.battery_fraction)
                self._send_streamed(M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, tm.extended_sys_state(f))
                if b.disarming_text is not None:
                    self._text(M.MAV_SEVERITY_INFO, b.disarming_text)
            case BatteryLow(text=text):
                log.warning("%s", text)
                self._text(M.MAV_SEVERITY_CRITICAL, text)
            case BatterySwapped(text=text):
                log.info("%s at t=%.1f s (sim): battery %.1f%%", text, f.time_s, 100 * f.battery_fraction)
                self._text(M.MAV_SEVERITY_INFO, "Battery swapped: full")
                self._send_to(tm.battery_status(f, 0.0), None)
            case GpsFix():
                for text in b.gps_fix_texts:
                    self._text(M.MAV_SEVERITY_INFO, text)
            case OriginSet():
                log.info("estimator origin set at t=%.1f s since boot", f.since_boot_s)
                for text in b.origin_texts:
                    self._text(M.MAV_SEVERITY_INFO, text.format(alt_m=self.config.origin.alt_m))
            case UsingGps():
                log.info("position valid at t=%.1f s since boot", f.since_boot_s)
                for text in b.using_gps_texts:
                    self._text(M.MAV_SEVERITY_INFO, text)
            case HomeSet():
                self.store.home_known()
                for msg_id in b.home_set_messages:  # once, unasked, to every link
                    message = self._message_for(msg_id)
                    if message is not None:
                        self._send_to(message, None)
            case _:
                assert_never(event)

    def _mission_current(self, message: Any) -> None:
        """MISSION_CURRENT at an event: PX4 sends it to every link; for ArduPilot an extra
        report to the peers that stream it (rates here are wall-clock, see tick)."""
        if self.behaviour.mission_current_to_all:
            self._send_to(message, None)
        else:
            self._send_streamed(M.MAVLINK_MSG_ID_MISSION_CURRENT, message)

    # --- input -----------------------------------------------------------------------------
    def handle(self, received: Received) -> None:
        msg, peer = received.msg, received.peer
        if received.new_peer:
            # Greet a new peer at once: MAVSDK then sees the vehicle in milliseconds.
            log.info("new peer %s (system %d)", peer, msg.get_srcSystem())
            self._peer_streams(peer)
            self._send_to(tm.heartbeat(self.flight), peer)
        target = getattr(msg, "target_system", None)
        if target not in (None, 0, self.config.system_id):
            return
        if not self.store.handle(msg, peer):
            self._handle_other(msg, peer)
        self._report_all(self.flight.drain())

    def _handle_other(self, msg: Any, peer: Hashable) -> None:
        kind = msg.get_type()
        if kind in ("COMMAND_LONG", "COMMAND_INT"):
            self._command(msg, peer)
        elif kind == "SET_MODE":
            mode = mode_from_custom(self.config.flavour, msg.custom_mode)
            if mode is not None:
                refusal = self.flight.set_mode(mode)
                refused_text = self.behaviour.mode_refused_text
                if refusal is not None and refused_text is not None:
                    ap, number = self.behaviour.autopilot, int(msg.custom_mode)
                    sub = (number >> ap.sub_shift) & 0xFF if ap.sub_shift is not None else 0
                    name = requested_name(ap, (number >> ap.main_shift) & ap.main_mask, mode, sub)
                    self._refusal_texts(refusal, refused_text.format(name=name), M.MAV_SEVERITY_WARNING)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            self._send_to(M.MAVLink_timesync_message(time.monotonic_ns(), msg.ts1), peer)
        elif kind == "REQUEST_DATA_STREAM":
            self._peer_streams(peer).request_data_stream(int(msg.req_stream_id), float(msg.req_message_rate),
                                                         bool(msg.start_stop))
        elif kind == "PARAM_REQUEST_LIST":
            for message in self.params.all():
                self._send_to(message, peer)
        elif kind == "PARAM_REQUEST_READ":
            name = msg.param_id.decode("ascii", "replace") if isinstance(msg.param_id, bytes) else str(msg.param_id)
            answer = self.params.read(name.rstrip("\x00"), int(msg.param_index))
            if answer is not None:  # an unknown name gets no answer, as on ArduPilot
                self._send_to(answer, peer)
        elif kind == "PARAM_SET":
            name = msg.param_id.decode("ascii", "replace") if isinstance(msg.param_id, bytes) else str(msg.param_id)
            index = self.params.index_of(name.rstrip("\x00"))
            if index is not None:  # read-only: the value kept is the answer
                self._send_to(self.params.message(index), None)

    def _refusal_texts(self, refusal: Refusal, prefix: str, severity: int) -> None:
        for note in refusal.notes:
            self._text(M.MAV_SEVERITY_CRITICAL, note)
        for reason in refusal.reasons:
            self._text(severity, prefix + reason)

    def _command(self, msg: Any, peer: Hashable) -> None:
        outcome = self.commands.execute(msg, peer)
        if outcome.result != M.MAV_RESULT_ACCEPTED:
            log.info("command %d refused (%d): %s", msg.command, outcome.result, outcome.reason)
        else:
            log.info("command %d accepted; mode %s, armed %s", msg.command,
                     mode_name(self.config.flavour, self.flight.mode), self.flight.armed)
        for before in outcome.before:
            self._send_to(before, peer)
        self._send_to(M.MAVLink_command_ack_message(
            msg.command, outcome.result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()), peer)
        for follow_up in outcome.follow_up:
            self._send_to(follow_up, peer)
        for severity, text in outcome.texts:
            self._text(severity, text)

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
            M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN: lambda: tm.gps_global_origin(f),
            M.MAVLINK_MSG_ID_AUTOPILOT_VERSION: lambda: tm.autopilot_version(f, self.config.system_id),
            M.MAVLINK_MSG_ID_VFR_HUD: lambda: tm.vfr_hud(f, 0 if f.landed else 50),
            M.MAVLINK_MSG_ID_SYSTEM_TIME: lambda: tm.system_time(f, time.time()),
        }
        if self.behaviour.estimator_report_streamed:
            builders[self.behaviour.autopilot.estimator_msg_id] = lambda: tm.ekf_status_report(f)
        builder = builders.get(msg_id)
        return builder() if builder else None

    def _on_accepted(self, items: list[MissionItem]) -> None:
        log.info("mission of %d items accepted (digest %s)", len(items), mission_digest(items, self.config.flavour))

    def _home_item(self) -> MissionItem:
        """ArduPilot's item 0 as read back: home in MAV_FRAME_GLOBAL (zeros before home)."""
        if not self.flight.home_set:
            return MissionItem(seq=0, frame=M.MAV_FRAME_GLOBAL, command=M.MAV_CMD_NAV_WAYPOINT)
        lat, lon, alt = local_to_global(self.config.origin, *self.flight.home)
        return MissionItem(seq=0, frame=M.MAV_FRAME_GLOBAL, command=M.MAV_CMD_NAV_WAYPOINT,
                           x=int(round(lat * 1e7)), y=int(round(lon * 1e7)), z=f32(alt))

    def _current_flag(self, seq: int) -> int:
        if self.behaviour.current_flag_is_command:
            # MissionItemProtocol_Waypoints::get_item compares the item's command id with
            # the current index (sic), so the flag is 1 only by coincidence; kept as is.
            items = self.store.items
            return int(0 <= seq < len(items) and items[seq].command == self.flight.current)
        return int(seq == self.flight.current)

    def _can_clear(self) -> bool:
        return self.flight.state is not MissionState.RUNNING

    def _on_set_current(self, seq: int, peer: Hashable) -> bool:
        ok = self.flight.set_current(seq)
        log.info("MISSION_SET_CURRENT %d %s: current %d, mission %s", seq, "accepted" if ok else "refused",
                 self.flight.current, self.flight.state.value)
        if ok and self.behaviour.echoes_set_current:
            # GCS_MAVLINK::handle_mission_set_current echoes the requested seq to the sender.
            self._send_to(tm.mission_current(self.flight, seq), peer)
        return ok

    def _item_problem(self, item: MissionItem) -> Problem | None:
        problem = self.behaviour.item_problem(item)
        if problem is not None:
            return problem
        if item.seq < self.behaviour.autopilot.home_slots:
            return None  # home: never flown
        return self._fence_problem(item)

    def _fence_problem(self, item: MissionItem) -> Problem | None:
        """The stub's geofence: the scenario's area grown by ``fence_margin_m``, and the
        altitude limit (a stand-in for the autopilot's fence, refused per item)."""
        side = self.config.scenario.area_side_m
        margin = self.config.fence_margin_m
        positional = item.command in NAV_POSITION_COMMANDS or item.command == M.MAV_CMD_NAV_LOITER_TIME
        if not positional or item.frame not in GLOBAL_FRAMES:
            return None
        if item.command == M.MAV_CMD_NAV_LAND and item.x == 0 and item.y == 0:
            return None  # land where it is
        x, y, z = item_local(item, self.config.origin)
        if item.command == M.MAV_CMD_NAV_TAKEOFF:
            # ArduCopter climbs where it stands, whatever the item's latitude and longitude
            # (mode_auto.cpp takeoff_start); a fleet's UAV standing away from the fleet's
            # origin sends the origin's: only the altitude is the takeoff's own
            x, y = 0.0, 0.0
        if not -margin <= x <= side + margin:
            return M.MAV_MISSION_INVALID_PARAM5_X, f"item {item.seq}: x {x:.0f} m outside the geofence"
        if not -margin <= y <= side + margin:
            return M.MAV_MISSION_INVALID_PARAM6_Y, f"item {item.seq}: y {y:.0f} m outside the geofence"
        if not 0.0 <= z <= self.config.max_altitude_m:
            return M.MAV_MISSION_INVALID_PARAM7, f"item {item.seq}: altitude {z:.0f} m out of limits"
        return None
