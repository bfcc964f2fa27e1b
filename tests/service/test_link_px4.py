"""Both link backends against the real PX4: PX4 SITL 1.18 with its SIH quadcopter
(tests/support/px4.py), on PX4's onboard (API) link as a companion computer uses it
(``Px4.url``, udpin:127.0.0.1:14540+N). The vehicle's truth is the harness's monitor on
the ground-station link (its GLOBAL_POSITION_INT fixes, heartbeats, MISSION_CURRENT).
What the link asks for, what PX4 refuses and what it sends unasked; a refused arm with
PX4's reason; a mission read back as PX4 stores it and named by its CRC32; a replacement
in flight flown as the new plan with each reached item reported once; PX4 killed and
restarted in the air under the link. The ArduCopter variants are in test_link_sitl.py;
what differs is in docs/VEHICLE.md, "The link against PX4 SITL"."""

from __future__ import annotations

import asyncio
import logging
import math
import socket
import time
from collections import Counter
from typing import Any, Callable

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from planner_service.service.errors import LinkError
from planner_service.service.link import (ArmedChanged, Connected, Current, LinkSettings, Lost, ModeChanged, Reached,
                                          Restarted, Restored, VehicleLink, open_link)
from planner_service.service.link.streams import stream_plan
from protocol import GeoOrigin, HoverPoint, encode_path, global_to_local, replacement_items, same_mission
from sim_bridge.vehicle.mission_id import px4_mission_id
from tests.service.test_link_sitl import PAUSED_S, Recorder, distance, until, where
from tests.support.px4 import PARAMS, Px4, read_params
from tests.support.turn import TURN_WAIT_S

pytestmark = [pytest.mark.sitl, pytest.mark.timeout(150 + TURN_WAIT_S)]
BACKENDS = ["pymavlink", "mavsdk"]
ORIGIN = GeoOrigin()
SPEED = 10
"""PX4_SIM_SPEED_FACTOR of the flying tests (measured to keep up on the 2 busy cores)."""
ALT_M = 20.0
NEAR_M = 3.0
"""How close the vehicle's own position must come to a point to have flown to it (PX4's
NAV_ACC_RAD default is 2 m)."""
FAR_M = 20.0
"""How far the vehicle must stay from a point it must not have flown to."""
WINDOW_S = 3 * max(spec.interval_s for spec in stream_plan("px4"))
"""How long the streams' rates are measured, in PX4's time: three of the slowest's intervals,
so that even it arrives at least twice."""
PX4_UNASKED_HZ = {"GLOBAL_POSITION_INT": 50.0, "SYS_STATUS": 5.0, "EXTENDED_SYS_STATE": 5.0}
"""What PX4 sends of these on its onboard link unasked, per simulated second
(test_conformance_px4.ONBOARD_HZ): the link's requests bring them down."""
FLYING = {"COM_DISARM_PRFLT": read_params(PARAMS)["COM_DISARM_PRFLT"]}
"""For a test that takes off: PX4's preflight disarm as the scenario sets it (100 s of its
time, 10 s of wall at x10), not its default 10 s: one second of wall at x10, which a start's
three round trips on the busy 2 cores once outlasted (a clean-clone run: "Disarmed by auto
preflight disarming" between the arming and AUTO.MISSION). The start arms in AUTO.MISSION
since, so PX4 climbs at once; the margin stays. The test of a slow start keeps PX4's default."""


def link_for(px4: Px4, backend: str, events: Recorder) -> VehicleLink:
    """The link as the service sets it up (its silence bound the service's default, 3 s: a
    CI run's MAVSDK link heard nothing for 2.4 s beside two SITLs, a loss at the 2 s these
    tests once set), with the short item timeout and the retries of a link on loopback."""
    return open_link(backend, LinkSettings(px4.url, "px4", item_timeout_s=0.5, retries=10), events)


