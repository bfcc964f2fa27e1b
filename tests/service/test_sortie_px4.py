"""Whole sorties of the service on a real PX4 (PX4 SITL 1.18 with its SIH quadcopter,
tests/support/px4.py), with each MAVLink backend: the service (``python -m planner_service
serve`` with docs/sitl-px4.toml, arming and starting the mission itself) on PX4's onboard
link, ``sim_bridge users`` at PX4's speed factor, and every service the journal records held
against PX4's own position reports, which the harness's monitor receives on another link
(PX4's ground-station link: ``Px4.fixes``, ``tests/support/truth.py``'s ``px4_track``).

**The aircraft.** PX4's simulated battery drains at one rate while armed, whatever the
motors do (SIM_BAT_DRAIN), and stops at 50 % unless told; docs/sitl-px4.params makes it the
scenario's 100 kJ pack at the field preset's 168.5 W, down to 0, and the cruise 10 m/s;
docs/sitl-px4.toml's scenario flies 40 m high at 10 m/s with the same power cruising as
hovering (docs/OPERATIONS.md, "Flying PX4 SITL").

**The pilot** is a second station on PX4's payload link (onboard mode, ``Px4.spare_url``):
armed, PX4 refuses POSCTL and MANUAL without a manual control input (no RC in SITL), so the
pilot's takeover is Hold (AUTO.LOITER) and then Land, which a pilot's switch or a ground
station gives alike.

The figures (``-s``): services, false services, uploads, decisions per service, tasks per
interval flown against the offline planner on the same scenario (its mean over seeds)."""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from planner_service.mcts import MctsConfig
from planner_service.service.config import ServiceConfig, load_config
from planner_service.service.planning import Planner
from planner_service.service.sortie import item_from_dict
from protocol.autopilot import PX4
from protocol.mission import max_points
from sim_bridge.vehicle.mission_id import px4_mission_id
from tests.support.autopilot_sortie import BUDGET_MS, check_requests_and_missions, decisions, event_at
from tests.support.autopilot_sortie import fly as fly_with
from tests.support.autopilot_sortie import EXPECTED_SEEDS, logged_at, offline, offline_expected, service_log
from tests.support.gcs import M, GroundStation
from tests.support.px4 import PARAMS, Px4, free_instance, read_params
from tests.support.stack import Stack
from tests.support.truth import false_services, px4_track, recorded_services
from tests.support.turn import TURN_WAIT_S

pytestmark = [pytest.mark.sitl, pytest.mark.timeout(300 + TURN_WAIT_S)]

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "docs" / "sitl-px4.toml"
SPEED = 10
BACKENDS = [pytest.param("pymavlink", marks=pytest.mark.slow), "mavsdk"]
"""The whole sortie with each backend; with pymavlink (60 s) under ``-m slow``, to keep `make
test` under 15 minutes: pymavlink flies PX4 in the suite in the restart and the pilot's hold
below, and its whole sortie on ArduCopter (test_sortie_sitl.py), as MAVSDK's whole sortie is
flown here and on ArduCopter only under ``-m slow``."""
TOLERANCE_S = 1.0
"""A hold is judged from GLOBAL_POSITION_INT (0.1 s apart in PX4's clock on both links) and
recorded whole when it came within 0.5 s of what the request needs (sortie/machine.py)."""
LOITER, LAND = PX4.mode_number("AUTO.LOITER"), PX4.mode_number("AUTO.LAND")


@pytest.fixture(scope="module")
def kernels() -> None:
    """The planner's kernels compiled before a service starts (test_sortie_sitl.py's reason)."""
    config = load_config(CONFIG)
    Planner(config.scenario(), MctsConfig(budget_ms=BUDGET_MS), 0, max_points(512, "px4"), "mcts").warm_up()


@pytest.fixture
def quad(make_px4: Callable[..., Px4], kernels: None) -> Px4:
    """PX4 SITL with docs/sitl-px4.params at x10, its pre-arm checks passed."""
    px4 = make_px4(instance=free_instance(), speed=SPEED, params=read_params(PARAMS))
    px4.wait_ready()
    return px4


