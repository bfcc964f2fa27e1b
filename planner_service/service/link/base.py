"""What the service needs of an autopilot link, whichever library speaks MAVLink.

A backend keeps ``telemetry`` (the latest snapshot, ``telemetry.Telemetry``) current and
reports typed events (``events.LinkEvent``) through the ``on_event`` callable it is given
(called on the event loop's thread); the service awaits ``upload``, ``set_current``,
``start``, ``resume`` and ``return_to_launch``, each of which raises ``LinkError`` saying
what was attempted and what the autopilot answered (with its STATUSTEXT where it said why).

Both backends share ``state.VehicleState`` (trust, telemetry, the judgements) and
``streams`` (the telemetry they ask for); they differ in how bytes and missions move.
"""

from __future__ import annotations

import abc
import asyncio
import logging
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence, TypeVar

from pymavlink.dialects.v20 import ardupilotmega as M

from protocol import MissionItem
from protocol.autopilot import autopilot_for
from protocol.mission import Flavour

from ..errors import LinkError
from .asked import Asked
from .events import LinkEvent
from .modes import HOLDING_MODES, MISSION_MODES, RETURNING_MODES, mode_name, mode_number
from .state import VehicleState
from .telemetry import ClockRate, Telemetry

__all__ = ["ClockRate", "HOLDING_MODES", "LinkSettings", "MISSION_MODES", "RETURNING_MODES", "Telemetry",
           "VehicleLink", "mode_name"]

log = logging.getLogger(__name__)
T = TypeVar("T")
CURRENT_WAIT_S = 2.0
"""Wall seconds to wait for a MISSION_CURRENT after an upload or a set_current (the link
asks for it at 2 Hz of vehicle time) before asking again."""

ARMED_SEEN_S = 3.0
"""Wall seconds an accepted arming waits for the heartbeat showing it (1 Hz at speed 1)."""

Proceed = Callable[[], "str | None"]
"""Asked between the steps of a command: None to go on, else why to stop."""


def _always() -> str | None:
    return None


def _go_on(proceed: Proceed, operation: str) -> None:
    """``LinkError`` naming ``operation`` and why, if ``proceed`` gives a reason to stop."""
    why = proceed()
    if why is not None:
        raise LinkError(operation, f"stopped between its steps: {why}")


@dataclass
class LinkSettings:
    """What every backend needs (from ``MavlinkConfig``)."""

    url: str
    flavour: Flavour
    item_timeout_s: float = 0.5
    retries: int = 10
    link_timeout_s: float = 3.0
    source_system: int = 255
    source_component: int = 190
    extra: dict = field(default_factory=dict)
    signing_key_file: str = ""
    """Sign with the key in this file (pymavlink backend; empty: no signing)."""
    signing_timestamp_file: str = ""
    """The signing timestamp's file (empty: beside the key)."""


