"""The simulated aircraft: flies a mission in simulated time and drains its battery with the
project's energy model. Pure: no sockets, no clock; ``step(dt)`` advances time and returns
what happened (typed events, ``events.py``); commands queue their events for the next
``drain()``.

Energy (planner_service.model.energy, the same functions the planner's playouts use):
- flight: each straight leg costs ``flight_energy_j(p, distance)``, charged as the distance
  grows, so a leg flown in many steps costs exactly what the model charges for one hop;
  climbs and descents are legs too (the model has no separate climb power);
- hovering: ``hover_power_w`` per second whenever airborne and not moving (holding at a
  waypoint or loitering);
- computation (6): while holding at a waypoint the UAV computes what the user below uploads,
  ``computation_energy_j(p, rate * dt)`` with the rate of a user straight below.
When the battery reaches ``battery_threshold * battery_j`` in the air the aircraft returns
to launch, as an autopilot's battery failsafe does.

The mission is executed the way each autopilot does it (docs/VEHICLE.md has what was
checked on ArduCopter SITL and read in the sources; each choice is a field of
``behaviour.Behaviour``):
- **ArduPilot** (``libraries/AP_Mission/AP_Mission.cpp``, ``AP_Mission_ChangeDetector.cpp``,
  ``ArduCopter/mode_auto.cpp``): a mission is STOPPED, RUNNING or COMPLETE at a navigation
  index; entering AUTO starts or resumes it (a completed one starts again at item 1);
  armed on the ground it climbs only after MISSION_START (``auto_armed``); a change to the
  stored mission while a waypoint is flown restarts the command at the same index (its hold
  starts again) or, if that index is gone, goes on with the command in progress; after the
  last item it hovers in AUTO. MISSION_SET_CURRENT starts the item now if the mission runs,
  otherwise only moves the index.
- **PX4** (``src/modules/navigator/mission_base.cpp``): a new mission (a different CRC)
  becomes active at the item marked current in the upload, or at the old index clamped to
  the new length, and in mission mode that item starts now; an identical upload changes
  nothing.

Battery swap (``recharge_s``): ``recharge_s`` simulated seconds after the aircraft is on
the ground and disarmed, its battery is full again and the failsafe is cleared. Auto-disarm
(``disarm_delay_s``, ArduPilot's DISARM_DELAY, PX4's COM_DISARM_PRFLT): armed on the ground
that long without leaving it, the motors stop.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

import numpy as np

from planner_service.model import Scenario, pack
from planner_service.model.channel import channel_gain, upload_rate_bps
from planner_service.model.energy import computation_energy_j, flight_energy_j
from protocol.geodesy import GeoOrigin
from protocol.mission import (
    DO_CHANGE_SPEED, GLOBAL_FRAMES, NAV_LAND, NAV_RTL, NAV_TAKEOFF, NAV_WAYPOINT, MissionItem,
    item_local,
)

from .behaviour import Behaviour, behaviour_for
from .errors import VehicleError
from .estimator import Stage, stage_at
from .events import (
    Armed, CommandStarted, CurrentChanged, CurrentUnnamed, Disarmed, FlightEvent, GpsFix, HomeSet, TouchedDown,
    MissionDone, MissionRestarted, MissionRestartFailed, ModeChangedItself, OriginSet, ItemComplete,
    UsingGps, BatteryLow, BatterySwapped,
)
from .modes import Mode
from .stored_items import NAV_COMMANDS, crc_of

NAV_LOITER_TIME = 19
NAV_DELAY = 93
HOLD_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_TIME})
GROUND_M = 0.05
"""Below this height (m) the aircraft counts as on the ground."""
EPS_S = 1e-9
FALL_MPS = 15.0
"""How fast a vehicle disarmed in the air falls (a small quadcopter's terminal speed is of
this order; the stub does not model the acceleration, only that it comes down and lands)."""
MAX_SUBSTEP_S = 1.0
"""The battery failsafe is checked at least this often (simulated seconds): the battery
ends at most one sub-step's drain below the threshold when the aircraft turns home."""
MAX_IDLE_SUBSTEPS = 64
"""Sub-steps in a row that use no time (items completed at once) before the rest of a step
is spent hovering: a bound on the work of one step, whatever the mission."""
PX4_TAKEOFF_MIN_M = 2.5
"""PX4's MIS_TAKEOFF_ALT: the least height of an implicit takeoff."""
CHANGE_WINDOW = 3
"""ArduPilot's change detector compares the next three navigation commands."""
GPS_MODES = frozenset({Mode.AUTO, Mode.GUIDED, Mode.HOLD, Mode.RTL, Mode.TAKEOFF})
"""Modes that need a position (Copter's ``requires_GPS``; PX4's global-position modes)."""
COMMAND_NAMES = {
    NAV_WAYPOINT: "WP", NAV_TAKEOFF: "Takeoff", NAV_LAND: "Land", NAV_RTL: "RTL",
    NAV_LOITER_TIME: "LoitTime", NAV_DELAY: "Delay", DO_CHANGE_SPEED: "ChangeSpeed",
}
"""AP_Mission::Mission_Command::type(), for ``Mission: 3 WP``."""