def fly(stack: Stack, px4: Px4, backend: str, **settings: str) -> ServiceConfig:
    """docs/sitl-px4.toml's service on PX4's onboard link and the simulated users, started."""
    return fly_with(stack, CONFIG, px4.url, backend, SPEED, **settings)


def stop_all(stack: Stack, px4: Px4) -> None:
    for child in reversed(stack.children):
        assert child.stop() == 0, f"{child.name}: {child.log()[-2000:]}"
    px4.stop()


def check_truth(stack: Stack, px4: Px4, config: ServiceConfig) -> int:
    """Every service of the journal borne out by PX4's own position reports, within the
    service's hold radius: the number of services."""
    track = px4_track(px4.fixes, config.origin_point())
    assert track, "PX4 sent the monitor no position"
    recorded = recorded_services(stack.journal_path)
    false = false_services(recorded, track, config.scenario(), config.safety.hold_radius_m, TOLERANCE_S)
    assert not false, "services PX4's own positions do not bear out:\n" + "\n".join(false)
    return len(recorded)


def modes_since(px4: Px4, since: float) -> list[str]:
    """PX4's modes (names) in its heartbeats to the monitor since ``since``, each change once."""
    names: list[str] = []
    for at, custom_mode, _ in list(px4.heartbeats):
        name = PX4.mode_name(custom_mode)
        if at >= since and (not names or names[-1] != name):
            names.append(name)
    return names


@pytest.mark.parametrize("backend", BACKENDS)
def test_whole_sortie(quad: Px4, stack: Stack, backend: str) -> None:
    """One sortie from the ground to the landing on PX4: at least 4 services (as on ArduCopter
    SITL), each borne out by PX4's own positions; replacements uploaded in flight, every
    accepted mission the one PX4 names (MISSION_CURRENT's mission_id is the CRC32 of an upload
    of ours); the landing ends the sortie with no authority ended (PX4's mission RTL hands it
    to AUTO.RTL, and back to an earlier mode after the landing's disarming); at least 80 % of
    the offline planner's tasks per interval on the same scenario (its mean over seeds:
    ``offline_expected``; one seed's figure is one draw of the users' world). How many services the pack
    holds depends on the wall clock: at x10 every tenth of a second the service and the
    planner take (100 ms a decision) is a second of PX4's hover, so on a quiet machine it
    serves 6 (the issue's demo target, measured in the demo) and 5 beside two other test
    processes; the count is printed."""
    px4 = quad
    config = fly(stack, px4, backend, sortie__repeat="false")
    scenario = config.scenario()
    started = time.monotonic()
    stack.wait_event(lambda e: e.event == "landed", 200.0, "the landing")
    wall_s = time.monotonic() - started
    stack.wait_disarmed(30.0)
    time.sleep(1.0)  # PX4's switch back to an earlier mode after the landing's disarming
    assert not [e.detail for e in stack.events if e.event == "authority_revoked"]
    stop_all(stack, px4)

    services = check_truth(stack, px4, config)
    assert services >= 4, stack.rows("SELECT user_id, tasks FROM services")
    ((ended, why),) = stack.rows("SELECT ended_at_s, why FROM sorties")
    assert ended is not None and why == "the vehicle landed", (ended, why)
    check_requests_and_missions(stack, config, "px4")
    events = stack.events
    in_flight = [e for e in events if e.event == "mission_uploaded" and "after item" in e.detail]
    assert in_flight, [e.detail for e in events if e.event == "mission_uploaded"]
    # PX4 named each mission it flew: every non-zero mission_id it reported is an upload of ours
    ours = {px4_mission_id([item_from_dict(i) for i in json.loads(items)])
            for (items,) in stack.rows("SELECT items FROM missions WHERE result = 'accepted'")}
    named = {mission_id for _, _, _, mission_id in px4.mission_ids if mission_id}
    assert named and named <= ours, (named, ours)
    assert not [e.detail for e in events if e.event == "returning" and "battery at" in e.detail]
    end = px4_track(px4.fixes[-1:], config.origin_point())[0].xyz
    assert math.hypot(*end[:2]) < 3.0 and abs(end[2]) < 1.0, end

    tasks = [t for (t,) in stack.rows("SELECT tasks FROM services ORDER BY service_id")]
    flown = float(np.mean(tasks))
    same_seed, world = offline(scenario, stack, 1)
    expected = offline_expected(scenario)
    ratio = flown / expected
    made = decisions(service_log(stack))
    print(f"\n{backend} on PX4 SITL x{SPEED}: {services} services, 0 false, {len(ours)} missions "
          f"({len(in_flight)} uploaded in flight), {made} decisions ({made / services:.2f} per service); "
          f"{flown:.2f} tasks/interval flown {tasks}; offline mcts {expected:.2f} over seeds 1-{EXPECTED_SEEDS} "
          f"(flown {ratio:.0%}), {same_seed['throughput_tasks_per_interval']:.2f} on seed 1, "
          f"{world['throughput_tasks_per_interval']:.2f} on the same first world; {wall_s:.0f} s wall")
    assert ratio >= 0.8, f"flown {flown:.2f} tasks/interval, {ratio:.0%} of the offline planner's {expected:.2f}"


