"""The simulated aircraft: flies a mission in simulated time and drains its battery with the
project's energy model. Pure: no sockets, no clock; ``step(dt)`` advances time and returns
what happened.

Energy (planner_service.model.energy, the same functions the planner's playouts use):
- flight: each straight leg costs ``flight_energy_j(p, distance)``, charged as the distance
  grows, so a leg flown in many steps costs exactly what the model charges for one hop;
  climbs and descents are legs too (the model has no separate climb power);
- hovering: ``hover_power_w`` per second whenever airborne and not moving (holding at a
  waypoint or loitering);
- computation (6): while holding at a waypoint the UAV computes what the user below uploads,
  ``computation_energy_j(p, rate * dt)`` with the rate of a user straight below (the
  vehicle does not know the user's exact position; straight below is the channel the
  hold time was planned for).
When the battery reaches ``battery_threshold * battery_j`` in the air the aircraft returns
to launch, as an autopilot's battery failsafe does.

Battery swap (``recharge_s``): ``recharge_s`` simulated seconds after the aircraft is on
the ground and disarmed, its battery is full again (a crew swapped or charged it) and the
failsafe is cleared, so it can fly the next sortie. Arming restarts the wait; None: never.
"""

from __future__ import annotations

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

from .errors import VehicleError
from .modes import Mode

NAV_LOITER_TIME = 19
NAV_DELAY = 93
HOLD_COMMANDS = frozenset({NAV_WAYPOINT, NAV_LOITER_TIME})
GROUND_M = 0.05
"""Below this height (m) the aircraft counts as on the ground."""
EPS_S = 1e-9
MAX_SUBSTEPS = 10_000
MAX_SUBSTEP_S = 1.0
"""The battery failsafe is checked at least this often (simulated seconds): the battery
ends at most one sub-step's drain below the threshold when the aircraft turns home."""


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