def tap(link: VehicleLink, arrivals: dict[int, list[float]] | None = None) -> Counter[int]:
    """Count every message the link takes from the autopilot, by message id (both backends
    tell ``streams.heard`` of each): what PX4 really sends on this link. ``arrivals``: each
    message's arrival times too, in the vehicle's time (the link's last ``boot_s``)."""
    counts: Counter[int] = Counter()
    streams = link.state.streams
    heard = streams.heard

    def counting(msg_id: int) -> bool:
        counts[msg_id] += 1
        if arrivals is not None and link.telemetry.boot_s is not None:
            arrivals.setdefault(msg_id, []).append(link.telemetry.boot_s)
        return heard(msg_id)

    streams.heard = counting  # type: ignore[method-assign]
    return counts


def rate_hz(arrivals: list[float]) -> float:
    """A stream's rate from its arrival times: intervals over the time they span (0: fewer
    than two arrivals)."""
    span = arrivals[-1] - arrivals[0] if len(arrivals) > 1 else 0.0
    return (len(arrivals) - 1) / span if span > 0 else 0.0


def fixes_local(px4: Px4, since: float = 0.0) -> list[tuple[float, float, float]]:
    """Where the vehicle really was (the monitor's fixes since ``since``), in local metres."""
    return [global_to_local(ORIGIN, f.lat_e7 / 1e7, f.lon_e7 / 1e7, ORIGIN.alt_m + f.relative_alt_mm / 1e3)
            for f in list(px4.fixes) if f.at >= since]


def closest(points: list[tuple[float, float, float]], to: HoverPoint) -> float:
    return min((distance(p, to) for p in points), default=math.inf)


@pytest.mark.parametrize("backend", BACKENDS)
def test_telemetry_from_px4s_streams_position_awaited_and_a_refused_arm(make_px4: Callable[..., Px4], backend: str,
                                                                         caplog: pytest.LogCaptureFixture) -> None:
    """At speed 1: the link listens before PX4 starts, as a companion computer beside it
    does; the arm is refused in AUTO.MISSION without a mission (PX4's checks never pass)."""
    caplog.set_level(logging.INFO, logger="planner_service")
    px4 = make_px4(speed=1, start=False)

    async def run() -> dict[str, Any]:
        events = Recorder()
        link = link_for(px4, backend, events)
        arrivals: dict[int, list[float]] = {}
        counts = tap(link, arrivals)
        connecting = asyncio.ensure_future(link.connect(30.0))
        await asyncio.to_thread(px4.start)
        await connecting
        try:
            # PX4's texts on this link come about a second late in its first second of boot
            # (measured at speed 1): arm after it.
            await asyncio.sleep(1.5)
            # In AUTO.MISSION without a mission PX4's pre-arm checks never pass: it refuses to
            # arm, and says why, however late the arm comes (on a loaded machine the checks of
            # a PX4 in AUTO.LOITER had passed before the arm went: the race is gone).
            await link.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 4, what="AUTO.MISSION")
            with pytest.raises(LinkError) as refused:
                await link.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arm()")
            reason = str(refused.value)
            assert "MAV_RESULT_TEMPORARILY_REJECTED" in reason, reason
            assert "autopilot: Arming denied: Resolve system health failures first" in reason, reason
            assert not link.telemetry.armed and px4.mode() is not None and not px4.mode()[1]  # type: ignore[index]
            # No position yet: the link says what it waits for, and start() refuses.
            if not link.telemetry.position_ok:
                assert link.telemetry.waiting_for, link.telemetry
                with pytest.raises(LinkError, match="no position"):
                    await link.start()
            await until("a position", lambda: link.telemetry.position_ok, 60.0, link)
            t = link.telemetry
            assert t.home_set and t.gps_fix >= 3 and (t.lat_deg, t.lon_deg) != (0.0, 0.0), t
            assert math.hypot(*where(link)[:2]) < 2.0  # at home
            await until("the telemetry arriving", lambda: link.telemetry.landed_source == "EXTENDED_SYS_STATE"
                        and link.telemetry.battery_fraction is not None and link.telemetry.missing == (), 20.0, link)
            assert link.telemetry.battery_fraction == 1.0  # SIH's pack, full while disarmed
            # Rates as asked, in PX4's time, once the requests are answered: each stream's
            # arrivals over whole intervals, so that where a window of 4 s begins is no matter
            # (counted in one, a 0.5 Hz stream 5 % late on a busy machine showed one message
            # in 4 s: half its rate).
            counts.clear()
            arrivals.clear()
            clock0, wall0 = link.telemetry.boot_s or 0.0, time.monotonic()
            await until("the window's end in PX4's time", lambda: (link.telemetry.boot_s or 0.0) - clock0 >= WINDOW_S,
                        30.0, link)
            vehicle_s = (link.telemetry.boot_s or 0.0) - clock0
            rates = {s.name: rate_hz(arrivals.get(s.msg_id, [])) for s in stream_plan("px4")}
            total_hz = sum(counts.values()) / (time.monotonic() - wall0)
            return {"reason": reason, "rates": rates, "vehicle_s": vehicle_s, "total_hz": total_hz,
                    "refusals": [r.getMessage() for r in caplog.records if "SET_MESSAGE_INTERVAL refused" in
                                 r.getMessage()]}
        finally:
            await link.close()

    figures = asyncio.run(run())
    rates = figures["rates"]
    for spec in stream_plan("px4"):
        asked = 1.0 / spec.interval_s
        # Each message arrives, at most at the rate asked (PX4 honours the interval) or, where
        # PX4 refused the request (MISSION_CURRENT: its mission manager's own 1 Hz), at its own.
        assert rates[spec.name] > 0.5 * min(asked, 1.0), (spec.name, rates)
        assert rates[spec.name] <= 1.3 * max(asked, 1.0) + 0.5, (spec.name, rates)
    for name, unasked in PX4_UNASKED_HZ.items():
        assert rates[name] < unasked / 2, f"{name} still at PX4's own rate: {rates}"
    # What PX4 refuses: SET_MESSAGE_INTERVAL for MISSION_CURRENT alone (MAV_RESULT_FAILED).
    assert len(figures["refusals"]) == 1 and "MISSION_CURRENT" in figures["refusals"][0], figures["refusals"]
    print(f"\n{backend}: refusal: {figures['reason']}; in {figures['vehicle_s']:.1f} s of PX4's time "
          f"{ {n: round(r, 1) for n, r in rates.items()} } Hz; everything: {figures['total_hz']:.0f} msg/s wall")