def test_px4_killed_and_restarted_mid_flight(quad: Px4, stack: Stack) -> None:
    """PX4 killed (SIGKILL, as a power loss) during a hold and started again in its folder:
    ``link_lost``, the link back by itself, the restart seen, the mission read back as ours
    (PX4's dataman kept it), the vehicle on the ground at home (SIH starts there) so sortie 1
    is over, and sortie 2 waits for the operator (the restart ended the authority); over both
    boots nothing is recorded that PX4's positions do not bear out."""
    px4 = quad
    config = fly(stack, px4, "pymavlink")
    first = stack.wait_event(lambda e: e.event == "user_served", 150.0, "a first service")
    stack.wait_event(lambda e: e.event == "waypoint_reached" and e.time_s > first.time_s and "serving" in e.detail,
                     120.0, "the next hold")
    time.sleep(1.0)
    killed_at = time.time()
    px4.kill()
    lost_at = event_at(stack, "link_lost", killed_at)
    restart_at = time.time()
    px4.restart()
    back_at = event_at(stack, "link_restored", restart_at)
    seen_at = event_at(stack, "vehicle_restarted", restart_at)
    over_at = event_at(stack, "landed", restart_at, "sortie 1")
    begun_at = event_at(stack, "sortie_started", restart_at, "sortie 2: authority none")
    # the read-back goes once the link is back and nothing else is in flight: on a busy
    # machine seconds after the new sortie began (a fixed 2 s missed it on a clean clone)
    deadline = time.monotonic() + 30.0
    while True:
        read_at = logged_at(service_log(stack), r"\(read back\)|re-planning from where it is", restart_at - 0.5)
        if read_at is not None or time.monotonic() > deadline:
            break
        time.sleep(0.5)
    time.sleep(2.0)
    log = service_log(stack)
    assert logged_at(log, r"mission started", restart_at) is None, "armed without the operator"
    stop_all(stack, px4)

    assert read_at is not None, "the mission was not read back after the restart"
    ((why,),) = stack.rows("SELECT why FROM sorties WHERE number = 1")
    assert "landed" in why, why
    cut = stack.rows(f"SELECT user_id FROM services WHERE sortie = 1 AND time_s >= {killed_at}")
    assert len(cut) <= 1, cut
    services = check_truth(stack, px4, config)
    print(f"\nPX4 killed in a hold: link_lost {lost_at - killed_at:.2f} s after; from its restart: link back "
          f"{back_at - restart_at:.1f} s, restart seen {seen_at - restart_at:.1f} s, mission read back "
          f"{read_at - restart_at:.1f} s, sortie 1 over {over_at - restart_at:.1f} s, sortie 2 begun "
          f"{begun_at - restart_at:.1f} s; {services} services, 0 false")


def in_flight(stack: Stack, px4: Px4) -> tuple[ServiceConfig, GroundStation]:
    """The service flying its first sortie under its authority (a first service recorded),
    and a second station on PX4's payload link."""
    config = fly(stack, px4, "pymavlink")
    stack.wait_event(lambda e: e.event == "user_served", 150.0, "a first service")
    assert stack.client is not None and stack.client.state().status.authority == "operator"
    gcs = GroundStation(px4.spare_url)
    gcs.wait_vehicle()
    return config, gcs