class MissionState(enum.Enum):
    """AP_Mission's states (PX4 is mapped onto the same three)."""

    STOPPED = "stopped"
    RUNNING = "running"
    COMPLETE = "complete"


@dataclass(frozen=True)
class Refusal:
    """Why a command was refused: ``reasons`` are the autopilot's own words (ArduPilot sends
    each as a STATUSTEXT), ``notes`` are sent before them (``Auto: Missing Takeoff Cmd``)."""

    reasons: tuple[str, ...]
    notes: tuple[str, ...] = ()

    @property
    def text(self) -> str:
        return "; ".join(self.notes + self.reasons)


@dataclass(frozen=True)
class FlightSnapshot:
    """A flight's state as the vehicle saves it to survive a restart (``--state-file``):
    local metres, joules, simulated seconds; ``mode`` is a ``Mode`` value."""

    flavour: str
    pos: tuple[float, float, float]
    home: tuple[float, float, float]
    energy_j: float
    armed: bool
    landed: bool
    mode: str
    time_s: float
    speed_mps: float
    flight_j: float = 0.0
    hover_j: float = 0.0
    compute_j: float = 0.0


@dataclass
class Flight:
    """One simulated aircraft. Positions are local metres (x east, y north, z up above the
    origin, which is also the ground height)."""

    scenario: Scenario
    origin: GeoOrigin = field(default_factory=GeoOrigin)
    flavour: str = "ardupilot"
    climb_mps: float = 5.0
    rtl_min_alt_m: float = 15.0
    recharge_s: float | None = None
    """Simulated seconds on the ground, disarmed, until the battery is full again."""
    gps_delay_s: float = 0.0
    """Simulated seconds after boot until the estimator navigates with GPS (estimator.py);
    0: a position from the start."""
    disarm_delay_s: float = 0.0
    """Armed on the ground this long without taking off, the motors stop; 0: never."""

    def __post_init__(self) -> None:
        if self.recharge_s is not None and not (math.isfinite(self.recharge_s) and self.recharge_s >= 0):
            raise VehicleError("recharge_s", f"must be a finite number of seconds >= 0, got {self.recharge_s}")
        for name in ("gps_delay_s", "disarm_delay_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise VehicleError(name, f"must be a finite number of seconds >= 0, got {value}")
        self.behaviour: Behaviour = behaviour_for(self.flavour)
        self.p = pack(self.scenario)
        self.home = (float(self.scenario.base_x_m), float(self.scenario.base_y_m), 0.0)
        self.pos = list(self.home)
        self.vel = (0.0, 0.0, 0.0)
        self.armed = False
        self.landed = True
        self.mode = self.behaviour.boot_mode
        self.mission: list[MissionItem] = []
        self.current = 0
        """The navigation index (ArduPilot: 0 when none is loaded)."""
        self.state = MissionState.STOPPED
        self.loaded: MissionItem | None = None
        """The navigation command being flown: a copy, so that a mission changed under it
        (ArduPilot's failed restart) does not change the target."""
        self.paused = False
        self.auto_armed = False
        """ArduPilot: AUTO on the ground climbs only once MISSION_START said so."""
        self.hold_left: float | None = None
        self.climb_out: float | None = None
        self.energy_j = float(self.scenario.battery_j)
        self.time_s = 0.0
        self.boot_s = 0.0
        """Simulated time of the last (re)start: ``time_boot_ms`` counts from here."""
        self.speed_mps = float(self.scenario.speed_mps)
        self.guided_alt: float | None = None
        self.failsafe = False
        self._leg: tuple[float, float, float] | None = None
        self._leg_m = 0.0
        self.flight_j = 0.0
        self.hover_j = 0.0
        self.compute_j = 0.0
        self.ground_s = 0.0
        """Simulated seconds on the ground and disarmed since the battery was last used."""
        self.ground_armed_s = 0.0
        """Simulated seconds armed on the ground (auto-disarm)."""
        self.swaps = 0
        self.stage = Stage.NO_GPS
        self.home_set = False
        self._window: tuple[tuple[int, MissionItem], ...] = ()
        self._events: list[FlightEvent] = []
        self._update_stage()
        self._warm_up()

    def _warm_up(self) -> None:
        """Call each compiled kernel once: loading numba's cache takes a fraction of a
        second, which must not happen in the middle of a flight."""
        here = np.zeros(3)
        flight_energy_j(self.p, 1.0)
        computation_energy_j(self.p, 1.0)
        upload_rate_bps(self.p, channel_gain(self.p, here, here))

    # --- read-outs ----------------------------------------------------------------------
    @property
    def energy_floor_j(self) -> float:
        return float(self.scenario.energy_floor_j)

    @property
    def battery_fraction(self) -> float:
        return max(0.0, self.energy_j / self.scenario.battery_j)

    @property
    def first_item(self) -> int:
        """ArduPilot's item 0 is home and never flown (``Autopilot.home_slots``)."""
        return self.behaviour.autopilot.first_item

    @property
    def since_boot_s(self) -> float:
        """Simulated seconds since the vehicle (re)started: its MAVLink clock."""
        return self.time_s - self.boot_s

    @property
    def position_ok(self) -> bool:
        """The estimator navigates: arming in a position mode and AUTO are allowed."""
        return self.stage is Stage.NAVIGATING

    @property
    def started(self) -> bool:
        return self.state is not MissionState.STOPPED or self.loaded is not None

    @property
    def mission_present(self) -> bool:
        """ArduPilot's ``present()``: more than home; PX4: any item."""
        return len(self.mission) > self.first_item

    def drain(self) -> list[FlightEvent]:
        """The events queued by commands and mission changes since the last step."""
        events, self._events = self._events, []
        return events

    # --- commands -------------------------------------------------------------------------
    def arm(self) -> Refusal | None:
        """Arm; the reasons if the pre-arm checks refuse."""
        if self.armed:
            return None
        reasons = self.arm_checks()
        if reasons:
            return Refusal(tuple(reasons))
        self.armed = True
        self.auto_armed = False
        self.ground_s = 0.0
        self.ground_armed_s = 0.0
        self._events.append(Armed())
        if self.stage >= Stage.ORIGIN and self.landed:
            self._set_home()  # both autopilots take home where they arm
        return None

    def arm_checks(self) -> list[str]:
        """The failing pre-arm checks, in the autopilot's words (empty: it would arm)."""
        reasons: list[str] = []
        if self.energy_j <= self.energy_floor_j:
            reasons.append("Battery below the return threshold")
        b = self.behaviour
        if b.arm_position_in_any_mode or self.mode in GPS_MODES:
            if b.arm_no_origin_text is not None and self.stage < Stage.ORIGIN:
                reasons.append(b.arm_no_origin_text)
            elif not self.position_ok:
                reasons.append(b.arm_no_position_text)
        if self.mode is Mode.AUTO and not b.arms_in_mission_mode:
            reasons.append("AUTO mode not armable" if self.mission_present else "Mode requires mission")
        return reasons

    def disarm(self, force: bool = False, why: str = "command") -> Refusal | None:
        if not self.armed:
            return None
        if not self.landed and not force:
            return Refusal(("cannot disarm in the air",))
        self.armed = False
        self.auto_armed = False
        self.vel = (0.0, 0.0, 0.0)
        if self.behaviour.disarm_resets_mission:  # no navigation index (MISSION_CURRENT 0)
            self.current, self.loaded = 0, None
            self.hold_left = self.climb_out = None
        self._events.append(Disarmed(why))
        return None

    def set_mode(self, mode: Mode) -> Refusal | None:
        if mode is self.mode and mode is not Mode.AUTO:
            return None
        b = self.behaviour
        if (self.armed or b.mode_checks_disarmed) and mode in GPS_MODES and not self.position_ok:
            return Refusal((b.mode_no_position_text,))
        if (b.auto_needs_takeoff_on_ground and mode is Mode.AUTO and self.armed and self.landed
                and not self._starts_with_takeoff()):
            return Refusal(("init failed",), notes=("Auto: Missing Takeoff Cmd",))
        if b.auto_needs_mission and mode is Mode.AUTO and not self.mission_present:
            return Refusal(("No valid mission available",))
        leaving_auto = self.mode is Mode.AUTO and mode is not Mode.AUTO
        if leaving_auto and self.state is MissionState.RUNNING:
            self.state = MissionState.STOPPED  # ModeAuto::exit stops the mission
        if mode in (Mode.TAKEOFF, Mode.GUIDED) and mode is not self.mode:
            self.guided_alt = None
        self.mode = mode
        self.paused = False
        if mode is Mode.AUTO:
            self._start_or_resume()
        return None

    def mission_start(self, first: int = 0, last: int = 0) -> Refusal | None:
        """MAV_CMD_MISSION_START."""
        if not self.behaviour.mission_start_range:
            if first or last:
                return Refusal(("first and last item are not supported",))  # Copter: DENIED
            refusal = self.set_mode(Mode.AUTO) if self.mode is not Mode.AUTO else None
            if refusal is not None:
                return refusal
            self.auto_armed = True  # read only where the behaviour waits for MISSION_START
            if self.state is not MissionState.RUNNING:
                self._start_or_resume()
            return None
        if first > 0 and not self.set_current(first):
            return Refusal((f"no mission item {first}",))
        if self.behaviour.auto_needs_mission and not self.mission_present:
            return Refusal(("No valid mission available",))
        if self.behaviour.mission_start_arms and not self.armed:
            refusal = self.arm()
            if refusal is not None:
                return refusal
        return self.set_mode(Mode.AUTO)

    def pause(self, pause: bool) -> Refusal | None:
        """MAV_CMD_DO_PAUSE_CONTINUE: ArduPilot pauses inside AUTO; PX4 switches to
        AUTO.LOITER and back."""
        if self.behaviour.pause_switches_to_hold:
            return self.set_mode(Mode.HOLD if pause else Mode.AUTO)
        if self.mode is not Mode.AUTO:
            return Refusal(("Failed to pause" if pause else "Failed to resume",))
        self.paused = pause
        return None

    def takeoff(self, alt_m: float) -> Refusal | None:
        if not self.armed:
            return Refusal(("not armed",))
        if not math.isfinite(alt_m) or alt_m <= 0:
            return Refusal(("takeoff altitude must be positive",))
        if self.behaviour.takeoff_switches_mode:
            if not self.position_ok:
                return Refusal((self.behaviour.mode_no_position_text,))
            self.mode = Mode.TAKEOFF
        elif self.mode is not Mode.GUIDED:
            return Refusal(("takeoff needs GUIDED mode",))
        self.guided_alt = float(alt_m)
        return None

    def set_speed(self, speed_mps: float) -> Refusal | None:
        if not math.isfinite(speed_mps) or speed_mps <= 0:
            return Refusal(("speed must be positive",))
        self.speed_mps = float(speed_mps)
        return None

    def set_current(self, seq: int) -> bool:
        """MISSION_SET_CURRENT / MAV_CMD_DO_SET_MISSION_CURRENT; False if refused."""
        if self.behaviour.set_current_to_nav_command:
            # AP_Mission::set_current_cmd: never item 0 (it becomes 1), not with only home.
            if seq >= len(self.mission) or len(self.mission) <= 1 or seq < 0:
                return False
            seq = max(seq, 1)
            if self.state is MissionState.RUNNING:
                self._advance(seq)
                return True
            nav = self._next_nav(seq)
            if nav is None:
                self.current, self.loaded = 0, None
                return False
            self.current, self.loaded = nav, None
            self.hold_left = self.climb_out = None
            if self.state is MissionState.COMPLETE:
                self.state = MissionState.STOPPED
            self._events.append(CurrentChanged(nav))
            return True
        if not 0 <= seq < len(self.mission):
            return False
        self.current, self.loaded = seq, None
        self.hold_left = self.climb_out = None
        if self.state is MissionState.COMPLETE:
            self.state = MissionState.STOPPED
        if self.mode is Mode.AUTO and self.state is MissionState.RUNNING:
            self._load(seq)
        else:
            self._events.append(CurrentChanged(seq))
        return True

    # --- the mission changes ----------------------------------------------------------------
    def set_mission(self, items: list[MissionItem]) -> None:
        """Replace the whole mission at once (as a finished upload does)."""
        if self.behaviour.autopilot.writes_items_as_they_arrive:
            self.mission_changed(items, frozenset(range(len(items))))
        else:
            self.replace_mission(items)

    def mission_changed(self, items: list[MissionItem], written: frozenset[int]) -> None:
        """ArduPilot: the stored mission changed (an item written, or truncated). Copter's
        AUTO compares the next three navigation commands from the current index with what
        it saw last; any write counts as a change even when the content is equal (seen on
        SITL: an identical upload restarts the command and its hold). A change while a
        waypoint is flown restarts the command at the current index, or fails to if that
        index is gone, and the command in progress goes on."""
        self.mission = list(items)
        if self.mode is not Mode.AUTO or self.state is not MissionState.RUNNING:
            return
        window = self._nav_window(self.current)
        # AP_Mission_ChangeDetector compares the stored commands with memcmp, padding
        # included: on SITL every write while there are commands to compare counts as a
        # change (an identical upload restarted the command once per item), while with none
        # left at the index only a different count does (one "failed to restart" per upload).
        changed = window != self._window or (bool(written) and bool(window))
        self._window = window
        if not changed or self.loaded is None or self.loaded.command != NAV_WAYPOINT:
            return
        if 0 < self.current < len(self.mission):
            self._load(self.current)
            self._events.append(MissionRestarted(self.current))
        else:
            self._events.append(MissionRestartFailed(self.current))

    def replace_mission(self, items: list[MissionItem]) -> None:
        """PX4: a whole mission replaced the active one (MissionBase::updateMavlinkMission)."""
        if crc_of(items) == crc_of(self.mission):
            self.mission = list(items)
            return  # same mission: PX4 does not update the active one
        self.mission = list(items)
        marked = next((i for i, item in enumerate(items) if item.current), None)
        self.current = marked if marked is not None else min(max(self.current, 0), max(len(items) - 1, 0))
        if marked is None and items:
            self._events.append(CurrentUnnamed())
        self.loaded = None
        self.hold_left = self.climb_out = None
        if not items:
            self.state = MissionState.STOPPED
            if self.mode is Mode.AUTO:
                self.mode = Mode.HOLD  # no mission to fly: PX4 leaves mission mode
                self._events.append(ModeChangedItself())
            return
        if self.state is MissionState.COMPLETE:
            self.state = MissionState.STOPPED
        if self.mode is Mode.AUTO and self.state is MissionState.RUNNING:
            self._load(self.current)  # reset_triplets + set_mission_items: the item starts now
        else:
            self._events.append(CurrentChanged(self.current))

    # --- mission execution ----------------------------------------------------------------------
    def _nav_window(self, start: int) -> tuple[tuple[int, MissionItem], ...]:
        out: list[tuple[int, MissionItem]] = []
        for i in range(max(start, 0), len(self.mission)):
            if self.mission[i].command in NAV_COMMANDS and i >= self.first_item:
                out.append((i, self.mission[i]))
                if len(out) == CHANGE_WINDOW:
                    break
        return tuple(out)

    def _next_nav(self, start: int) -> int | None:
        window = self._nav_window(start)
        return window[0][0] if window else None

    def _starts_with_takeoff(self) -> bool:
        """AP_Mission::starts_with_takeoff_cmd: from the resume index (MIS_RESTART 0)."""
        start = self.current if self.current > 0 and self.state is MissionState.STOPPED else self.first_item
        nav = self._next_nav(start)
        return nav is not None and self.mission[nav].command == NAV_TAKEOFF

    def _start_or_resume(self) -> None:
        """Entering AUTO (or MISSION_START): ArduPilot resumes at its index (a completed
        mission starts again at item 1); PX4 continues at its current item."""
        self._window = self._nav_window(self.current)
        if self.behaviour.resumes_at_nav_index:
            if self.state is MissionState.COMPLETE or not 0 < self.current < len(self.mission):
                self.state = MissionState.RUNNING
                self._advance(1)
            else:
                self.state = MissionState.RUNNING
                self._load(self.current)
            self._window = self._nav_window(self.current)
            return
        if not self.mission:
            return
        if self.state is MissionState.COMPLETE or self.current >= len(self.mission):
            self.current = 0
        self.state = MissionState.RUNNING
        self._load(self.current)

    def _advance(self, start: int) -> None:
        """Start the first navigation command at or after ``start``, running the commands
        without a position on the way; past the end the mission is complete."""
        i = start
        while i < len(self.mission):
            item = self.mission[i]
            if i < self.first_item:
                i += 1
                continue
            if item.command in NAV_COMMANDS:
                self._load(i)
                return
            self._events.append(CommandStarted(i, COMMAND_NAMES.get(item.command, "Cmd")))
            if item.command == DO_CHANGE_SPEED and item.param2 > 0:
                self.speed_mps = float(item.param2)
            if self.behaviour.do_items_reached:
                self._events.append(ItemComplete(i, item.command))
            i += 1
        self._complete()

    def _load(self, seq: int) -> None:
        self.current = seq
        self.loaded = self.mission[seq]
        self.hold_left = None
        self.climb_out = None
        self._events.append(CommandStarted(seq, COMMAND_NAMES.get(self.loaded.command, "Cmd")))
        self._events.append(CurrentChanged(seq))

    def _complete(self) -> None:
        last = self.current
        self.state = MissionState.COMPLETE
        self.loaded = None
        self._events.append(MissionDone(last))
        if self.landed and self.armed and self.behaviour.disarms_at_mission_end_landed:
            self.disarm(why="landed")  # ModeAuto::exit_mission on the ground

    def _item_done(self, events: list[FlightEvent]) -> None:
        """The loaded command completed: report it and go on with the next item."""
        events.append(ItemComplete(self.current, self.loaded.command if self.loaded is not None else 0))
        self._events_into(events)
        self._advance(self.current + 1)
        self._events_into(events)

    def _events_into(self, events: list[FlightEvent]) -> None:
        events.extend(self._events)
        self._events = []

    # --- restart ------------------------------------------------------------------------------
    def snapshot(self) -> FlightSnapshot:
        """What survives a restart of the vehicle: where it is and what it has spent."""
        return FlightSnapshot(
            flavour=self.flavour, pos=(self.pos[0], self.pos[1], self.pos[2]), home=self.home,
            energy_j=self.energy_j, armed=self.armed, landed=self.landed, mode=self.mode.value,
            time_s=self.time_s, speed_mps=self.speed_mps, flight_j=self.flight_j, hover_j=self.hover_j,
            compute_j=self.compute_j,
        )

    def resume(self, snap: FlightSnapshot) -> None:
        """Come back as after a reboot: at the saved position with the saved battery and
        home, but with the mission lost (the worst case: an autopilot that keeps its mission
        in storage would still hold it) and the clock since boot restarting at 0. In the air
        it is armed and holds position (LOITER / AUTO.LOITER) until told otherwise; on the
        ground it is disarmed. In the air the estimator navigates at once (an aircraft that
        reboots in flight has no time to wait for it); on the ground it starts again."""
        if behaviour_for(snap.flavour) is not self.behaviour:
            raise VehicleError("state_file", f"saved by a {snap.flavour} vehicle, this one is {self.flavour}")
        self.pos = list(snap.pos)
        self.home = snap.home
        self.energy_j = snap.energy_j
        self.landed = snap.landed
        self.armed = snap.armed and not snap.landed
        self.mode = Mode.HOLD if not self.landed else self.behaviour.boot_mode
        self.time_s = self.boot_s = snap.time_s
        self.speed_mps = snap.speed_mps
        self.flight_j, self.hover_j, self.compute_j = snap.flight_j, snap.hover_j, snap.compute_j
        self.vel = (0.0, 0.0, 0.0)
        self.mission, self.failsafe = [], False
        self.state, self.loaded, self.current = MissionState.STOPPED, None, 0
        self.guided_alt = None
        self.hold_left = self.climb_out = None
        self._leg, self._leg_m = None, 0.0
        self._events = []
        if not self.landed:
            self.stage, self.home_set = Stage.NAVIGATING, True
        else:
            self.stage, self.home_set = Stage.NO_GPS, False
            self._update_stage()

    # --- simulation -------------------------------------------------------------------------
    def step(self, dt_s: float) -> list[FlightEvent]:
        """Advance simulated time by ``dt_s`` seconds."""
        events = self.drain()
        remaining = float(dt_s)
        idle = 0
        while remaining > EPS_S:
            self._update_stage()
            self._check_battery()
            used = self._advance_time(min(remaining, MAX_SUBSTEP_S), events)
            self._events_into(events)
            if used <= EPS_S:
                idle += 1
                if idle > MAX_IDLE_SUBSTEPS + len(self.mission):
                    # Only transitions that take no time could repeat; hover the rest.
                    used = remaining
                    self._hover(used)
            else:
                idle = 0
            remaining -= used
            self.time_s += used
        self._update_stage()
        self._events_into(events)
        return events

    def _update_stage(self) -> None:
        stage = stage_at(self.since_boot_s, self.gps_delay_s)
        while self.stage < stage:
            self.stage = Stage(self.stage + 1)
            if self.stage is Stage.GPS:
                self._events.append(GpsFix())
            elif self.stage is Stage.ORIGIN:
                self._events.append(OriginSet())
                if not self.home_set:
                    self._set_home()
            elif self.stage is Stage.NAVIGATING:
                self._events.append(UsingGps())
                if not self.home_set:
                    self._set_home()

    def _set_home(self) -> None:
        self.home = (self.pos[0], self.pos[1], 0.0)
        self.home_set = True
        self._events.append(HomeSet())

    def _check_battery(self) -> None:
        if self.landed or self.failsafe or self.energy_j > self.energy_floor_j:
            return
        self.failsafe = True
        self._events.append(BatteryLow(f"battery at {self.battery_fraction:.0%}: returning"))
        if self.mode not in (Mode.RTL, Mode.LAND):
            if self.mode is Mode.AUTO and self.state is MissionState.RUNNING:
                self.state = MissionState.STOPPED
            self.mode = Mode.RTL
            self._events.append(ModeChangedItself())

    def _advance_time(self, budget: float, events: list[FlightEvent]) -> float:
        if not self.armed and not self.landed:
            return self._fall(budget, events)
        if not self.armed:
            self.vel = (0.0, 0.0, 0.0)
            self._recharge(budget)
            return budget
        used = self._fly(budget, events)
        if self.armed and self.landed and used > 0:
            self.ground_armed_s += used
            if self.disarm_delay_s > 0 and self.ground_armed_s >= self.disarm_delay_s:
                self.disarm(why="auto")
        elif not self.landed:
            self.ground_armed_s = 0.0
        return used

    def _fly(self, budget: float, events: list[FlightEvent]) -> float:
        if self.mode is Mode.AUTO:
            return self._auto(budget, events)
        if self.mode is Mode.RTL:
            return self._return_home(budget, events, in_mission=False)
        if self.mode is Mode.LAND:
            return self._land_here(budget, events, in_mission=False)
        if self.mode in (Mode.GUIDED, Mode.TAKEOFF) and self.guided_alt is not None:
            target = (self.pos[0], self.pos[1], self.guided_alt)
            used, arrived = self._move(target, budget, self.climb_mps)
            if arrived:
                self.guided_alt = None
                if self.mode is Mode.TAKEOFF:
                    self.mode = Mode.HOLD
                    self._events.append(ModeChangedItself())
            return used
        return self._hover(budget)

    def _auto(self, budget: float, events: list[FlightEvent]) -> float:
        if self.state is not MissionState.RUNNING or self.paused:
            return self._hover(budget)  # AUTO with nothing to do: hold where it is
        if self.behaviour.waits_for_mission_start and self.landed and not self.auto_armed:
            return self._hover(budget)  # motors spinning, waiting for MISSION_START
        if self.loaded is None:
            self._advance(self.current if self.current >= self.first_item else self.first_item)
            return 0.0
        item = self.loaded
        if self.behaviour.empty_mission_keeps_command and not self.mission:
            # AP_Mission::update does nothing with an empty mission: the command in progress
            # is flown but never completes.
            if item.command in NAV_COMMANDS and item.frame in GLOBAL_FRAMES and item.command != NAV_RTL:
                used, _ = self._move(self._item_pos(item), budget, self.speed_mps)
                if used > 0:
                    return used
            return self._hover(budget)
        if item.command == NAV_TAKEOFF:
            alt = self._item_pos(item)[2]
            if self.landed:
                alt = max(alt, 1.0)  # a takeoff from the ground climbs at least a metre
            used, arrived = self._move((self.pos[0], self.pos[1], max(alt, self.pos[2])), budget, self.climb_mps)
            if arrived:
                self._item_done(events)
            return used
        if item.command in HOLD_COMMANDS:
            return self._fly_and_hold(item, budget, events)
        if item.command == NAV_DELAY:
            return self._delay(item, budget, events)
        if item.command == NAV_RTL:
            return self._return_home(budget, events, in_mission=True)
        if item.command == NAV_LAND:
            if item.frame in GLOBAL_FRAMES and (item.x or item.y):
                x, y, _ = self._item_pos(item)
                if abs(x - self.pos[0]) > 1e-6 or abs(y - self.pos[1]) > 1e-6:
                    return self._move((x, y, self.pos[2]), budget, self.speed_mps)[0]
            return self._land_here(budget, events, in_mission=True)
        self._item_done(events)
        return 0.0

    def _fly_and_hold(self, item: MissionItem, budget: float, events: list[FlightEvent]) -> float:
        target = self._item_pos(item)
        if self.hold_left is None:
            if self.landed and self.climb_out is None:
                # PX4's implicit takeoff (an ArduPilot mission must start with a takeoff
                # item to leave the ground in AUTO): straight up to the point's height, at
                # least MIS_TAKEOFF_ALT, then across.
                self.climb_out = max(target[2], PX4_TAKEOFF_MIN_M)
            if self.climb_out is not None:
                used, arrived = self._move((self.pos[0], self.pos[1], self.climb_out), budget, self.climb_mps)
                if arrived:
                    self.climb_out = None
                return used
            used, arrived = self._move(target, budget, self.speed_mps)
            if arrived:
                self.hold_left = max(0.0, float(item.param1)) if math.isfinite(item.param1) else 0.0
            return used
        return self._hold(budget, events)

    def _delay(self, item: MissionItem, budget: float, events: list[FlightEvent]) -> float:
        """MAV_CMD_NAV_DELAY (MAVSDK's loiter time): wait param1 seconds where it is; the
        time-of-day form (param1 = -1) is not simulated and completes at once."""
        if self.hold_left is None:
            self.hold_left = max(0.0, float(item.param1)) if math.isfinite(item.param1) else 0.0
        return self._hold(budget, events)

    def _hold(self, budget: float, events: list[FlightEvent]) -> float:
        """Hover (computing the user's tasks) for what is left of the hold, then complete
        the item; returns the simulated seconds used."""
        if self.hold_left is not None and self.hold_left > EPS_S:
            used = min(budget, self.hold_left)
            self._hover(used, computing=True)
            self.hold_left -= used
            return used
        self._item_done(events)
        return 0.0

    def _return_home(self, budget: float, events: list[FlightEvent], in_mission: bool) -> float:
        if self.landed:
            return self._touchdown(events, in_mission) if self.armed else budget
        hx, hy, _ = self.home
        cruise = max(self.pos[2], self.rtl_min_alt_m)
        if not self._near_xy(self.home):
            if self.pos[2] < cruise - 1e-6:
                return self._move((self.pos[0], self.pos[1], cruise), budget, self.climb_mps)[0]
            return self._move((hx, hy, self.pos[2]), budget, self.speed_mps)[0]
        return self._land_here(budget, events, in_mission)

    def _land_here(self, budget: float, events: list[FlightEvent], in_mission: bool) -> float:
        if self.landed:
            return self._touchdown(events, in_mission) if self.armed else budget
        used, arrived = self._move((self.pos[0], self.pos[1], 0.0), budget, self.climb_mps)
        if arrived:
            self._touchdown(events, in_mission)
        return used

    def _fall(self, budget: float, events: list[FlightEvent]) -> float:
        """Disarmed in the air (a pilot's forced disarming, a motor kill): the motors stop
        and the vehicle falls straight down, using no energy, until it hits the ground."""
        step = min(self.pos[2], FALL_MPS * budget)
        self.pos = [self.pos[0], self.pos[1], self.pos[2] - step]
        self.vel = (0.0, 0.0, -FALL_MPS)
        if self.pos[2] <= 0.0:
            self.pos[2] = 0.0
            self._touchdown(events, in_mission=False)
        return step / FALL_MPS if step > 0 else budget

    def _touchdown(self, events: list[FlightEvent], in_mission: bool) -> float:
        self.landed = True
        self.vel = (0.0, 0.0, 0.0)
        events.append(TouchedDown())
        if in_mission:
            events.append(ItemComplete(self.current, self.loaded.command if self.loaded is not None else 0))
            self.state = MissionState.COMPLETE
            self.loaded = None
            events.append(MissionDone(self.current))
        if self.armed:
            self.disarm(why="landed")
        self._events_into(events)
        return 0.0

    def _recharge(self, dt: float) -> None:
        """The battery swap: full again once on the ground and disarmed for ``recharge_s``."""
        if self.recharge_s is None or not self.landed or self.energy_j >= self.scenario.battery_j:
            self.ground_s = 0.0
            return
        self.ground_s += dt
        if self.ground_s + EPS_S < self.recharge_s:
            return
        self.energy_j = float(self.scenario.battery_j)
        self.failsafe = False
        self.ground_s = 0.0
        self.swaps += 1
        self._events.append(BatterySwapped(f"battery swapped (swap {self.swaps})"))

    def _near_xy(self, target: tuple[float, float, float]) -> bool:
        return math.hypot(target[0] - self.pos[0], target[1] - self.pos[1]) < 1e-6

    def _item_pos(self, item: MissionItem) -> tuple[float, float, float]:
        return item_local(item, self.origin)

    def _move(self, target: tuple[float, float, float], budget: float, speed: float) -> tuple[float, bool]:
        """Fly straight towards ``target`` for at most ``budget`` s: (time used, arrived)."""
        dx, dy, dz = (target[i] - self.pos[i] for i in range(3))
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if dist < 1e-6:
            self.pos = [target[0], target[1], target[2]]
            return 0.0, True
        if self._leg != target:
            self._leg, self._leg_m = target, 0.0
        step = min(dist, speed * budget)
        f = step / dist
        self.pos = [self.pos[0] + dx * f, self.pos[1] + dy * f, max(0.0, self.pos[2] + dz * f)]
        used = step / speed
        self.vel = (dx / dist * speed, dy / dist * speed, dz / dist * speed)
        energy = flight_energy_j(self.p, self._leg_m + step) - flight_energy_j(self.p, self._leg_m)
        self._leg_m += step
        self._drain(energy, "flight")
        if self.landed and self.pos[2] > GROUND_M:
            self.landed = False
        arrived = step >= dist - 1e-9
        if arrived:
            self.pos = [target[0], target[1], target[2]]
            self.vel = (0.0, 0.0, 0.0)
        return used, arrived

    def _hover(self, dt: float, computing: bool = False) -> float:
        self.vel = (0.0, 0.0, 0.0)
        if self.landed:
            return dt
        self._drain(self.scenario.hover_power_w * dt, "hover")
        if computing:
            below = np.array([self.pos[0], self.pos[1], 0.0])
            here = np.array(self.pos, dtype=np.float64)
            rate = upload_rate_bps(self.p, channel_gain(self.p, here, below))
            self._drain(computation_energy_j(self.p, rate * dt), "compute")  # (6)
        return dt

    def _drain(self, energy_j: float, kind: str) -> None:
        self.energy_j = max(0.0, self.energy_j - energy_j)
        if kind == "flight":
            self.flight_j += energy_j
        elif kind == "hover":
            self.hover_j += energy_j
        else:
            self.compute_j += energy_j
