"""Both link backends against the real autopilot: ArduCopter SITL (tests/support/sitl.py),
over TCP on loopback. What the link asks for and receives, the wait for a position, a
refused arm, a mission read back as ArduPilot stores it, a replacement in flight that the
vehicle's own position (telemetry and its dataflash log) shows flown, a return-to-launch
replacement, and the autopilot killed and restarted under the link."""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import threading
import time
from typing import Any, Callable

import pytest

from planner_service.service.errors import LinkError
from planner_service.service.link import (Connected, Current, LinkEvent, LinkSettings, Lost, Restarted,
                                          Restored, VehicleLink, open_link)
from protocol import GeoOrigin, HoverPoint, encode_path, global_to_local, replacement_items, same_mission

from planner_service.harness.processes import free_port
from tests.support.sitl import PtyBridge, Sitl, ports, set_param
from tests.support.turn import TURN_WAIT_S

pytestmark = [pytest.mark.sitl, pytest.mark.timeout(150 + TURN_WAIT_S)]
BACKENDS = ["pymavlink", "mavsdk"]
ORIGIN = GeoOrigin()
ALT_M = 20.0
NEAR_M = 3.0
"""How close the vehicle's own position must come to a point to have flown to it (ArduCopter's
default WPNAV_RADIUS is 2 m)."""
PAUSED_S = 5.0
"""Vehicle seconds a pause is held before the test ends it (its item holds 60)."""


class Recorder:
    """The link's events, with the time each came."""

    def __init__(self) -> None:
        self.events: list[tuple[float, LinkEvent]] = []

    def __call__(self, ev: LinkEvent) -> None:
        self.events.append((time.monotonic(), ev))

    def of(self, kind: type) -> list[Any]:
        return [ev for _, ev in self.events if isinstance(ev, kind)]


async def until(what: str, predicate: Callable[[], bool], timeout_s: float, link: VehicleLink | None = None) -> None:
    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            detail = f"; telemetry {link.telemetry}" if link is not None else ""
            raise AssertionError(f"not {what} within {timeout_s:g} s{detail}")
        await asyncio.sleep(0.05)


def where(link: VehicleLink) -> tuple[float, float, float]:
    t = link.telemetry
    return global_to_local(ORIGIN, t.lat_deg, t.lon_deg, ORIGIN.alt_m + t.rel_alt_m)


def distance(a: tuple[float, float, float], b: HoverPoint) -> float:
    return math.dist(a, (b.x_m, b.y_m, b.z_m))


async def connected(sitl: Sitl, backend: str, events: Recorder) -> VehicleLink:
    link = open_link(backend, LinkSettings(sitl.url(1), "ardupilot", item_timeout_s=0.5, retries=10,
                                           link_timeout_s=2.0), events)
    await link.connect(15.0)
    return link


