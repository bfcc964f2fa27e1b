"""The autopilot as a link hears it: one ``VehicleState`` per link, fed every message with
its source (system, component) by either backend, keeping ``Telemetry`` and emitting the
typed events. No I/O: the backend gives it an ``emit`` callable, a clock, and callbacks
for what needs I/O (asking for telemetry again, a new mission generation on a restart).

Trust (issue: a forged datagram must change nothing): the autopilot is the (system,
component) of the first heartbeat from a component 1 with a real autopilot type; from then
on telemetry, STATUSTEXT and (in the backends) mission replies, reports and COMMAND_ACKs
count only from that pair. A restart is believed only from several position reports of a
clock gone back, consistent with each other, over half a second of wall time with none of the
clock kept between (``clock.ClockWatch``); a report far ahead is discarded, never taken as the
clock. A MISSION_CURRENT naming another item counts only once the vehicle's stream agrees
(``progress.CurrentWatch``).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from typing import Any, Callable

from pymavlink.dialects.v20 import ardupilotmega as M

from protocol.text import printable

from .events import (MAX_TEXT, ArmedChanged, Connected, OnGround, LinkEvent, Lost, ModeChanged, PositionChanged,
                     Restarted, Restored, StatusText, TelemetryMissing)
from protocol.autopilot import Autopilot, autopilot_for, autopilot_name

from .asked import Asked
from .modes import mode_name
from .progress import CurrentWatch
from .statustext import StatusTexts
from .streams import Request, Streams, quiet_plan, stream_plan
from .telemetry import (ClockRate, ClockWatch, PositionInputs, Telemetry, assess_position, battery_fraction,
                        derived_airborne, energy_used_j)

log = logging.getLogger("planner_service.link")

AUTOPILOT_COMPONENT = M.MAV_COMP_ID_AUTOPILOT1
AIRBORNE_STATES = frozenset({M.MAV_LANDED_STATE_IN_AIR, M.MAV_LANDED_STATE_TAKEOFF, M.MAV_LANDED_STATE_LANDING})
NOT_AUTOPILOTS = frozenset({M.MAV_TYPE_GCS, M.MAV_TYPE_ONBOARD_CONTROLLER, M.MAV_TYPE_GIMBAL, M.MAV_TYPE_CAMERA,
                            M.MAV_TYPE_ADSB, M.MAV_TYPE_ANTENNA_TRACKER})
SILENCE_S = 1.3
"""Seconds without any message from the autopilot after which the next one is taken as
possibly from a new boot, and its telemetry is asked for again (an autopilot sends a
heartbeat every second whatever else it sends)."""
DERIVED = "derived (armed, relative altitude, climb)"
TEXTS_KEPT_S = 30.0
"""STATUSTEXTs kept this long, to name an autopilot's refusal in an error."""