@pytest.mark.parametrize("backend", BACKENDS)
def test_read_back_crc_and_a_replacement_in_flight_flown_with_each_reach_reported_once(
        make_px4: Callable[..., Px4], backend: str) -> None:
    """[takeoff, a, b, c, RTL]; while the vehicle holds at a (item 1), b and c are replaced by
    d and e (items 0..1 kept, d marked current): PX4 flies d at once, ending the hold. On the
    way to e, e is lost (another member claimed it first): a replacement whose item 3 is a
    pause where the vehicle is, then e, marked current, stops it there until ``set_current(4)``
    ends the pause (``SortieLogic._maybe_end_pause``). At e a replacement of return to launch
    alone brings it home, where it lands and disarms."""
    px4 = make_px4(speed=SPEED, params=FLYING)
    px4.wait_ready()
    a, b, c = HoverPoint(30.0, 30.0, ALT_M, 60.0), HoverPoint(90.0, 30.0, ALT_M), HoverPoint(90.0, 90.0, ALT_M)
    d, e = HoverPoint(-10.0, 70.0, ALT_M, 3.0), HoverPoint(60.0, 100.0, ALT_M, 60.0)

    async def run() -> dict[str, Any]:
        events = Recorder()
        link = link_for(px4, backend, events)
        counts = tap(link)
        await link.connect(15.0)
        try:
            await until("a position", lambda: link.telemetry.position_ok, 30.0, link)
            first = encode_path([a, b, c], ORIGIN, "px4")  # [takeoff, a, b, c, RTL]
            await link.upload(first)
            crc = px4_mission_id(first)
            assert link.mission_id == crc, (link.mission_id, crc)
            held = await link.download()
            assert same_mission(held, first, "px4"), (held, first)  # PX4 stores it as sent (NaN kept)
            assert link.mission_id == crc
            await until("MISSION_CURRENT naming it", lambda: link.telemetry.mission_id == crc, 10.0, link)
            await link.start()
            await until("holding at a (item 1)", lambda: link.telemetry.mission_seq == 1
                        and distance(where(link), a) < NEAR_M, 60.0, link)
            replaced_at = time.monotonic()
            second, next_seq = replacement_items(held, 1, [d, e], ORIGIN, "px4")
            await link.upload(second, current_seq=next_seq)
            assert link.telemetry.mission_seq == next_seq == 2
            assert link.mission_id == px4_mission_id(second)
            await until("on the way to e", lambda: link.telemetry.mission_seq == 3
                        and distance(where(link), d) > 2 * NEAR_M, 60.0, link)
            here = where(link)
            pause = HoverPoint(here[0], here[1], ALT_M, 60.0)
            third, pause_seq = replacement_items(second, 2, [pause, e], ORIGIN, "px4")
            await link.upload(third, current_seq=pause_seq)
            assert link.telemetry.mission_seq == pause_seq == 3
            at_pause: list[float] = []

            def paused() -> bool:
                boot_s = link.telemetry.position_boot_s
                if boot_s is not None and distance(where(link), pause) < NEAR_M:
                    at_pause.append(boot_s)
                return len(at_pause) > 1 and at_pause[-1] - at_pause[0] >= PAUSED_S

            await until(f"paused {PAUSED_S:g} s", paused, 60.0, link)
            await link.set_current(4)  # the new point's claim has settled: fly on
            await until("away from the pause", lambda: paused() or distance(where(link), pause) > 2 * NEAR_M, 20.0,
                        link)
            paused_s = at_pause[-1] - at_pause[0]
            await until("holding at e", lambda: link.telemetry.mission_seq == 4
                        and distance(where(link), e) < NEAR_M, 60.0, link)
            home_at = time.monotonic()
            fourth, rtl_seq = replacement_items(third, 4, [], ORIGIN, "px4")
            await link.upload(fourth, current_seq=rtl_seq)
            await until("landed at home", lambda: not link.telemetry.armed and not link.telemetry.airborne, 90.0, link)
            await asyncio.sleep(1.5)  # PX4 repeats the last MISSION_ITEM_REACHED after the landing
            return {"replaced_at": replaced_at, "home_at": home_at, "events": events, "pause": pause,
                    "paused_s": paused_s,
                    "reached_raw": counts[M.MAVLINK_MSG_ID_MISSION_ITEM_REACHED], "generation": link.generation}
        finally:
            await link.close()

    figures = asyncio.run(run())
    events: Recorder = figures["events"]
    # The vehicle's truth: it flew to d and e, never to b or c; it came home.
    after = fixes_local(px4, figures["replaced_at"])
    assert closest(after, d) < NEAR_M and closest(after, e) < NEAR_M, (closest(after, d), closest(after, e))
    assert closest(after, figures["pause"]) < NEAR_M
    assert PAUSED_S <= figures["paused_s"] < figures["pause"].hold_s / 2, figures["paused_s"]  # ended by the command
    everywhere = fixes_local(px4)
    assert closest(everywhere, b) > FAR_M and closest(everywhere, c) > FAR_M
    assert math.hypot(*everywhere[-1][:2]) < NEAR_M, everywhere[-1]
    going_home = fixes_local(px4, figures["home_at"])
    assert closest(going_home, e) < NEAR_M and all(p[0] < e.x_m + NEAR_M for p in going_home)  # e's hold ended
    # Each item reached is reported once, though PX4 repeats each MISSION_ITEM_REACHED.
    reached = [(ev.mission, ev.seq) for ev in events.of(Reached)]
    assert len(reached) == len(set(reached)), reached
    assert figures["reached_raw"] > len(reached), (figures["reached_raw"], reached)
    by_mission = {m: sorted(s for mm, s in reached if mm == m) for m, _ in reached}
    # Of the first mission only the takeoff: PX4 left a's hold for d, never completing a.
    assert by_mission[min(by_mission)] == [0], by_mission
    print(f"\n{backend}: reached {reached} ({figures['reached_raw']} MISSION_ITEM_REACHED heard); MISSION_CURRENT "
          f"{[(ev.mission, ev.seq) for ev in events.of(Current)]}; closest to d "
          f"{closest(after, d):.1f} m, to b {closest(everywhere, b):.0f} m; paused {figures['paused_s']:.1f} s; landed "
          f"{math.hypot(*everywhere[-1][:2]):.2f} m from home")