@pytest.mark.parametrize("backend", BACKENDS)
def test_telemetry_requested_position_awaited_a_refused_arm_and_a_disarming_between_the_steps(sitl: Sitl,
                                                                                                backend: str) -> None:
    async def run() -> None:
        events = Recorder()
        link = await connected(sitl, backend, events)
        try:
            # ArduCopter streams nothing until asked: everything the link needs arrives
            # because it asked, EXTENDED_SYS_STATE included (in no stream group).
            await until("the telemetry arriving", lambda: link.telemetry.landed_source == "EXTENDED_SYS_STATE"
                        and link.telemetry.battery_fraction is not None and link.telemetry.gps_fix >= 0, 20.0, link)
            # Before its EKF uses the GPS the autopilot has no position, and the link says why.
            assert not link.telemetry.position_ok, link.telemetry
            assert link.telemetry.waiting_for, link.telemetry
            with pytest.raises(LinkError, match="no position"):
                await link.start()
            await until("a position", lambda: link.telemetry.position_ok, 90.0, link)
            assert "EKF3 IMU0 is using GPS" in [t for _, t in sitl.texts]  # the autopilot agrees
            t = link.telemetry
            assert t.home_set and t.gps_fix >= 3 and (t.lat_deg, t.lon_deg) != (0.0, 0.0)
            assert t.position_boot_s is not None and t.position_boot_s > 0
            assert math.hypot(*where(link)[:2]) < 2.0  # at home
            await until("nothing missing", lambda: link.telemetry.missing == (), 10.0, link)
            # An arm the autopilot refuses (battery under its arming voltage): LinkError with
            # its own words, and the vehicle stays disarmed.
            set_param(sitl.url(2), "BATT_ARM_VOLT", 13.5)  # SITL's pack shows 12.6 V
            items = encode_path([HoverPoint(30.0, 30.0, ALT_M, 1.0)], ORIGIN, "ardupilot")
            await link.upload(items)
            with pytest.raises(LinkError) as refused:
                await link.start()
            assert "arm()" in str(refused.value) and "autopilot:" in str(refused.value), refused.value
            await asyncio.sleep(1.0)
            assert not link.telemetry.armed and not link.telemetry.airborne
            # Armed in GUIDED, the vehicle disarms itself on the ground after DISARM_DELAY (10 s
            # of its time) if the start's next steps are slow: then they are not sent, nothing
            # the operator allowed is left to start.
            set_param(sitl.url(2), "BATT_ARM_VOLT", 0.0)
            set_mode = link._set_mode

            async def slow_set_mode(name: str) -> None:  # a link slower than DISARM_DELAY
                if name == "AUTO":
                    await until("ArduCopter's own disarming", lambda: not link.telemetry.armed, 60.0, link)
                await set_mode(name)

            link._set_mode = slow_set_mode  # type: ignore[method-assign]
            with pytest.raises(LinkError, match=r"disarmed meanwhile .* s after the arming\)") as disarmed:
                await link.start()
            await asyncio.sleep(1.0)
            assert not link.telemetry.armed and not link.telemetry.airborne, link.telemetry
        finally:
            await link.close()
        print(f"\n{backend}: refusal: {refused.value}\n{disarmed.value}")

    asyncio.run(run())


