"""A fleet on the real autopilot: three ArduCopter SITL instances (each its own home, 40 m
apart, and instance number), three services (docs/sitl-copter.toml, each its own layer,
journal and SITL), two meshed routers and the simulated users submitting to the fleet.

Proves: every service recorded by each member is borne out by that vehicle's own dataflash
log (``tests/support/truth.py``); no user served beyond the fairness rule across the fleet;
separation never lost as each member judged it live; one service killed mid-sortie, its
SITL flies its uploaded mission home and lands, and its users are taken over (served by
another member, or left out with a reason in its journal)."""

from __future__ import annotations

import signal
import time
import tomllib
from collections import Counter
from pathlib import Path
from typing import Callable

import pytest

from planner_service.model.fleet.claims import owner
from planner_service.harness.fleet_demo import OFFLINE_ALGO, fleet_of, offline_fleet, scenario_settings
from planner_service.harness.report import sortie_summary
from planner_service.model.fleet import uav_scenarios
from planner_service.service.config import load_config
from planner_service.service.fleet.airspace import separation_lost
from planner_service.service.journal import Journal
from tests.support.fleet import wait_until
from tests.support.fleet_stack import FleetStack, Intentions, Positions, Uav, home
from tests.support.sitl import Sitl, free_instance
from tests.support.truth import false_services, recorded_services, sitl_track
from tests.support.turn import TURN_WAIT_S

pytestmark = [pytest.mark.sitl, pytest.mark.timeout(600 + TURN_WAIT_S), pytest.mark.usefixtures("heavy_turn")]

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "docs" / "sitl-copter.toml"
PARAMS = REPO / "docs" / "sitl-copter.parm"
INSTANCES = range(40, 50)
SPEEDUP = 10
LAYERS_M = (40.0, 60.0, 80.0)
HOME_STEP_M = 40.0
TOLERANCE_S = 1.0
"""As test_sortie_sitl.py's: the service's rounding of a hold, not a false service."""
USERS = 10
FLOWN_TO_OFFLINE = 0.9
"""The fleet flown on SITL against the offline fleet planner: issue 35's target (issue 27 asked 0.8)."""


def sitl_settings() -> dict[str, str]:
    """docs/sitl-copter.toml as settings (its scenario fitted to SITL's copter)."""
    with open(CONFIG, "rb") as handle:
        raw = tomllib.load(handle)
    return {f"{section}.{key}": str(value).lower() if isinstance(value, bool) else str(value)
            for section, values in raw.items() for key, value in values.items() if key != "url"}


def fly_three(make_sitl: Callable[..., Sitl], fleet: FleetStack,
              layers: dict[int, dict[str, str]] | None = None) -> tuple[list[Sitl], list[Uav]]:
    """Three SITL copters (homes ``HOME_STEP_M`` apart) and their services, on
    docs/sitl-copter.toml with layers ``LAYERS_M`` (or each UAV's ``scenario.*`` settings of
    ``layers``), waiting for ten requests each."""
    copters = []
    for j in range(3):
        sitl = make_sitl(instance=free_instance(INSTANCES), speedup=SPEEDUP, defaults=(PARAMS,),
                         home=home(j * HOME_STEP_M) + ",0")
        copters.append(sitl)
    for sitl in copters:
        sitl.wait_ready(120.0)
    base = sitl_settings()
    uavs: list[Uav] = []
    for j, (sitl, layer) in enumerate(zip(copters, LAYERS_M)):
        own = layers[j] if layers is not None else {"scenario.altitude_m": str(layer), "scenario.base_z_m": str(layer),
                                                    "scenario.base_x_m": str(j * HOME_STEP_M)}
        settings = {**base, **own, "planner.min_requests": "10", "planner.seed": str(j + 1), "sortie.repeat": "false"}
        uavs.append(fleet.uav(f"uav{j + 1}", layer, str(SPEEDUP), autopilot=sitl.url(1), **settings))
    return copters, uavs


def stop_all(fleet: FleetStack, copters: list[Sitl]) -> None:
    for child in reversed(fleet.children):
        child.stop()
    for sitl in copters:
        sitl.stop()  # flushes the dataflash log


def check_truth(uavs: list[Uav], copters: list[Sitl], positions: Positions) -> None:
    """Every service borne out by its own copter's log, separation never lost (as each member
    judged it live, and on the copters' own positions side by side), no two copters over one
    point, no user served beyond the fairness rule across the fleet."""
    cfg = load_config(uavs[0].folder / "planner.toml")
    lost = [p for p in positions.pairs() if separation_lost(p[3], p[4], cfg.fleet.min_horizontal_m,
                                                              cfg.fleet.vertical_separation_m)]
    assert not lost, f"separation lost on the copters' own positions: {lost[:10]}"
    # two copters holding over one point (issue 35, finding 1): each within the hold radius of
    # it, longer than a copter takes to pass over another's point (0.1 s of wall at x10)
    assert not positions.stacked(2 * cfg.safety.hold_radius_m, 1.0), positions.stacked(2 * cfg.safety.hold_radius_m, 1.0)
    assert len(positions.pairs()) > 100, "the copters' positions were not heard side by side"
    total: Counter[str] = Counter()
    for uav, sitl in zip(uavs, copters):
        cfg = load_config(uav.folder / "planner.toml")
        track = sitl_track(sitl.read_log(("POS",)), cfg.origin_point())
        recorded = recorded_services(uav.journal)
        false = false_services(recorded, track, cfg.scenario(), cfg.safety.hold_radius_m, TOLERANCE_S)
        assert not false, f"{uav.vehicle}: services its SITL's log does not bear out:\n" + "\n".join(false)
        total.update(user for user, _ in uav.services())
        assert "SEPARATION LOST" not in uav.service.log()
    limit = load_config(uavs[0].folder / "planner.toml").scenario().max_services_per_user
    assert all(n <= limit for n in total.values()), total