@pytest.mark.parametrize("backend", BACKENDS)
def test_px4_killed_and_restarted_in_the_air(make_px4: Callable[..., Px4], backend: str,
                                             caplog: pytest.LogCaptureFixture) -> None:
    """PX4 dies in flight (SIGKILL) and starts again in the same folder: it boots on the
    ground at home, disarmed, with the mission kept in its dataman. The link sees it lost,
    restored and restarted, asks for its telemetry again, and reads the mission back."""
    caplog.set_level(logging.INFO, logger="planner_service")
    px4 = make_px4(speed=SPEED, params=FLYING)
    px4.wait_ready()
    a = HoverPoint(40.0, 0.0, ALT_M, 60.0)

    async def run() -> dict[str, float]:
        events = Recorder()
        link = link_for(px4, backend, events)
        await link.connect(15.0)
        try:
            await until("a position", lambda: link.telemetry.position_ok, 30.0, link)
            items = encode_path([a], ORIGIN, "px4")
            await link.upload(items)
            await link.start()
            await until("holding at a", lambda: distance(where(link), a) < NEAR_M, 60.0, link)
            before = link.telemetry.position_boot_s or 0.0
            killed_at = time.monotonic()
            await asyncio.to_thread(px4.restart)
            restarted_s = time.monotonic() - killed_at
            await until("the restart believed", lambda: bool(events.of(Restarted)), 30.0, link)
            await until("telemetry again", lambda: (link.telemetry.position_boot_s or math.inf) < before
                        and link.telemetry.landed_source == "EXTENDED_SYS_STATE" and link.telemetry.position_ok,
                        60.0, link)
            seen_s = time.monotonic() - killed_at
            t = link.telemetry
            assert t.connected and not t.armed and not t.airborne, t
            assert math.hypot(*where(link)[:2]) < 2.0 and abs(t.rel_alt_m) < 1.0, where(link)  # at home
            held = await link.download()
            assert same_mission(held, items, "px4") and link.mission_id == px4_mission_id(items), held
            assert len(events.of(Connected)) == 1 and len(events.of(Restarted)) == 1
            lost = bool(events.of(Lost))
            assert not lost or events.of(Restored), "lost and never restored"
            return {"restart_s": restarted_s, "seen_s": seen_s, "lost": float(lost)}
        finally:
            await link.close()

    figures = asyncio.run(run())
    said = [r.getMessage() for r in caplog.records]
    assert any("the autopilot restarted" in m for m in said), said
    print(f"\n{backend}: PX4 up again {figures['restart_s']:.2f} s after the kill, the restart and a position seen "
          f"{figures['seen_s']:.2f} s after it; link lost meanwhile: {bool(figures['lost'])}")