@pytest.mark.parametrize("backend", BACKENDS)
def test_replacement_in_flight_flies_the_new_plan_and_an_rtl_replacement_returns_home(sitl_ready: Sitl,
                                                                                        backend: str) -> None:
    """[home, takeoff, a, b, c, RTL]; while the vehicle holds at a (item 2), b and c are
    replaced by d and e with items 0..2 kept and ``current_seq`` 3: ArduPilot restarts the
    hold at a (the change is within its three-command window), and the link moves it on to
    3 with MAV_CMD_DO_SET_MISSION_CURRENT. At d, ``set_current(4)`` ends the hold early;
    towards e, e is lost (another member claimed it first): a replacement whose item 4 is a
    pause where the vehicle is, then e, stops it there until ``set_current(5)`` ends the pause
    (``SortieLogic._maybe_end_pause``); towards e again, a replacement of return to launch
    alone brings it home."""
    sitl = sitl_ready
    a, b, c = HoverPoint(40.0, 40.0, ALT_M, 30.0), HoverPoint(120.0, 40.0, ALT_M, 0.0), HoverPoint(120.0, 120.0, ALT_M)
    d, e = HoverPoint(0.0, 110.0, ALT_M, 30.0), HoverPoint(90.0, 150.0, ALT_M)

    async def run() -> dict[str, Any]:
        events = Recorder()
        link = await connected(sitl, backend, events)
        paused: list[HoverPoint] = []
        closest: dict[str, float] = {"d": math.inf, "e": math.inf, "b": math.inf}
        at_d: list[float] = []
        at_pause: list[float] = []

        def track() -> bool:
            here = where(link)
            for name, point in (("d", d), ("e", e), ("b", b)):
                closest[name] = min(closest[name], distance(here, point))
            if link.telemetry.position_boot_s is not None:
                if distance(here, d) < NEAR_M:
                    at_d.append(link.telemetry.position_boot_s)
                if paused and distance(here, paused[0]) < NEAR_M:
                    at_pause.append(link.telemetry.position_boot_s)
            return False

        async def watch(what: str, done: Callable[[], bool], timeout_s: float) -> None:
            await until(what, lambda: track() or done(), timeout_s, link)

        try:
            await until("a position", lambda: link.telemetry.position_ok, 30.0, link)
            first = encode_path([a, b, c], ORIGIN, "ardupilot")  # [home, takeoff, a, b, c, RTL]
            await link.upload(first)
            held = await link.download()
            assert same_mission(held, first, "ardupilot"), (held, first)  # read back as ArduPilot stores it
            await link.start()
            await watch("holding at a (item 2)", lambda: link.telemetry.mission_seq == 2
                        and distance(where(link), a) < NEAR_M, 60.0)
            second, next_seq = replacement_items(held, 2, [d, e], ORIGIN, "ardupilot")
            await link.upload(second, current_seq=next_seq)
            assert link.telemetry.mission_seq == next_seq == 3
            await watch("holding at d", lambda: len(at_d) > 4, 60.0)
            await link.set_current(4)  # the user's upload is done: end the hold early
            assert link.telemetry.mission_seq == 4
            await watch("away from d", lambda: distance(where(link), d) > 2 * NEAR_M, 20.0)
            held_at_d = at_d[-1] - at_d[0]
            # e lost on the way: a pause where the vehicle is, then e, ended by the service.
            here = where(link)
            paused.append(HoverPoint(here[0], here[1], ALT_M, 60.0))
            third, pause_seq = replacement_items(second, 3, [paused[0], e], ORIGIN, "ardupilot")
            await link.upload(third, current_seq=pause_seq)
            assert link.telemetry.mission_seq == pause_seq == 4
            await watch(f"paused {PAUSED_S:g} s", lambda: len(at_pause) > 1 and at_pause[-1] - at_pause[0] >= PAUSED_S,
                        60.0)
            await link.set_current(5)  # the new point's claim has settled: fly on
            assert link.telemetry.mission_seq == 5
            await watch("away from the pause", lambda: distance(where(link), paused[0]) > 2 * NEAR_M, 20.0)
            paused_s = at_pause[-1] - at_pause[0]
            # Return to launch alone, replacing e while the vehicle flies towards it.
            fourth, rtl_seq = replacement_items(third, 4, [], ORIGIN, "ardupilot")
            assert fourth[rtl_seq].command == 20 and len(fourth) == rtl_seq + 1
            await link.upload(fourth, current_seq=rtl_seq)
            await watch("landed at home", lambda: not link.telemetry.armed and not link.telemetry.airborne, 90.0)
            home_m = math.hypot(*where(link)[:2])
            assert home_m < NEAR_M, home_m
            assert closest["d"] < NEAR_M and held_at_d < d.hold_s / 2, (closest, held_at_d)
            assert PAUSED_S <= paused_s < paused[0].hold_s / 2, paused_s  # held, then ended by the command
            assert closest["e"] > 20.0 and closest["b"] > 20.0, closest  # never flew the replaced points
            return {"closest": closest, "home_m": home_m, "held_at_d": held_at_d, "paused_s": paused_s,
                    "pause": paused[0],
                    "currents": [ev.seq for ev in events.of(Current)]}
        finally:
            await link.close()

    figures = asyncio.run(run())
    sitl.stop()  # flushes the dataflash log
    # The autopilot's own log: it flew to d, never to b or e, and restarted the command on
    # the upload as ArduPilot does.
    own = [global_to_local(ORIGIN, r["Lat"], r["Lng"], ORIGIN.alt_m + r["RelHomeAlt"]) for r in sitl.read_log(("POS",))]
    assert own, "no POS records in the dataflash log"
    assert min(distance(p, d) for p in own) < NEAR_M
    assert min(distance(p, b) for p in own) > 20.0 and min(distance(p, e) for p in own) > 20.0
    assert min(distance(p, figures["pause"]) for p in own) < NEAR_M
    texts = [r["Message"] for r in sitl.read_log(("MSG",))]
    assert any("Auto mission changed, restarted command" in t for t in texts), texts[-20:]
    print(f"\n{backend}: closest approach {figures['closest']}, held {figures['held_at_d']:.1f} s of {d.hold_s:g} "
          f"at d, paused {figures['paused_s']:.1f} s, landed {figures['home_m']:.2f} m from home, MISSION_CURRENT {figures['currents']}")