def test_a_pilots_hold_ends_the_authority_and_after_the_pilots_landing_nothing_arms(quad: Px4,
                                                                                    stack: Stack) -> None:
    """The pilot always wins on PX4: in a sortie the service started, the pilot switches to
    Hold (AUTO.LOITER); the authority ends, the service commands no mode; the pilot lands
    (AUTO.LAND) and the service arms nothing. PX4's own heartbeats (to the monitor) are the
    judge: after the pilot's Hold only the pilot's modes, armed no more after the landing."""
    px4 = quad
    config, gcs = in_flight(stack, px4)
    try:
        took_over = time.monotonic()
        assert gcs.set_mode(*LOITER) == M.MAV_RESULT_ACCEPTED
        revoked = stack.wait_event(lambda e: e.event == "authority_revoked", 15.0, "the end of the authority")
        assert "AUTO.LOITER" in revoked.detail and "not commanded by the service" in revoked.detail, revoked.detail
        time.sleep(3.0)  # 30 s of PX4's time: the users go on asking, the service goes on planning
        assert gcs.set_mode(*LAND) == M.MAV_RESULT_ACCEPTED
        landed = stack.wait_event(lambda e: e.event == "landed", 120.0, "the pilot's landing")
        assert "sortie 1" in landed.detail, landed.detail
        time.sleep(3.0)
    finally:
        gcs.close()
    assert stack.client is not None
    status = stack.client.state().status  # (a next sortie may have begun: PX4's battery is full again)
    assert status.authority in ("revoked", "none") and not status.armed, status
    assert "the operator's start is awaited" in status.authority_detail, status.authority_detail
    stop_all(stack, px4)
    modes = modes_since(px4, took_over)
    if modes[:1] == ["AUTO.MISSION"]:
        modes = modes[1:]  # a heartbeat sent before the Hold took effect
    # the pilot's Hold and Land, then PX4's own return to the Hold at the landing's disarming
    assert modes[:2] == ["AUTO.LOITER", "AUTO.LAND"] and set(modes[2:]) <= {"AUTO.LOITER"}, modes
    armed = [a for at, _, a in px4.heartbeats if at >= took_over]
    assert False in armed and not any(armed[armed.index(False):]), "armed again after the pilot's landing"
    services = check_truth(stack, px4, config)
    print(f"\npilot on PX4: modes after the Hold {modes}; authority ended by {revoked.detail!r}; "
          f"{services} services, 0 false")


def test_a_second_stations_mission_is_named_by_px4_and_ends_the_authority_within_a_second(
        quad: Px4, stack: Stack) -> None:
    """Another station replaces the service's mission with one of the same length (ours,
    each point 55 m north): PX4 names the mission it holds (MISSION_CURRENT.mission_id, the
    CRC32), so the service knows it is not ours within a second; it neither replaces their
    mission nor commands anything after."""
    px4 = quad
    _, gcs = in_flight(stack, px4)
    try:
        ours = gcs.download()
        theirs = [replace(i, x=i.x + 5000) if i.x else i for i in ours]  # 5000e-7 degree: 55 m
        uploaded_at = time.time()
        t0 = time.monotonic()
        assert gcs.upload(theirs) == M.MAV_MISSION_ACCEPTED
        revoked = stack.wait_event(lambda e: e.event == "authority_revoked" and e.time_s >= uploaded_at, 20.0,
                                   "the end of the authority")
        delay = revoked.time_s - uploaded_at
        time.sleep(3.0)
        held = gcs.download()
    finally:
        gcs.close()
    assert "not ours" in revoked.detail or "mission_id" in revoked.detail, revoked.detail
    assert [(i.command, i.x, i.y) for i in held] == [(i.command, i.x, i.y) for i in theirs], "theirs was replaced"
    stop_all(stack, px4)
    assert modes_since(px4, t0) in (["AUTO.MISSION"], []), modes_since(px4, t0)
    print(f"\nsecond station on PX4: authority ended {delay:.2f} s after their upload ({revoked.detail[:120]})")
    assert delay < 1.0, f"{delay:.2f} s"