class VehicleState:
    def __init__(self, flavour: str | Autopilot, emit: Callable[[LinkEvent], None], *, link_timeout_s: float = 3.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.profile = autopilot_for(flavour)
        self.flavour = self.profile.name
        self.emit = emit
        self.clock = clock
        self.link_timeout_s = link_timeout_s
        self.telemetry = Telemetry()
        self.autopilot: tuple[int, int] | None = None
        self.streams = Streams(stream_plan(self.profile), clock, quiet_plan(self.profile))
        self.estimator = self.profile.estimator_message
        self.request_streams: Callable[[], None] = lambda: None
        """Set by the backend: ask for every stream again (after a restart or a gap)."""
        self.on_restart: Callable[[], None] = lambda: None
        """Set by the backend: the vehicle restarted (a new mission generation)."""
        self.texts: deque[tuple[float, int, str]] = deque(maxlen=32)
        self.wrong_autopilot = ""
        """Why the first autopilot heard was not taken: another autopilot than configured."""
        self._texts = StatusTexts(id_zero_chunks=self.profile.text_ids_from_zero)
        self.untrusted = 0
        """Messages dropped because they did not come from the autopilot."""
        self.disarms = 0
        """Disarmings seen (a start stops if one comes between its steps)."""
        self._clock_watch = ClockWatch()
        self.current_watch = CurrentWatch()
        """Which MISSION_CURRENT the backends believe (``progress``)."""
        self._clock_rate = ClockRate()
        self._pos = PositionInputs(estimator_name=self.estimator,
                                   estimator_unaided_flags=self.profile.estimator_unaided_flags)
        self.mode_asked: Asked[str] = Asked()
        self.arming_asked: Asked[bool] = Asked()
        """What the link asked for: a heartbeat showing it was commanded (``asked``)."""
        self._last_heard = 0.0
        self._lost = False
        self._missing_said: tuple[str, ...] = ()
        self._derived_said = False
        self._last_reached: tuple[int, int] | None = None

    # --- trust ----------------------------------------------------------------------------
    def trusted(self, system: int, component: int) -> bool:
        """The message comes from the autopilot (counted otherwise, and dropped by the caller)."""
        if self.autopilot is not None and (system, component) == self.autopilot:
            return True
        self.untrusted += 1
        return False

    def _set(self, **changes: Any) -> None:
        self.telemetry = Telemetry(**{**self.telemetry.__dict__, **changes})

    def set_progress(self, seq: int, total: int, mission_id: int = 0) -> None:
        """The mission item flown, the mission's size and id, as the backend's reports say."""
        t = self.telemetry
        if (seq, total, mission_id) != (t.mission_seq, t.mission_total, t.mission_id):
            log.debug("vehicle: mission item %d of %d (mission id %d)", seq, total, mission_id)
        self._set(mission_seq=seq, mission_total=total, mission_id=mission_id)

    def new_reach(self, mission: int, seq: int) -> bool:
        """A MISSION_ITEM_REACHED of item ``seq`` of ``mission`` (a generation): False when it
        repeats the last one. PX4 sends each up to 11 times, then 10 more at 1 Hz (seen on
        PX4 SITL 1.18); only another item in between makes the same one news again (a
        mission flown again from an earlier item). The repeats carry the seq alone: those
        straddling an upload's ACK are sorted to the missions on either side (``reports``), so
        a repeat is the last seq reached whatever mission it is put to."""
        if self._last_reached is not None and self._last_reached[1] == seq:
            return False
        self._last_reached = (mission, seq)
        return True

    # --- link liveness ----------------------------------------------------------------------
    def heard(self) -> None:
        now = self.clock()
        silent_s = now - self._last_heard
        self._last_heard = now
        if self._lost:
            self._lost = False
            self._set(connected=True)
            log.info("autopilot heard again (mode %s)", self.telemetry.mode)
            self.emit(Restored(self.telemetry.mode))
            self.request_streams()  # it may have restarted meanwhile, its rates reset
        elif silent_s > SILENCE_S:
            # Too short for a lost link, long enough for a reboot: a restarted autopilot
            # streams nothing until asked, and only its reports' clock shows the restart, so
            # ask now rather than when a missing message is next asked for (seconds later,
            # after the mode it came back in was taken for a pilot's; test_faults met it).
            log.info("autopilot heard after %.1f s of silence: asking for its telemetry again", silent_s)
            self.request_streams()

    def lose(self, detail: str) -> None:
        """The link is down (silence, or the connection broke)."""
        if self._lost or self.autopilot is None:
            return
        self._lost = True
        self._set(connected=False)
        log.warning("autopilot link lost: %s", detail)
        self.emit(Lost(detail))

    @property
    def lost(self) -> bool:
        return self._lost

    def tick(self) -> list[Request]:
        """Once a second: the silence watchdog, what is missing, the judgements that change
        with time; returns the stream requests to repeat."""
        now = self.clock()
        self._said(self._texts.flush(now))
        if self.autopilot is not None and not self._lost and now - self._last_heard > self.link_timeout_s:
            self.lose(f"nothing heard from the autopilot for {now - self._last_heard:.1f} s")
        if self.autopilot is None or self._lost:
            return []
        missing = self.streams.missing()
        if missing != self._missing_said:
            self._missing_said = missing
            self._set(missing=missing)
            if missing:
                log.warning("telemetry missing: %s", "; ".join(f"{n} {self.streams.describe(n)}" for n in missing))
            else:
                log.info("telemetry: every message asked for arrives")
            self.emit(TelemetryMissing(missing))
        self._assess()
        self._derive_landed()
        return self.streams.due()

    # --- incoming -------------------------------------------------------------------------
    def on_heartbeat(self, system: int, component: int, msg: Any) -> bool:
        """A HEARTBEAT; True when it is the autopilot's (the first such chooses it)."""
        if msg.autopilot == M.MAV_AUTOPILOT_INVALID or msg.type in NOT_AUTOPILOTS:
            return False
        first = self.autopilot is None
        if first:
            if component != AUTOPILOT_COMPONENT:
                return False
            if msg.autopilot != self.profile.mav_autopilot:
                # Flown with another autopilot's conventions its mission would be wrong (a
                # home slot, mode numbers): never taken for the autopilot configured.
                self.wrong_autopilot = (f"the autopilot {system}/{component} is {autopilot_name(msg.autopilot)} "
                                        f"(HEARTBEAT autopilot {msg.autopilot}), not {self.profile.name} "
                                        f"as mavlink.flavour says")
                return False
            self.autopilot = (system, component)
        elif (system, component) != self.autopilot:
            # Another vehicle or component on the same network: following it would show its
            # state as ours, and its landing would end our sortie.
            self.untrusted += 1
            return False
        armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
        mode = mode_name(self.profile, msg.custom_mode)
        old_mode, was_armed = self.telemetry.mode, self.telemetry.armed
        self._set(armed=armed, mode=mode, connected=not self._lost or first)
        if first:
            self._last_heard = self.clock()
            log.info("autopilot %d/%d connected (mode %s)", system, component, mode)
            self.emit(Connected(mode, system, component))
        else:
            self.heard()
        if old_mode and mode != old_mode:
            commanded = self.mode_asked.shows(mode, self.clock())
            log.info("vehicle: mode %s (was %s; %s)", mode, old_mode, _by(commanded))
            self.emit(ModeChanged(mode, commanded))
        if not first and armed != was_armed:
            commanded = self.arming_asked.shows(armed, self.clock())
            log.info("vehicle: %s (%s)", "armed" if armed else "disarmed", _by(commanded))
            self.disarms += not armed
            self.emit(ArmedChanged(armed, commanded))
        self._derive_landed()
        return True

    def on_message(self, name: str, msg_id: int, system: int, component: int, msg: Any) -> bool:
        """A telemetry message (not HEARTBEAT, not mission protocol); False when dropped."""
        if not self.trusted(system, component):
            return False
        self.heard()
        self.streams.heard(msg_id)
        handler = _HANDLERS.get(name)
        if handler is not None:
            return handler(self, msg)
        return True

    def _position(self, msg: Any) -> bool:
        boot_s = msg.time_boot_ms / 1e3
        now = self.clock()
        verdict = self._clock_watch.observe(boot_s, self.telemetry.time_rate, now)
        if verdict == "outlier":
            return False  # ignored unless the reports that follow confirm a new clock
        if verdict == "restart":
            self._restarted(f"its clock went back to {boot_s:.1f} s ({self._clock_watch.confirm_readings} "
                            f"reports over {self._clock_watch.confirm_s:g} s)")
        elif verdict == "jump":
            log.warning("the autopilot's clock jumped ahead to %.1f s (reports over %g s): its rate is measured again",
                        boot_s, self._clock_watch.confirm_s)
            self._clock_rate = ClockRate()
        rate = self._clock_rate.update(boot_s, now)
        self._pos = _replace(self._pos, lat_e7=int(msg.lat), lon_e7=int(msg.lon))
        self._set(lat_deg=msg.lat / 1e7, lon_deg=msg.lon / 1e7, rel_alt_m=msg.relative_alt / 1e3,
                  climb_mps=-msg.vz / 100.0, position_boot_s=boot_s, boot_s=boot_s, position_at=now, time_rate=rate)
        self._assess()
        self._derive_landed()
        return True

    def _gps(self, msg: Any) -> bool:
        self._pos = _replace(self._pos, gps_fix=int(msg.fix_type))
        self._set(gps_fix=int(msg.fix_type))
        self._assess()
        return True

    def _estimator(self, msg: Any) -> bool:
        self._pos = _replace(self._pos, estimator_flags=int(msg.flags))
        self._assess()
        return True

    def _home(self, msg: Any) -> bool:
        home = not (msg.latitude == 0 and msg.longitude == 0)
        self._pos = _replace(self._pos, home_set=home)
        self._set(home_set=home)
        self._assess()
        return True

    def _sys_status(self, msg: Any) -> bool:
        if self.streams.arriving("BATTERY_STATUS"):
            return True  # BATTERY_STATUS says more (the energy used)
        self._set(battery_fraction=battery_fraction(int(msg.battery_remaining)), battery_at=self.clock())
        return True

    def _battery(self, msg: Any) -> bool:
        if int(getattr(msg, "id", 0)) != 0:
            return True  # the first battery is the one flown on
        self._set(battery_fraction=battery_fraction(int(msg.battery_remaining)),
                  energy_used_j=energy_used_j(int(msg.energy_consumed)), battery_at=self.clock())
        return True

    def _extended_sys_state(self, msg: Any) -> bool:
        state = int(msg.landed_state)
        if state == M.MAV_LANDED_STATE_UNDEFINED:
            return True
        self._landed(state in AIRBORNE_STATES, "EXTENDED_SYS_STATE")
        return True

    def _statustext(self, msg: Any) -> bool:
        joined = self._texts.feed(str(msg.text).rstrip("\x00"), int(msg.severity), int(getattr(msg, "id", 0) or 0),
                                  int(getattr(msg, "chunk_seq", 0) or 0), self.clock())
        self._said(joined)
        return True

    def _said(self, texts: list[tuple[str, int]]) -> None:
        for raw, severity in texts:
            text = printable(raw, MAX_TEXT)
            self.texts.append((self.clock(), severity, text))
            log.log(logging.WARNING if severity <= M.MAV_SEVERITY_WARNING else logging.INFO, "autopilot: %s", text)
            self.emit(StatusText(text, severity))

    # --- judgements ---------------------------------------------------------------------------
    def texts_since(self, since: float) -> list[str]:
        """The STATUSTEXTs heard since ``since`` (monotonic), oldest first."""
        cutoff = max(since, self.clock() - TEXTS_KEPT_S)
        return [text for at, _, text in self.texts if at >= cutoff]

    def _assess(self) -> None:
        p = _replace(self._pos, position_fresh="GLOBAL_POSITION_INT" not in self.streams.missing(),
                     gps_available=self.streams.available("GPS_RAW_INT"),
                     estimator_available=self.streams.available(self.estimator),
                     home_available=self.streams.available("HOME_POSITION"))
        waiting = assess_position(p)
        t = self.telemetry
        if waiting == t.waiting_for and t.position_ok == (not waiting):
            return
        self._set(position_ok=not waiting, waiting_for=waiting)
        if t.position_ok != (not waiting):
            if waiting:
                log.warning("no position: waiting for %s", waiting)
            else:
                log.info("position: the autopilot has one (GPS fix %d)", t.gps_fix)
            self.emit(PositionChanged(not waiting, waiting))

    def _landed(self, airborne: bool, source: str) -> None:
        was = self.telemetry.airborne
        self._set(airborne=airborne, landed_known=True, landed_source=source)
        if was != airborne:
            log.info("vehicle: %s (%s)", "in the air" if airborne else "on the ground", source)
        if was and not airborne:
            self.emit(OnGround(source))

    def _derive_landed(self) -> None:
        """Where the autopilot gives no landed state (EXTENDED_SYS_STATE refused or silent),
        derive it from armed, the height above home and the climb."""
        if self.streams.arriving("EXTENDED_SYS_STATE") or "EXTENDED_SYS_STATE" not in self.streams.missing():
            return
        t = self.telemetry
        if t.position_boot_s is None:
            return
        if not self._derived_said:
            self._derived_said = True
            log.warning("no EXTENDED_SYS_STATE from the autopilot: the landed state is %s", DERIVED)
        self._landed(derived_airborne(t.armed, t.rel_alt_m, t.climb_mps, t.airborne), DERIVED)

    def _restarted(self, detail: str) -> None:
        """The vehicle rebooted: what it reported before (home, estimator, mission) is stale."""
        self._pos = PositionInputs(estimator_name=self.estimator,
                                   estimator_unaided_flags=self.profile.estimator_unaided_flags)
        self._clock_rate = ClockRate()
        self.current_watch.reset()
        self._set(home_set=False, gps_fix=-1, mission_seq=0, mission_total=-1, mission_id=0)
        log.warning("the autopilot restarted: %s", detail)
        self.on_restart()
        self.emit(Restarted(detail))
        self.request_streams()


def _by(commanded: bool) -> str:
    return "asked by the service" if commanded else "not asked by the service"


def _replace(p: PositionInputs, **changes: Any) -> PositionInputs:
    return PositionInputs(**{**p.__dict__, **changes})


_HANDLERS: dict[str, Callable[[VehicleState, Any], bool]] = {
    "GLOBAL_POSITION_INT": VehicleState._position,
    "GPS_RAW_INT": VehicleState._gps,
    "EKF_STATUS_REPORT": VehicleState._estimator,
    "ESTIMATOR_STATUS": VehicleState._estimator,
    "HOME_POSITION": VehicleState._home,
    "SYS_STATUS": VehicleState._sys_status,
    "BATTERY_STATUS": VehicleState._battery,
    "EXTENDED_SYS_STATE": VehicleState._extended_sys_state,
    "STATUSTEXT": VehicleState._statustext,
}