class VehicleLink(abc.ABC):
    """One autopilot, one library."""

    def __init__(self, settings: LinkSettings, on_event: Callable[[LinkEvent], None]) -> None:
        self.settings = settings
        self.on_event = on_event
        self.profile = autopilot_for(settings.flavour)
        """The autopilot's conventions (``protocol.autopilot``), from the configured name."""
        self.state = VehicleState(self.profile, self._emit, link_timeout_s=settings.link_timeout_s)
        self.generation = 0
        """Which mission the vehicle holds, as far as this link knows (see ``events``)."""
        self.mission_id = 0
        """The autopilot's id of the mission it took from our last upload or gave in our
        last download (MISSION_ACK's or MISSION_COUNT's ``opaque_id``, PX4: a CRC32 of the
        items), the id its MISSION_CURRENT names that mission by; 0: not said."""
        self._current: tuple[int, int] | None = None
        """(generation, seq) of the latest MISSION_CURRENT about the mission held."""
        self._current_moved = asyncio.Event()
        """Set by the backend on each MISSION_CURRENT it records in ``_current``."""

    async def _wait_current(self, timeout_s: float, want: int | None = None) -> int | None:
        """The vehicle's current item of the mission held, as its next MISSION_CURRENT (or
        the latest already heard of this generation, unless ``want`` is not it yet) says
        within ``timeout_s``; None when none came."""
        deadline = time.monotonic() + timeout_s
        while True:
            seen = self._current
            if seen is not None and seen[0] == self.generation and (want is None or seen[1] == want):
                return seen[1]
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return seen[1] if seen is not None and seen[0] == self.generation else None
            self._current_moved.clear()
            try:
                await asyncio.wait_for(self._current_moved.wait(), remaining)
            except TimeoutError:
                pass

    def _emit(self, event: LinkEvent) -> None:
        self.on_event(event)

    @property
    def telemetry(self) -> Telemetry:
        return self.state.telemetry

    @abc.abstractmethod
    async def connect(self, timeout_s: float) -> None:
        """Open the link and wait for the autopilot's first heartbeat (``LinkError`` after
        ``timeout_s``); afterwards the backend keeps reconnecting on its own and asks for
        the telemetry it needs on every (re)connection."""

    @abc.abstractmethod
    async def upload(self, items: Sequence[MissionItem], *, current_seq: int | None = None,
                     restart_current: bool = False) -> None:
        """Upload a whole mission with the protocol's retries. When this returns the
        autopilot holds it (``generation`` has grown) and, with ``current_seq``, flies that
        item (confirmed from its MISSION_CURRENT; set with MAV_CMD_DO_SET_MISSION_CURRENT,
        or MISSION_SET_CURRENT where refused, when it reported another; with
        ``restart_current`` also when it flies that index already, so that the index's new
        content is flown: ArduPilot restarts no return, takeoff or land item on an upload,
        and a new point put where the return was would never be flown). When it raises
        ``LinkError`` the autopilot kept its old mission, unless the error's
        ``outcome_unknown`` says that could not be found out, or the error is about the
        current item (``operation`` "set_current()"): then the new mission is held but the
        vehicle flies another item."""

    @abc.abstractmethod
    async def set_current(self, seq: int) -> None:
        """Make the vehicle fly item ``seq`` of the mission it holds now (ends a hold
        early), confirmed from MISSION_CURRENT, or ``LinkError``."""

    @abc.abstractmethod
    async def download(self) -> list[MissionItem]:
        """The mission the autopilot holds (``generation`` grows: later reports are about
        it)."""

    async def start(self, proceed: Proceed = _always) -> None:
        """Arm and fly the mission from its start (the operator allowed it). Only with a
        position (``telemetry.position_ok``); a refused arm or mode change leaves the
        vehicle disarmed (disarmed again if it was armed and is still on the ground) and
        raises ``LinkError`` naming the autopilot's refusal. ``proceed`` is asked before each
        step after the first: a reason from it stops the start where it is, nothing more
        sent (the service's authority ended meanwhile: the vehicle is someone else's)."""
        t = self.telemetry
        self._check_link("start()")
        if not t.position_ok:
            raise LinkError("start()", f"no position: waiting for {t.waiting_for}")
        armed_here, was_armed = False, t.armed  # a vehicle someone else armed is left to them
        try:
            if self.profile.arm_mode is not None and t.mode != self.profile.arm_mode:
                await self._set_mode(self.profile.arm_mode)  # ArduCopter refuses to arm in AUTO
                _go_on(proceed, "start()")
            disarms = self.state.disarms
            await self._arm(True)
            armed_here, armed_at = True, time.monotonic()
            await self._armed_seen("start()")
            await self._resume(proceed, "start()", disarms, armed_at)
        except LinkError as err:
            if (armed_here or self.telemetry.armed) and not was_armed and proceed() is None:
                await self._disarm_on_ground(err)
            raise

    async def _armed_seen(self, operation: str) -> None:
        """Wait for the heartbeat showing the arming the autopilot accepted: the steps after
        it check that the vehicle is still armed (PX4's MISSION_START would arm it again)."""
        deadline = time.monotonic() + ARMED_SEEN_S
        while not self.telemetry.armed:
            if time.monotonic() > deadline:
                raise LinkError(operation, f"the arming was accepted but no heartbeat showed it within "
                                           f"{ARMED_SEEN_S:g} s")
            await asyncio.sleep(0.02)

    async def _disarm_on_ground(self, why: LinkError) -> None:
        """A start that failed after arming must not leave motors armed on the ground."""
        if self.telemetry.airborne:
            return
        try:
            await self._arm(False)
            log.warning("start failed (%s): disarmed again", why)
        except LinkError as err:
            log.error("start failed (%s) and disarming failed too: %s", why, err)

    @abc.abstractmethod
    async def command(self, command: int, *params: float, what: str) -> None:
        """A COMMAND_LONG that must be accepted: ``LinkError`` names the result and what
        the autopilot said about it."""

    @abc.abstractmethod
    def _check_link(self, operation: str) -> None:
        """``LinkError`` naming ``operation`` unless the autopilot is connected."""

    async def _asked(self, asked: Asked[T], value: T, command: int, *params: float, what: str) -> None:
        """A command whose effect the heartbeat shows (a mode, an arming): a change to
        ``value`` shown while it is in flight, or soon after its answer, was commanded
        (``ModeChanged``, ``ArmedChanged``). A refusal ends that at once; no answer does
        not (the autopilot may have done it)."""
        asked.ask(value)
        refused = False
        try:
            await self.command(command, *params, what=what)
        except LinkError as err:
            refused = not err.result.startswith("NO_ANSWER")
            raise
        finally:
            asked.answered(self.state.clock(), refused=refused)

    async def _set_mode(self, name: str) -> None:
        main, sub = mode_number(self.profile, name)
        await self._asked(self.state.mode_asked, name, M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                          main, sub, what=f"set_mode({name})")

    async def _arm(self, armed: bool) -> None:
        await self._asked(self.state.arming_asked, armed, M.MAV_CMD_COMPONENT_ARM_DISARM, 1 if armed else 0,
                          what="arm()" if armed else "disarm()")

    async def resume(self, proceed: Proceed = _always) -> None:
        """Fly the mission held from its current item again, already armed and airborne
        (mode AUTO / AUTO.MISSION and MISSION_START): after the autopilot restarted in the
        air. ``proceed`` as for ``start``."""
        self._check_link("resume()")
        await self._resume(proceed, "resume()", self.state.disarms)

    async def _resume(self, proceed: Proceed, operation: str, disarms: int, armed_at: float | None = None) -> None:
        _go_on(proceed, operation)
        await self._set_mode(self.profile.mission_mode)
        _go_on(proceed, operation)
        if self.state.disarms != disarms or not self.telemetry.armed:
            # PX4's MISSION_START arms a disarmed vehicle by itself: after the autopilot's
            # own disarming (PX4's preflight disarm, ArduCopter's DISARM_DELAY) nothing the
            # operator allowed is left to start. How long the steps took says which it was.
            since = "" if armed_at is None else f", {time.monotonic() - armed_at:.1f} s after the arming"
            raise LinkError(operation, f"the vehicle was disarmed meanwhile (the autopilot's own disarming, or "
                                       f"someone's{since}): the mission is not started")
        await self.command(M.MAV_CMD_MISSION_START, 0, 0, what="start_mission()")

    async def return_to_launch(self) -> None:
        """Command return to launch now."""
        await self._asked(self.state.mode_asked, self.profile.return_mode, M.MAV_CMD_NAV_RETURN_TO_LAUNCH,
                          what="return_to_launch()")

    async def hold(self) -> None:
        """Hold position where the vehicle is (LOITER, PX4's AUTO.LOITER): the operator's hold."""
        self._check_link("hold()")
        await self._set_mode(self.profile.hold_mode)

    @abc.abstractmethod
    async def close(self) -> None:
        """Stop every thread and socket of the link."""
