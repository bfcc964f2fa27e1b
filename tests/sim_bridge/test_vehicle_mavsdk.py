"""MAVSDK (native mavsdk 4 binding, asyncio API) flies the vehicle stub.

If MAVSDK refuses the stub, the stub is wrong: these tests are the proof that it behaves
as MAVSDK expects of an ArduPilot or PX4 autopilot.
"""

from __future__ import annotations

import asyncio
import logging
import math
from typing import Any

import pytest

from mavsdk import log_subscribe
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission import MissionAsync
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.plugins.mission import MissionError, MissionItem, MissionPlan, MissionResult
from mavsdk.plugins.mission_raw import MissionItem as RawItem

from protocol.geodesy import GeoOrigin, local_to_global
from protocol.mission import HoverPoint, MissionItem as Item, encode_path
from tests.support.gcs import as_stored

ORIGIN = GeoOrigin()
log = logging.getLogger("mavsdk")


def _to_logging(level: Any, message: str, file: str | None, line: int) -> bool:
    log.debug("%s %s", getattr(level, "name", level), message)
    return True  # MAVSDK's coloured lines would otherwise go to stdout


log_subscribe(_to_logging)


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        return (math.isnan(a) and math.isnan(b)) or a == b
    return a == b


def same_fields(a: Any, b: Any) -> bool:
    return vars(a).keys() == vars(b).keys() and all(_same(vars(a)[k], vars(b)[k]) for k in vars(a))


async def connect(port: int) -> tuple[Mavsdk, Any]:
    sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await sdk.add_any_connection(f"udpout://127.0.0.1:{port}")
    system = await sdk.first_autopilot(timeout_s=10.0)
    assert system is not None, "MAVSDK did not accept the stub as an autopilot"
    return sdk, system


async def close(sdk: Mavsdk, *plugins: Any) -> None:
    """MAVSDK destroyed after its plugins, each kept referenced until then: a plugin whose
    last reference an executor thread dropped after a call was destroyed there while MAVSDK
    was destroyed here, and the process aborted (a CI run: ``Fatal Python error: Aborted``)."""
    for plugin in plugins:
        plugin.destroy()
    result = sdk.destroy()
    if asyncio.iscoroutine(result):
        await result


async def follow_to_the_end(progress_stream: Any, total: int) -> list[int]:
    seen: list[int] = []
    async for progress in progress_stream:
        assert progress.total == total
        seen.append(progress.current)
        if progress.current == progress.total:
            return seen
    return seen


async def finished(plugin: Any, timeout_s: float = 2.0) -> bool:
    """MAVSDK's ``is_mission_finished`` of ``plugin`` (mission or mission_raw: the last item's
    MISSION_ITEM_REACHED counted) within ``timeout_s``: its progress comes from another
    message, MISSION_CURRENT, and on a loaded machine MAVSDK may report one before it has
    handled the other (seen once in a CI run)."""
    deadline = asyncio.get_running_loop().time() + timeout_s
    while not await plugin.is_mission_finished():
        if asyncio.get_running_loop().time() > deadline:
            return False
        await asyncio.sleep(0.05)
    return True


def path(flavour: str) -> list[Item]:
    points = [HoverPoint(40.0 + 55.0 * i, 60.0 + 40.0 * i, 50.0, 3.0) for i in range(6)]
    return encode_path(points, ORIGIN, flavour)  # type: ignore[arg-type]


def raw_items(items: list[Item]) -> list[RawItem]:
    return [
        RawItem(seq=i.seq, frame=i.frame, command=i.command, current=i.current, autocontinue=i.autocontinue,
                param1=i.param1, param2=i.param2, param3=i.param3, param4=i.param4, x=i.x, y=i.y, z=i.z,
                mission_type=i.mission_type)
        for i in items
    ]