def test_three_copters_share_the_users_and_take_over_a_lost_ones(make_sitl: Callable[..., Sitl],
                                                                  fleet: FleetStack) -> None:
    copters, uavs = fly_three(make_sitl, fleet)
    config = load_config(uavs[0].folder / "planner.toml")
    wire = Intentions(fleet.endpoints[1], fleet.roster)
    positions = Positions(fleet.endpoints[1], fleet.roster)
    try:
        fleet.users("--count", str(USERS), "--speedup", str(SPEEDUP), "--seed", "1", *config.scenario_arguments())
        # uav3's service dies while it claims a user, a service of its own flown; its copter
        # flies its mission home. (Not once every copter has served: on a clean clone uav3 had
        # served its last user by then and claimed nothing more, 120 s.)
        lost = uavs[2]
        wait_until(lambda: lost.services() and any(owner(u, wire.claims()) == "uav3"
                                                   for u in wire.claims().get("uav3", {})), 300.0,
                   lambda: f"uav3 serving and claiming a user: {lost.services()}, {wire.claims()}\n{fleet.logs()}")
        claims = wire.claims()
        owned = {u for u in claims.get("uav3", {}) if owner(u, claims) == "uav3"}
        done_before = {u.vehicle: len(u.services()) for u in uavs}
        lost.service.proc.send_signal(signal.SIGKILL)
        lost_at = time.monotonic()
        copters[2].wait_text(r"Disarming motors", 300.0)
        for uav in uavs[:2]:
            wait_until(lambda uav=uav: "over:" in uav.service.log(), 300.0,
                       lambda uav=uav: f"{uav.vehicle}'s landing\n{uav.service.log()[-3000:]}")
        first = min((at for v in ("uav1", "uav2") for at, users in wire.since(v, lost_at) if users & owned),
                    default=None)
    finally:
        wire.close()
        positions.close()
    stop_all(fleet, copters)
    check_truth(uavs, copters, positions)
    assert all(uav.services() for uav in uavs), f"a service by each copter: {[uav.services() for uav in uavs]}"

    # uav3's users served by the others after its loss, or left out with a reason
    after = {u for uav in uavs[:2] for u, _ in uav.services()[done_before[uav.vehicle]:]}
    reasons = {u: r for uav in uavs[:2] for u, r in uav.rows("SELECT user_id, reason FROM requests "
                                                            "WHERE status = 'not_served'")}
    assert all(u in after or reasons.get(u) for u in owned), (owned, after, reasons)
    print(f"\nservices {[len(u.services()) for u in uavs]} (0 false); uav3 owned {sorted(owned)} when killed; "
          f"first plan of the others with them {'-' if first is None else f'{first - lost_at:.2f}'} s wall after "
          f"(one interval {config.scenario().task_arrival_period_s / SPEEDUP:.1f} s); served after by the others: "
          f"{sorted(owned & after)}")


@pytest.mark.slow
def test_three_copters_fly_near_the_offline_fleet_planner(make_sitl: Callable[..., Sitl], fleet: FleetStack) -> None:
    """The fleet's throughput on SITL against the offline fleet planner (``claims``) on the
    same scenario, fleet layout and seed, its users' tasks arriving in time as the simulated
    users' do: at least ``FLOWN_TO_OFFLINE`` (the issue's target), every service borne out by
    the copters' own logs. Slow (a whole sortie of three copters: about a minute of wall); the
    figure is docs/PERFORMANCE.md's: ``pytest -s -m slow -k offline_fleet tests/service/test_fleet_sitl.py``."""
    base = load_config(CONFIG).scenario()
    layout = fleet_of(3)
    assert (layout.layer_m, layout.base_step_m) == (LAYERS_M[1] - LAYERS_M[0], HOME_STEP_M)
    scenarios = uav_scenarios(base, layout)
    copters, uavs = fly_three(make_sitl, fleet, {j: scenario_settings(base, sc) for j, sc in enumerate(scenarios)})
    config = load_config(uavs[0].folder / "planner.toml")
    positions = Positions(fleet.endpoints[1], fleet.roster)
    try:
        fleet.users("--count", str(USERS), "--speedup", str(SPEEDUP), "--seed", "1", *config.scenario_arguments())
        for uav in uavs:
            wait_until(lambda uav=uav: "over:" in uav.service.log(), 600.0,
                       lambda uav=uav: f"{uav.vehicle}'s landing\n{uav.service.log()[-3000:]}")
    finally:
        positions.close()
    stop_all(fleet, copters)
    check_truth(uavs, copters, positions)

    per_uav = []
    for uav, sc in zip(uavs, scenarios):
        journal = Journal(uav.journal)
        try:
            per_uav.append(sortie_summary(journal, sc, None)["throughput_tasks_per_interval"])
        finally:
            journal.close()
    flown = sum(per_uav)
    offline = offline_fleet(base, USERS, layout, 1, config.planner.budget_ms)
    ratio = flown / offline["throughput_tasks_per_interval"]
    print(f"\nflown {flown:.1f} tasks/interval (per UAV {[round(t, 1) for t in per_uav]}, services "
          f"{[len(u.services()) for u in uavs]}) against the offline {OFFLINE_ALGO} planner's "
          f"{offline['throughput_tasks_per_interval']:.1f}: {ratio:.2f}")
    assert ratio >= FLOWN_TO_OFFLINE, (flown, offline)