@pytest.mark.parametrize("backend", BACKENDS)
def test_upload_and_read_back_over_a_lossy_link(make_px4: Callable[..., Px4], backend: str, tmp_path: Any) -> None:
    """Through ``sim_bridge lossy-proxy`` (a fifth of the datagrams dropped each way, some
    duplicated, delayed and reordered) to PX4's onboard port, which answers whoever spoke to it
    first: a 20-point mission goes up in full and reads back as sent, PX4 names it by its CRC32,
    and the link does not take the losses for a lost autopilot. At speed 1: PX4 times its
    own mission transfers in its simulated time, so at speed 10 it gives up a transfer after a
    tenth of a real vehicle's wait (MAVSDK's download then fails with PX4's "Mission sync
    timeout")."""
    from planner_service.harness.processes import Child, free_port

    px4 = make_px4(speed=1)
    port = free_port(socket.SOCK_DGRAM)
    proxy = Child("sim_bridge", ["lossy-proxy", "--listen", f"127.0.0.1:{port}", "--forward",
                                 f"127.0.0.1:{14580 + px4.instance}", "--drop", "0.2", "--dup", "0.05",
                                 "--delay-ms", "20", "--seed", "3"], tmp_path / "proxy.log")
    points = [HoverPoint(20.0 * (k % 5), 25.0 * (k // 5), ALT_M, 5.0) for k in range(20)]
    items = encode_path(points, ORIGIN, "px4")
    try:
        proxy.wait_ready("lossy proxy")

        async def run() -> tuple[list[Any], int, int]:
            events = Recorder()
            link = open_link(backend, LinkSettings(f"udpout:127.0.0.1:{port}", "px4", item_timeout_s=0.5, retries=10,
                                                   link_timeout_s=3.0), events)
            await link.connect(20.0)
            try:
                await link.upload(items)
                held = await link.download()
                return held, link.mission_id, len(events.of(Lost))
            finally:
                await link.close()

        held, mission_id, lost = asyncio.run(run())
    finally:
        assert proxy.stop() == 0, proxy.log()[-2000:]
    assert same_mission(held, items, "px4"), (len(held), len(items))
    assert mission_id == px4_mission_id(items)
    assert lost == 0
    print(f"\n{backend} over a lossy link to PX4: {len(items)} items up and read back; mission_id {mission_id}")


def test_a_start_arms_in_the_mission_mode_and_goes_no_further_once_the_authority_ends(
        make_px4: Callable[..., Px4]) -> None:
    """A start switches PX4 to AUTO.MISSION before arming it (``PX4.arm_mode``), so PX4 is never
    armed on the ground in another mode: armed in AUTO.LOITER it sat there until the next step,
    its land detector could blink "in the air" and COM_DISARM_LAND then disarmed it (a whole
    sortie in CI, MAVSDK, on a loaded machine). A start also stops between its steps: when
    ``proceed`` gives a reason (the service's authority ended meanwhile) nothing more is sent,
    and PX4 is not armed. A link too slow for PX4's preflight disarm (10 s of its time, 1 s at
    x10; the default, unlike docs/sitl-px4.params) no longer loses the start: armed in the
    mission mode it is flying before the next step. One backend: the steps are the link's base
    class, shared."""
    px4 = make_px4(speed=SPEED)
    px4.wait_ready()

    async def run() -> tuple[LinkError, Recorder]:
        events = Recorder()
        link = link_for(px4, "mavsdk", events)
        await link.connect(15.0)
        try:
            await until("a position", lambda: link.telemetry.position_ok, 30.0, link)
            # a hold longer than the test: the mission's RTL (AUTO.RTL) comes some 14 s of wall after
            # the arming at the soonest, never within the slow step below (with a hold of 5 s it
            # came about 2.6 s after, and a CI run saw it)
            await link.upload(encode_path([HoverPoint(30.0, 0.0, ALT_M, 120.0)], ORIGIN, "px4"))
            with pytest.raises(LinkError, match="stopped between its steps: the pilot took it") as stopped:
                await link.start(lambda: "the pilot took it")
            await until("AUTO.MISSION shown", lambda: link.telemetry.mode == "AUTO.MISSION", 10.0, link)
            await asyncio.sleep(1.0)  # nothing after the mode: PX4 is not armed
            assert not link.telemetry.armed and link.telemetry.mode == "AUTO.MISSION", link.telemetry

            set_mode = link._set_mode

            async def slow_set_mode(name: str) -> None:  # a slow link: past PX4's preflight disarm
                await asyncio.sleep(2.5)
                await set_mode(name)

            link._set_mode = slow_set_mode  # type: ignore[method-assign]
            await link.start()
            await until("in the air above 5 m", lambda: link.telemetry.airborne and link.telemetry.rel_alt_m > 5.0,
                        30.0, link)
            return stopped.value, events
        finally:
            await link.close()

    stopped, events = asyncio.run(run())
    # The vehicle's own word: every heartbeat that showed it armed showed AUTO.MISSION.
    changes = [(type(ev).__name__, ev.mode if isinstance(ev, ModeChanged) else ev.armed)
               for ev in events.of((ModeChanged, ArmedChanged))]
    armed_at = changes.index(("ArmedChanged", True))
    assert ("ModeChanged", "AUTO.MISSION") in changes[:armed_at], changes
    assert not [c for c in changes[armed_at:] if c[0] == "ModeChanged"], changes
    assert not [t for _, t in list(px4.texts) if "Disarmed" in t], px4.texts
    print(f"\n{stopped}\n{changes}")
