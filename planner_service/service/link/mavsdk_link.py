"""The MAVSDK backend: the native mavsdk 4 binding (no mavsdk_server), asyncio API.

Missions go through ``mission_raw`` (MISSION_ITEM_INT as the protocol encodes them): the
``mission`` plugin is written for PX4 and loses the first waypoint to ArduPilot's home
item. Progress comes from mission_raw's progress stream: the current item moving from c
to c' means items c .. c'-1 were completed. MAVSDK's coloured log lines are routed to the
``mavsdk`` logger (stderr) instead of stdout.

Which mission a report is about: ``generation`` grows after each accepted upload or
download (MAVSDK hides the packets, so a progress report delayed past an upload cannot be
told apart; the progress baseline below guards against most). A vehicle restart shows as
the attitude's timestamp going back: a "restarted" event. MAVSDK itself reconnects to the
restarted vehicle on its own (same system id); the service then uploads and resumes.

Battery: MAVSDK reports the remaining percentage (1 % steps) but no energy consumed, so the
battery in joules is that fraction of the scenario's pack (the planner's margin covers the
step). Vehicle time (for the clock rate) comes from the attitude's timestamp.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from typing import Any, AsyncIterator, Callable, Sequence

from mavsdk import log_subscribe
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.action import ActionError
from mavsdk.plugins.mission_raw import MissionItem as RawItem
from mavsdk.plugins.mission_raw import MissionRawError, MissionRawResult

from protocol import MissionItem

from ..errors import LinkError
from .base import ClockRate, LinkEvent, LinkSettings, Telemetry, VehicleLink

_log = logging.getLogger("mavsdk")
RESTART_SLACK_S = 2.0
"""Wall seconds (times the clock rate) the vehicle's clock must go back to count as a restart."""
RETRYABLE = {MissionRawResult.BUSY, MissionRawResult.TIMEOUT, MissionRawResult.ERROR}


def _to_logging(level: Any, message: str, file: str | None, line: int) -> bool:
    _log.debug("%s %s", getattr(level, "name", level), message)
    return True  # True: MAVSDK does not print it to stdout


log_subscribe(_to_logging)


def mavsdk_url(url: str) -> str:
    """pymavlink's connection strings in MAVSDK's form (udpout:H:P -> udpout://H:P)."""
    if "://" in url:
        return url
    scheme, _, rest = url.partition(":")
    if scheme in ("udpout", "udpin"):
        return f"{scheme}://{rest}"
    if scheme == "udp":
        return f"udpin://{rest}"
    if scheme == "tcp":
        return f"tcpout://{rest}"
    if scheme == "tcpin":
        return f"tcpin://{rest}"
    device, _, baud = url.partition(",")
    return f"serial://{device}:{baud or 57600}"


def _name(result: Any) -> str:
    return str(getattr(result, "name", result))


def mission_item(raw: RawItem) -> MissionItem:
    return MissionItem(seq=raw.seq, frame=raw.frame, command=raw.command, current=raw.current,
                       autocontinue=raw.autocontinue, param1=raw.param1, param2=raw.param2, param3=raw.param3,
                       param4=raw.param4, x=raw.x, y=raw.y, z=raw.z, mission_type=raw.mission_type)


def raw_item(item: MissionItem) -> RawItem:
    return RawItem(seq=item.seq, frame=item.frame, command=item.command, current=item.current,
                   autocontinue=item.autocontinue, param1=item.param1, param2=item.param2, param3=item.param3,
                   param4=item.param4, x=item.x, y=item.y, z=item.z, mission_type=item.mission_type)