@pytest.mark.parametrize("backend, transport", [("pymavlink", "tcp"), ("pymavlink", "udp"), ("pymavlink", "serial"),
                                                ("mavsdk", "tcp"), ("mavsdk", "udp"), ("mavsdk", "serial")])
def test_the_link_survives_the_autopilot_killed_and_restarted(make_sitl: Callable[..., Sitl], backend: str,
                                                              transport: str, caplog: pytest.LogCaptureFixture) -> None:
    """TCP: SITL's SERIAL1 port, closed under the link; UDP: SITL sends to the link's port
    (``--serial1 udpclient:``) and falls silent; serial: a pseudo-terminal joined to SITL's
    SERIAL2, which stays open while the autopilot behind it restarts."""
    bridge: PtyBridge | None = None
    if transport == "udp":
        port = free_port(socket.SOCK_DGRAM)
        sitl = make_sitl(serials={1: f"udpclient:127.0.0.1:{port}"})
        url = f"udpin:127.0.0.1:{port}"
    else:
        sitl = make_sitl()
        url = sitl.url(1)
        if transport == "serial":
            bridge = PtyBridge(ports(sitl.instance)[2])
            url = f"{bridge.device},115200"
    sitl.wait_ready()

    async def run() -> dict[str, float]:
        events = Recorder()
        link = open_link(backend, LinkSettings(url, "ardupilot", link_timeout_s=2.0), events)
        await link.connect(15.0)
        try:
            await until("a position", lambda: link.telemetry.position_ok, 30.0, link)
            before = link.telemetry.position_boot_s
            threads = {t.name for t in threading.enumerate()}
            killed_at = time.monotonic()
            await asyncio.to_thread(sitl.kill)
            await until("lost", lambda: bool(events.of(Lost)), 10.0, link)
            lost_s = time.monotonic() - killed_at
            assert not link.telemetry.connected
            with pytest.raises(LinkError, match="NO_LINK"):
                await link.upload(encode_path([HoverPoint(10.0, 10.0, ALT_M)], ORIGIN, "ardupilot"))
            await asyncio.sleep(1.0)
            started_at = time.monotonic()
            await asyncio.to_thread(sitl.start)
            await until("restored", lambda: bool(events.of(Restored)), 30.0, link)
            await until("the restart believed", lambda: bool(events.of(Restarted)), 30.0, link)
            restored_s = time.monotonic() - started_at
            # The new boot streams nothing until asked: the link asked again by itself.
            await until("telemetry again", lambda: link.telemetry.position_boot_s is not None
                        and link.telemetry.position_boot_s < (before or 0.0)
                        and link.telemetry.landed_source == "EXTENDED_SYS_STATE", 30.0, link)
            await until("a position again", lambda: link.telemetry.position_ok, 90.0, link)
            assert link.telemetry.connected
            assert {t.name for t in threading.enumerate()} >= threads - {"sitl-monitor"}
            assert all(not task.done() for task in link._tasks)  # type: ignore[attr-defined]
            # The link works: a mission goes up and comes back.
            items = encode_path([HoverPoint(10.0, 10.0, ALT_M, 1.0)], ORIGIN, "ardupilot")
            await link.upload(items)
            assert same_mission(await link.download(), items, "ardupilot")
            assert len(events.of(Connected)) == 1 and len(events.of(Restarted)) == 1
            return {"lost_s": lost_s, "restored_s": restored_s}
        finally:
            await link.close()

    caplog.set_level(logging.INFO, logger="planner_service")
    try:
        figures = asyncio.run(run())
    finally:
        if bridge is not None:
            bridge.close()
    said = [r.getMessage() for r in caplog.records]
    assert any("autopilot link lost" in m for m in said) and any("the autopilot restarted" in m for m in said), said
    print(f"\n{backend} over {transport}: lost {figures['lost_s']:.2f} s after the kill; restored and restart "
          f"seen {figures['restored_s']:.2f} s after SITL started again")