@dataclass(frozen=True)
class FlightEvent:
    """Something the link reports: ``kind`` is one of reached, current, mode, landed,
    disarmed, battery_low, battery_swapped, mission_done; ``seq`` the mission item when it
    applies."""

    kind: str
    seq: int = -1
    text: str = ""


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

    def __post_init__(self) -> None:
        self.p = pack(self.scenario)
        self.home = (float(self.scenario.base_x_m), float(self.scenario.base_y_m), 0.0)
        self.pos = list(self.home)
        self.vel = (0.0, 0.0, 0.0)
        self.armed = False
        self.landed = True
        self.mode = Mode.MANUAL if self.flavour == "ardupilot" else Mode.HOLD
        self.mission: list[MissionItem] = []
        self.current = 0
        self.started = False
        self.hold_left: float | None = None
        self.energy_j = float(self.scenario.battery_j)
        self.time_s = 0.0
        self.boot_s = 0.0
        """Simulated time of the last (re)start: ``time_boot_ms`` counts from here."""
        self.speed_mps = float(self.scenario.speed_mps)
        self.guided_alt: float | None = None
        self.climb_out: float | None = None
        self.failsafe = False
        self._leg: tuple[float, float, float] | None = None
        self._leg_m = 0.0
        self.flight_j = 0.0
        self.hover_j = 0.0
        self.compute_j = 0.0
        self.ground_s = 0.0
        """Simulated seconds on the ground and disarmed since the battery was last used."""
        self.swaps = 0
        if self.recharge_s is not None and not (math.isfinite(self.recharge_s) and self.recharge_s >= 0):
            raise VehicleError("recharge_s", f"must be a finite number of seconds >= 0, got {self.recharge_s}")
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
        """ArduPilot's item 0 is home and never flown."""
        return 1 if self.flavour == "ardupilot" and len(self.mission) > 1 else 0

    @property
    def since_boot_s(self) -> float:
        """Simulated seconds since the vehicle (re)started: its MAVLink clock."""
        return self.time_s - self.boot_s

    @property
    def mission_done(self) -> bool:
        return self.started and self.current >= len(self.mission)

    # --- commands -------------------------------------------------------------------------
    def arm(self) -> str | None:
        """Arm; a reason string if refused."""
        if self.energy_j <= self.energy_floor_j:
            return "battery below the return threshold"
        self.armed = True
        self.ground_s = 0.0
        return None

    def disarm(self, force: bool = False) -> str | None:
        if not self.landed and not force:
            return "cannot disarm in the air"
        self.armed = False
        self.vel = (0.0, 0.0, 0.0)
        return None

    def set_mode(self, mode: Mode) -> str | None:
        if mode is Mode.AUTO:
            if not self._has_nav_items():
                return "no mission to fly"
            if self.current >= len(self.mission) or self.current < self.first_item:
                self._go_to_item(self.first_item)
            self.started = True
        if mode in (Mode.TAKEOFF, Mode.GUIDED) and mode is not self.mode:
            self.guided_alt = None
        self.mode = mode
        return None

    def takeoff(self, alt_m: float) -> str | None:
        if not self.armed:
            return "not armed"
        if not math.isfinite(alt_m) or alt_m <= 0:
            return "takeoff altitude must be positive"
        if self.flavour == "px4":
            self.mode = Mode.TAKEOFF
        elif self.mode is not Mode.GUIDED:
            return "takeoff needs GUIDED mode"
        self.guided_alt = float(alt_m)
        return None

    def set_speed(self, speed_mps: float) -> str | None:
        if not math.isfinite(speed_mps) or speed_mps <= 0:
            return "speed must be positive"
        self.speed_mps = float(speed_mps)
        return None

    def set_current(self, seq: int) -> bool:
        if not 0 <= seq < len(self.mission):
            return False
        self._go_to_item(seq)
        return True

    def set_mission(self, items: list[MissionItem]) -> None:
        """Replace the mission. In the air in AUTO the new mission is flown from its start
        (a re-plan holds the rest of the plan); with nothing to fly the aircraft holds."""
        self.mission = list(items)
        self.started = False
        self._go_to_item(self.first_item)
        if self.mode is Mode.AUTO:
            if self._has_nav_items():
                self.started = True
            else:
                self.mode = Mode.HOLD

    def _has_nav_items(self) -> bool:
        return any(item.command in HOLD_COMMANDS | {NAV_TAKEOFF, NAV_LAND, NAV_RTL, NAV_DELAY}
                   for item in self.mission[self.first_item:])

    def _go_to_item(self, seq: int) -> None:
        self.current = seq
        self.hold_left = None
        self.climb_out = None

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
        ground it is disarmed."""
        if snap.flavour != self.flavour:
            raise VehicleError("state_file", f"saved by a {snap.flavour} vehicle, this one is {self.flavour}")
        self.pos = list(snap.pos)
        self.home = snap.home
        self.energy_j = snap.energy_j
        self.landed = snap.landed
        self.armed = snap.armed and not snap.landed
        self.mode = Mode.HOLD if not self.landed else (Mode.MANUAL if self.flavour == "ardupilot" else Mode.HOLD)
        self.time_s = self.boot_s = snap.time_s
        self.speed_mps = snap.speed_mps
        self.flight_j, self.hover_j, self.compute_j = snap.flight_j, snap.hover_j, snap.compute_j
        self.vel = (0.0, 0.0, 0.0)
        self.mission, self.started, self.failsafe = [], False, False
        self.guided_alt = None
        self._go_to_item(0)
        self._leg, self._leg_m = None, 0.0

    # --- simulation -------------------------------------------------------------------------
    def step(self, dt_s: float) -> list[FlightEvent]:
        """Advance simulated time by ``dt_s`` seconds."""
        events: list[FlightEvent] = []
        remaining = float(dt_s)
        for _ in range(MAX_SUBSTEPS):
            if remaining <= EPS_S:
                break
            self._check_battery(events)
            used = self._advance(min(remaining, MAX_SUBSTEP_S), events)
            remaining -= used
            self.time_s += used
        else:
            # Only zero-time transitions could loop; skip the rest of this step.
            self.time_s += remaining
        return events

    def _check_battery(self, events: list[FlightEvent]) -> None:
        if self.landed or self.failsafe or self.energy_j > self.energy_floor_j:
            return
        self.failsafe = True
        events.append(FlightEvent("battery_low", text=f"battery at {self.battery_fraction:.0%}: returning"))
        if self.mode not in (Mode.RTL, Mode.LAND):
            self.mode = Mode.RTL
            events.append(FlightEvent("mode"))

    def _advance(self, budget: float, events: list[FlightEvent]) -> float:
        if not self.armed:
            self.vel = (0.0, 0.0, 0.0)
            self._recharge(budget, events)
            return budget
        if self.mode is Mode.AUTO and self.started:
            return self._auto(budget, events)
        if self.mode is Mode.RTL:
            return self._return_home(budget, events, seq=-1)
        if self.mode is Mode.LAND:
            return self._land_here(budget, events, seq=-1)
        if self.mode in (Mode.GUIDED, Mode.TAKEOFF) and self.guided_alt is not None:
            target = (self.pos[0], self.pos[1], self.guided_alt)
            used, arrived = self._move(target, budget, self.climb_mps)
            if arrived:
                self.guided_alt = None
                if self.mode is Mode.TAKEOFF:
                    self.mode = Mode.HOLD
                    events.append(FlightEvent("mode"))
            return used
        return self._hover(budget)

    def _auto(self, budget: float, events: list[FlightEvent]) -> float:
        if self.current >= len(self.mission):
            return self._hover(budget)
        item = self.mission[self.current]
        seq = self.current
        if item.command == NAV_TAKEOFF:
            target = (self.pos[0], self.pos[1], max(self._item_pos(item)[2], self.pos[2]))
            used, arrived = self._move(target, budget, self.climb_mps)
            if arrived:
                self._reached(events)
            return used
        if item.command in HOLD_COMMANDS:
            return self._fly_and_hold(item, budget, events)
        if item.command == NAV_DELAY:
            return self._delay(item, budget, events)
        if item.command == NAV_RTL:
            return self._return_home(budget, events, seq=seq)
        if item.command == NAV_LAND:
            if item.frame in GLOBAL_FRAMES and (item.x or item.y):
                x, y, _ = self._item_pos(item)
                if abs(x - self.pos[0]) > 1e-6 or abs(y - self.pos[1]) > 1e-6:
                    return self._move((x, y, self.pos[2]), budget, self.speed_mps)[0]
            return self._land_here(budget, events, seq=seq)
        if item.command == DO_CHANGE_SPEED and item.param2 > 0:
            self.speed_mps = float(item.param2)
        # Commands without a position (camera, gimbal, speed) complete at once.
        self._reached(events)
        return 0.0

    def _fly_and_hold(self, item: MissionItem, budget: float, events: list[FlightEvent]) -> float:
        target = self._item_pos(item)
        if self.hold_left is None:
            if self.landed and self.climb_out is None:
                # The implicit takeoff PX4 performs (ArduPilot needs a takeoff item; the
                # stub is lenient): climb over the launch point first.
                self.climb_out = target[2]
            if self.climb_out is not None:
                used, arrived = self._move((self.pos[0], self.pos[1], self.climb_out), budget, self.climb_mps)
                if arrived:
                    self.climb_out = None
                return used
            used, arrived = self._move(target, budget, self.speed_mps)
            if arrived:
                self.hold_left = max(0.0, float(item.param1))
            return used
        return self._hold(budget, events)

    def _delay(self, item: MissionItem, budget: float, events: list[FlightEvent]) -> float:
        """MAV_CMD_NAV_DELAY (MAVSDK's loiter time): wait param1 seconds where it is; the
        time-of-day form (param1 = -1) is not simulated and completes at once."""
        if self.hold_left is None:
            self.hold_left = max(0.0, float(item.param1)) if math.isfinite(item.param1) else 0.0
        return self._hold(budget, events)

    def _hold(self, budget: float, events: list[FlightEvent]) -> float:
        """Hover (computing the user's tasks) for what is left of the hold, then mark the
        item reached; returns the simulated seconds used."""
        if self.hold_left is not None and self.hold_left > EPS_S:
            used = min(budget, self.hold_left)
            self._hover(used, computing=True)
            self.hold_left -= used
            return used
        self._reached(events)
        return 0.0

    def _reached(self, events: list[FlightEvent]) -> None:
        events.append(FlightEvent("reached", seq=self.current))
        self._go_to_item(self.current + 1)
        if self.current >= len(self.mission):
            events.append(FlightEvent("mission_done", seq=self.current - 1))
        else:
            events.append(FlightEvent("current", seq=self.current))

    def _return_home(self, budget: float, events: list[FlightEvent], seq: int) -> float:
        if self.landed:
            return self._touchdown(events, seq) if self.armed else budget
        hx, hy, _ = self.home
        cruise = max(self.pos[2], self.rtl_min_alt_m)
        if not self._near_xy(self.home):
            if self.pos[2] < cruise - 1e-6:
                return self._move((self.pos[0], self.pos[1], cruise), budget, self.climb_mps)[0]
            return self._move((hx, hy, self.pos[2]), budget, self.speed_mps)[0]
        return self._land_here(budget, events, seq)

    def _land_here(self, budget: float, events: list[FlightEvent], seq: int) -> float:
        if self.landed:
            return self._touchdown(events, seq) if self.armed else budget
        used, arrived = self._move((self.pos[0], self.pos[1], 0.0), budget, self.climb_mps)
        if arrived:
            self._touchdown(events, seq)
        return used

    def _touchdown(self, events: list[FlightEvent], seq: int) -> float:
        self.landed = True
        self.vel = (0.0, 0.0, 0.0)
        events.append(FlightEvent("landed"))
        if seq >= 0:
            self._reached(events)
        self.armed = False
        events.append(FlightEvent("disarmed"))
        return 0.0

    def _recharge(self, dt: float, events: list[FlightEvent]) -> None:
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
        events.append(FlightEvent("battery_swapped", text=f"battery swapped (swap {self.swaps})"))

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