@pytest.mark.timeout(60)
@pytest.mark.parametrize("flavour", ["ardupilot", "px4"])
def test_mission_raw_upload_download_fly(vehicle, flavour: str) -> None:
    _, port = vehicle("--flavour", flavour, "--speedup", "300", "--gps-delay-s", "0")

    async def scenario() -> None:
        sdk, system = await connect(port)
        raw, action = MissionRawAsync(system), ActionAsync(system)
        try:
            items = raw_items(path(flavour))
            await raw.upload_mission(items)
            back = await raw.download_mission()
            assert len(back) == len(items)
            # Read back as the autopilot stores it (ArduPilot: frames, whole seconds, home).
            for sent, got in zip(raw_items(as_stored(path(flavour), flavour)), back):
                assert same_fields(sent, got), f"{sent} != {got}"
            await action.arm()
            if flavour == "ardupilot":
                # ArduCopter's AUTO does not leave the ground without MISSION_START (or
                # throttle), which MAVSDK's start_mission does not send: take off first,
                # as ArduPilot users of MAVSDK do.
                await action.takeoff()
            await raw.start_mission()
            seen = await follow_to_the_end(raw.subscribe_mission_progress(), len(items))
            assert seen[-1] == len(items)
            assert seen == sorted(seen), f"progress only goes forward: {seen}"
            assert await finished(raw), "MAVSDK never counted the last item reached"
        finally:
            await close(sdk, raw, action)

    asyncio.run(asyncio.wait_for(scenario(), 50))


def mission_plan() -> MissionPlan:
    items = []
    for i in range(5):
        lat, lon, _ = local_to_global(ORIGIN, 50.0 + 80.0 * i, 400.0 - 70.0 * i, 0.0)
        # Degrees on a 1e-7 grid: MISSION_ITEM_INT carries nothing finer, so the download
        # can be compared field by field.
        items.append(MissionItem(
            latitude_deg=round(lat * 1e7) / 1e7, longitude_deg=round(lon * 1e7) / 1e7,
            relative_altitude_m=50.0, speed_m_s=12.0, is_fly_through=False, loiter_time_s=4.0,
            acceptance_radius_m=1.0,
        ))
    return MissionPlan(items)


@pytest.mark.timeout(60)
def test_mission_plugin_px4_upload_download_fly(vehicle) -> None:
    _, port = vehicle("--flavour", "px4", "--speedup", "300", "--gps-delay-s", "0")

    async def scenario() -> None:
        sdk, system = await connect(port)
        mission, action = MissionAsync(system), ActionAsync(system)
        try:
            plan = mission_plan()
            await mission.set_return_to_launch_after_mission(True)
            await mission.upload_mission(plan)
            back = await mission.download_mission()
            assert len(back.mission_items) == len(plan.mission_items)
            for sent, got in zip(plan.mission_items, back.mission_items):
                assert same_fields(sent, got), f"{sent} != {got}"
            assert await mission.get_return_to_launch_after_mission()
            await action.arm()
            await mission.start_mission()
            seen = await follow_to_the_end(mission.subscribe_mission_progress(), len(plan.mission_items))
            assert seen[-1] == len(plan.mission_items)
            assert await finished(mission), "MAVSDK never counted the last item reached"
        finally:
            await close(sdk, mission, action)

    asyncio.run(asyncio.wait_for(scenario(), 50))


@pytest.mark.timeout(60)
def test_mission_plugin_ardupilot_loses_item_0_to_home(vehicle) -> None:
    """MAVSDK's mission plugin is written for PX4: it puts its first waypoint in item 0,
    where ArduPilot keeps home. The stub, like ArduPilot, accepts the upload and replaces
    item 0 with home; the plugin then cannot read home's absolute-altitude frame back.
    Hence the service uses mission_raw with a home placeholder for ArduPilot."""
    _, port = vehicle("--flavour", "ardupilot", "--speedup", "300", "--gps-delay-s", "0")

    async def scenario() -> None:
        sdk, system = await connect(port)
        mission, raw_plugin = MissionAsync(system), MissionRawAsync(system)
        try:
            plan = mission_plan()
            await mission.upload_mission(plan)
            with pytest.raises(MissionError) as refused:
                await mission.download_mission()
            assert refused.value.result == MissionResult.UNSUPPORTED
            raw = await raw_plugin.download_mission()
            home = raw[0]
            assert (home.frame, home.command) == (0, 16)  # MAV_FRAME_GLOBAL, NAV_WAYPOINT
            assert (home.x, home.y, home.z) == (round(ORIGIN.lat_deg * 1e7), round(ORIGIN.lon_deg * 1e7), ORIGIN.alt_m)
            second = plan.mission_items[1]
            assert any(item.x == round(second.latitude_deg * 1e7) for item in raw[1:])
        finally:
            await close(sdk, mission, raw_plugin)

    asyncio.run(asyncio.wait_for(scenario(), 50))