class MavsdkLink(VehicleLink):
    def __init__(self, settings: LinkSettings, on_event: Callable[[LinkEvent], None]) -> None:
        super().__init__(settings, on_event)
        self._sdk: Any = None
        self._tasks: list[asyncio.Task[None]] = []
        self._clock_rate = ClockRate()
        self._progress: tuple[int, int] | None = None  # (current, total) baseline
        self._expect_total: int | None = None
        self._heard = 0.0
        self._lost = False
        self._boot_s: float | None = None
        self._upload_lock = asyncio.Lock()

    async def connect(self, timeout_s: float) -> None:
        self._sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        url = mavsdk_url(self.settings.url)
        await self._sdk.add_any_connection(url)
        system = await self._sdk.first_autopilot(timeout_s=timeout_s)
        if system is None:
            raise LinkError("connect", f"no autopilot at {url} within {timeout_s:g} s")
        self._raw = MissionRawAsync(system)
        self._action = ActionAsync(system)
        tel = TelemetryAsync(system)
        self._heard = time.monotonic()
        self._set(connected=True)
        streams: list[tuple[Callable[[], AsyncIterator[Any]], Callable[[Any], None]]] = [
            (tel.subscribe_position, self._on_position), (tel.subscribe_battery, self._on_battery),
            (tel.subscribe_armed, lambda v: self._set(armed=bool(v))), (tel.subscribe_in_air, self._on_in_air),
            (tel.subscribe_flight_mode, self._on_mode), (tel.subscribe_attitude_euler, self._on_attitude),
            (self._raw.subscribe_mission_progress, self._on_progress),
        ]
        self._tasks = [asyncio.create_task(self._pump(sub, handler)) for sub, handler in streams]
        self._tasks.append(asyncio.create_task(self._watchdog()))
        self.on_event(LinkEvent("connected", text="mavsdk"))

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks = []
        if self._sdk is not None:
            result = self._sdk.destroy()
            if asyncio.iscoroutine(result):
                await result
            self._sdk = None

    # --- telemetry ----------------------------------------------------------------------------
    def _set(self, **changes: Any) -> None:
        self.telemetry = Telemetry(**{**self.telemetry.__dict__, **changes})

    async def _pump(self, subscribe: Callable[[], AsyncIterator[Any]], handler: Callable[[Any], None]) -> None:
        async for value in subscribe():
            handler(value)

    def _on_position(self, pos: Any) -> None:
        if math.isnan(pos.latitude_deg):
            return
        self._heard = time.monotonic()
        if self._lost:
            self._lost = False
            self._set(connected=True)
            self.on_event(LinkEvent("restored"))
        self._set(valid=True, lat_deg=pos.latitude_deg, lon_deg=pos.longitude_deg, rel_alt_m=pos.relative_altitude_m,
                  position_at=self._heard)

    def _on_battery(self, battery: Any) -> None:
        if not math.isnan(battery.remaining_percent):
            self._set(battery_fraction=battery.remaining_percent / 100.0, battery_at=time.monotonic())

    def _on_attitude(self, attitude: Any) -> None:
        if not attitude.timestamp_us:
            return
        boot_s = attitude.timestamp_us / 1e6
        last = self._boot_s
        if last is not None and boot_s < last - RESTART_SLACK_S * max(self.telemetry.time_rate, 1.0):
            self.generation += 1
            self._progress, self._expect_total = None, None
            self.on_event(LinkEvent("restarted", text=f"its clock went back from {last:.1f} s to {boot_s:.1f} s"))
            last = None
        self._boot_s = boot_s if last is None else max(last, boot_s)
        self._set(time_rate=self._clock_rate.update(boot_s, time.monotonic()))

    def _on_in_air(self, in_air: Any) -> None:
        was = self.telemetry.airborne
        self._set(airborne=bool(in_air), landed_known=True)
        if was and not in_air:
            self.on_event(LinkEvent("landed"))

    def _on_mode(self, mode: Any) -> None:
        name = getattr(mode, "name", str(mode))
        old = self.telemetry.mode
        self._set(mode=name)
        if old and old != name:
            self.on_event(LinkEvent("mode", text=name))

    def _on_progress(self, progress: Any) -> None:
        current, total = int(progress.current), int(progress.total)
        self._set(mission_seq=max(current, 0), mission_total=max(total, 0))
        if self._expect_total is not None and total != self._expect_total:
            return  # a report about the mission held before the last upload
        base = self._progress
        self._progress = (current, total)
        if base is None or base[1] != total or current < base[0]:
            return  # a new baseline: nothing completed yet
        for seq in range(base[0], current):
            self.on_event(LinkEvent("reached", seq=seq, mission=self.generation))
        if current != base[0]:
            self.on_event(LinkEvent("current", seq=current, total=total, mission=self.generation))

    async def _watchdog(self) -> None:
        while True:
            await asyncio.sleep(0.5)
            silent = time.monotonic() - self._heard
            if not self._lost and silent > self.settings.link_timeout_s:
                self._lost = True
                self._set(connected=False)
                self.on_event(LinkEvent("lost", text=f"no position for {silent:.1f} s"))

    # --- operations ---------------------------------------------------------------------------
    async def upload(self, items: Sequence[MissionItem]) -> None:
        raw = [raw_item(i) for i in items]
        async with self._upload_lock:
            if self._lost:
                raise LinkError("upload_mission()", "NO_LINK: the autopilot is not connected")
            last: MissionRawError | None = None
            for _ in range(self.settings.retries):
                try:
                    await self._raw.upload_mission(raw)
                except MissionRawError as err:
                    last = err
                    if err.result not in RETRYABLE:
                        break
                    continue
                self._expect_total, self._progress = len(raw), None
                self.generation += 1
                return
            result = _name(last.result) if last is not None else "UNKNOWN"
            raise LinkError("upload_mission()", result)

    async def download(self) -> list[MissionItem]:
        async with self._upload_lock:
            try:
                raw = await self._raw.download_mission()
            except MissionRawError as err:
                if err.result != MissionRawResult.NO_MISSION_AVAILABLE:
                    raise LinkError("download_mission()", _name(err.result)) from None
                raw = []  # the vehicle holds none
            self._expect_total, self._progress = len(raw), None
            self.generation += 1
            return [mission_item(r) for r in raw]

    async def start(self) -> None:
        try:
            await self._action.arm()
            await self._raw.start_mission()
        except (ActionError, MissionRawError) as err:
            raise LinkError("start()", _name(err.result)) from None

    async def resume(self) -> None:
        try:
            await self._raw.start_mission()  # PX4: AUTO.MISSION; ArduPilot: AUTO and MISSION_START
        except MissionRawError as err:
            raise LinkError("resume()", _name(err.result)) from None

    async def return_to_launch(self) -> None:
        try:
            await self._action.return_to_launch()
        except ActionError as err:
            raise LinkError("return_to_launch()", _name(err.result)) from None
