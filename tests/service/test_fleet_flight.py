"""A fleet in flight on loopback: two vehicle stubs, two services (one per UAV, each its own
journal and layer), two meshed zenoh routers and simulated users who submit once to the fleet
(``sim_bridge users --fleet``). Nothing central: the services share the user space through
their intentions and services (``planner_service.service.fleet.ledger``).

Proves: every request is held by every live member; both UAVs serve; no user is served more
often than the fairness rule allows across the fleet; a service killed mid-sortie leaves its
users to the other, which serves them, and each of them sees its place move there
(``PlannerClient.follow_fleet_place``); a router killed costs no request (the users and the
services reach the other)."""

from __future__ import annotations

import csv
import signal
import time
from collections import Counter

import pytest

from planner_service.model.fleet.claims import owner
from planner_service.model import field
from planner_service.service.config import build_config
from protocol import Keys
from protocol.client import PlannerClient, request_for
from protocol.fleet_places import FleetPlaces
from tests.support.fleet import wait_until
from tests.support.fleet_stack import Arrivals, FleetStack, Intentions, Uav

SPEEDUP = "20"
DEFAULTS = build_config({}, {})
INTERVAL_S = DEFAULTS.scenario().task_arrival_period_s
"""One interval of the service's scenario, vehicle seconds."""
SETTLE_S = DEFAULTS.fleet.settle_max_s / float(SPEEDUP)
"""The fleet's wait for a claim to settle, as much flight as on the field (wall seconds at x1):
its default 10 s of wall time is 200 s of flight at x20, and a member on its way home when
the other's service died (its token gone within the wait: it may come back with new claims)
landed before its decision to serve the lost member's users had settled (a clean clone's
failure). On loopback the members hear each other in milliseconds, well within it."""
START = {"mavlink.start_mission": "true", "planner.min_requests": "3", "fleet.settle_max_s": f"{SETTLE_S:g}"}


def served_by(fleet: FleetStack) -> dict[str, Counter[str]]:
    """vehicle -> user -> services, from each UAV's own journal."""
    return {v: Counter(user for user, _ in uav.services()) for v, uav in fleet.uavs.items()}


def check_fairness(fleet: FleetStack) -> None:
    """No user served more often across the fleet than the fairness rule allows."""
    limit = field().max_services_per_user
    total: Counter[str] = Counter()
    for counts in served_by(fleet).values():
        total.update(counts)
    over = {u: n for u, n in total.items() if n > limit}
    assert not over, f"served beyond the fairness rule ({limit}): {over}; {served_by(fleet)}"


@pytest.mark.timeout(300)
def test_two_uavs_share_the_users_and_one_takes_over_a_lost_ones(fleet: FleetStack) -> None:
    uav1 = fleet.uav("uav1", 100.0, SPEEDUP, **START)
    uav2 = fleet.uav("uav2", 120.0, SPEEDUP, home_east_m=60.0, **START)
    wait_until(lambda: "fleet: uav2 announced layer 120 m" in uav1.service.log(), 30.0, "uav1 hearing of uav2")
    wire = Intentions(fleet.endpoints[1], fleet.roster)
    arrivals = Arrivals(fleet.endpoints[1])
    try:
        fly_and_lose_one(fleet, uav1, uav2, wire, arrivals)
    finally:
        arrivals.close()
        wire.close()


def fly_and_lose_one(fleet: FleetStack, uav1: Uav, uav2: Uav, wire: Intentions, arrivals: Arrivals) -> None:
    # each user follows its place across the fleet from the start (the subscriptions are long
    # in place when the plans that matter come), and uav1's plans are read as they go out
    follower = PlannerClient([fleet.endpoints[1]], keys=Keys(vehicle="uav1"))
    try:
        places = Places(follower, {f"user-{i}" for i in range(8)})
        fly_lose_and_follow(fleet, uav1, uav2, wire, arrivals, places)
    finally:
        follower.close()


def fly_lose_and_follow(fleet: FleetStack, uav1: Uav, uav2: Uav, wire: Intentions, arrivals: Arrivals,
                        places: "Places") -> None:
    users = fleet.users("--count", "8", "--speedup", SPEEDUP, "--seed", "3")

    # every request held by both members: the users' requests in both journals
    def held_by_both() -> bool:
        ids = [set(u for (u,) in uav.rows("SELECT DISTINCT user_id FROM requests")) for uav in (uav1, uav2)]
        return len(ids[0]) == 8 and ids[0] == ids[1]
    wait_until(held_by_both, 60.0, lambda: f"every user's request in both journals\n{fleet.logs()}")

    # both fly and serve: the users are shared
    wait_until(lambda: all(served_by(fleet)[v] for v in ("uav1", "uav2")), 120.0,
               lambda: f"a service by each UAV: {served_by(fleet)}\n{fleet.logs()}")
    check_fairness(fleet)
    check_claimed_before_arrival(fleet, wire, arrivals)

    # a router dies: the members keep each other, a request still reaches both
    fleet.kill_router(0)
    time.sleep(3.0)
    for uav, other in ((uav1, "uav2"), (uav2, "uav1")):
        assert f"fleet: {other} left" not in uav.service.log(), f"{uav.vehicle} lost {other} with router 0"
    with PlannerClient([fleet.endpoints[1]]) as client:
        assert client.wait_for_fleet(10.0)
        answer = client.submit_to_fleet(request_for("probe-1", 250.0, 250.0, 12))
    # every member answers through router 1: an ack from each flying, a refusal from one landed
    assert answer.holders and len(answer.holders) + len(answer.refusals) == 2, answer

    # uav2's service dies mid-sortie: its users become uav1's
    wait_until(lambda: any(owner(u, wire.claims()) == "uav2" for u in wire.claims().get("uav2", {})), 30.0,
               lambda: f"uav2 claiming a user of its own: {wire.claims()}")
    claims = wire.claims()
    owned = {u for u in claims.get("uav2", {}) if owner(u, claims) == "uav2"}
    assert "over:" not in uav2.service.log(), "uav2 landed before its service could be killed in flight"
    uav2.service.proc.send_signal(signal.SIGKILL)
    lost_at = time.monotonic()
    wait_until(lambda: "fleet: uav2 left" in uav1.service.log(), 30.0, lambda: f"uav1 seeing uav2 go\n{fleet.logs()}")
    # the users' view: uav2's word forgotten once its token is gone (of the users followed:
    # uav2 may own the probe too)...
    followed = owned & places.followed.keys()
    wait_until(lambda: all("uav2" not in places.followed[u].members() for u in followed), 30.0,
               lambda: f"uav2's places forgotten: { {u: places.followed[u].members() for u in followed} }")
    take_over(fleet, uav1, uav2, wire, owned, lost_at)
    # ...and each of its users that uav1 planned since was told its place there (a user served
    # by a hold's binding, never planned, has no place to be told)
    planned = places.planned_by_uav1_since(lost_at)
    print(f"uav2's users in uav1's plans since: {sorted(owned & planned)}; their places, member after "
          f"member: { {u: places.moved[u] for u in sorted(owned)} }")
    for u in owned & planned:
        assert places.placed_by(u, "uav1"), (u, places.moved[u])
    check_fairness(fleet)
    for uav, layer in ((uav1, 100.0), (uav2, 120.0)):  # each cruised its own layer, by its own positions
        heights = Counter(round(z) for z, mode in track(uav) if mode == "AUTO" and z > 50.0)
        assert heights.most_common(1)[0][0] == layer and max(heights) <= layer + 1, (uav.vehicle, heights)
    # judged live on both statuses by each member (fleet.separation): never lost
    for uav in (uav1, uav2):
        assert "SEPARATION LOST" not in uav.service.log()
    assert users.stop() == 0
    assert uav1.service.stop() == 0


class Places:
    """What the users see of their places (``PlannerClient.follow_fleet_place``), beside what
    uav1's plans say (its ``plan`` publication): two publications of the service to hold
    against each other."""

    def __init__(self, client: PlannerClient, users: set[str]) -> None:
        self.moved: dict[str, list[str]] = {u: [] for u in users}
        """user -> the members that held its place (``where()``) in turn."""
        self._placed: dict[str, set[str]] = {u: set() for u in users}
        """user -> every member that ever said it plans the user."""
        self._plans: list[tuple[float, set[str]]] = []
        self.followed = {u: client.follow_fleet_place(u, self._note) for u in users}
        client.follow_plans(lambda plan: self._plans.append(
            (time.monotonic(), {p.user_id for p in plan.points if p.user_id})))

    def _note(self, places: FleetPlaces) -> None:
        self._placed[places.user_id] |= {v for v, p in places.members().items() if p.place is not None}
        here, seen = places.where(), self.moved[places.user_id]
        if here is not None and (not seen or seen[-1] != here.vehicle):
            seen.append(here.vehicle)

    def placed_by(self, user: str, vehicle: str) -> bool:
        return vehicle in self._placed[user]

    def planned_by_uav1_since(self, t: float) -> set[str]:
        return {u for at, users in list(self._plans) if at >= t for u in users}


def check_claimed_before_arrival(fleet: FleetStack, wire: Intentions, arrivals: Arrivals) -> None:
    """Issue 35, finding 1: a member claimed the point it held or had just left, never the
    point it flew to (three copters held together over one point). Every point a member
    arrived at was in its claims before it arrived: in its last intentions made more than
    50 ms before the arrival (the arrival's own, made as it binds the hold, do not count)."""
    for vehicle in fleet.uavs:
        said = wire.said(vehicle)
        for point, at in arrivals.of(vehicle):
            before = [m for m in said if m.time_s < at - 0.05]
            assert before and point in before[-1].points, (
                f"{vehicle} arrived at point {point} (t={at:.2f}) unclaimed: its claims then "
                f"{before[-1].points if before else None}; all: {[(round(m.time_s - at, 2), m.points) for m in said]}")


def take_over(fleet: FleetStack, uav1: Uav, uav2: Uav, wire: Intentions, owned: set[str], lost_at: float) -> None:
    """uav1 flies its sortie out after uav2's service was lost, and serves uav2's users (or
    leaves them out by a rule, never silently)."""
    served_before = len(uav1.services())

    # uav1 flies its sortie out; uav2's vehicle, its service gone, flies its uploaded mission home
    wait_until(lambda: "over:" in uav1.service.log(), 120.0, lambda: f"uav1's landing\n{fleet.logs()}")
    wait_until(lambda: landed(uav2), 120.0, lambda: f"uav2's vehicle home\n{uav2.stub.log()[-2000:] if uav2.stub else ''}")
    first = min((at for at, users in wire.since("uav1", lost_at) if users & owned), default=None)
    print(f"uav2 owned {sorted(owned)} when it was killed; uav1's first plan with them "
          f"{'-' if first is None else f'{first - lost_at:.2f}'} s wall after (one interval: "
          f"{INTERVAL_S / float(SPEEDUP):.2f} s)")
    after = {u for u, _ in uav1.rows(f"SELECT user_id, tasks FROM services WHERE service_id > {served_before}")}
    reasons = dict(uav1.rows("SELECT user_id, reason FROM requests WHERE status = 'not_served'"))
    print(f"of uav2's users, uav1 served {sorted(owned & after)}; not served: "
          f"{ {u: reasons[u] for u in sorted(owned - after) if u in reasons} }")
    # each of uav2's users served by uav1, or left out by the fleet-wide fairness rule (its
    # services by uav2 counted), or by the sortie's end: never silently dropped
    assert all(u in after or reasons.get(u) for u in owned), (owned, after, reasons)
    over = [line for line in uav1.service.log().splitlines() if "over:" in line]
    assert owned & after or all(reasons[u].startswith("fairness") for u in owned), (
        f"of uav2's {sorted(owned)} uav1 served none ({ {u: reasons.get(u) for u in owned} }); uav1's end: {over}")


def track(uav: Uav) -> list[tuple[float, str]]:
    """(height, mode) of every row of the vehicle's own flight log."""
    with open(uav.folder / "track.csv") as f:
        rows = list(csv.DictReader(f))
    return [(float(r["z_m"]), r["mode"]) for r in rows]


def landed(uav: Uav) -> bool:
    with open(uav.folder / "track.csv") as f:
        rows = list(csv.DictReader(f))
    return len(rows) > 10 and rows[-1]["armed"] == "0" and float(rows[-1]["z_m"]) < 1.0 and \
        any(r["armed"] == "1" for r in rows)


@pytest.mark.timeout(240)
def test_a_uav_that_joins_mid_sortie_takes_a_share(fleet: FleetStack) -> None:
    """uav1 flies the users alone; uav2 joins after uav1's first service, reads the requests
    its users send from then on, claims users uav1 does not, and serves some: the fleet rule
    (fairness across both journals) holds."""
    uav1 = fleet.uav("uav1", 100.0, SPEEDUP, **START)
    users = fleet.users("--count", "8", "--speedup", SPEEDUP, "--seed", "5")
    wait_until(lambda: bool(uav1.services()), 60.0, lambda: f"uav1's first service\n{fleet.logs()}")
    uav2 = fleet.uav("uav2", 120.0, SPEEDUP, home_east_m=60.0, **{**START, "planner.min_requests": "1"})
    wait_until(lambda: bool(uav2.services()), 90.0,
               lambda: f"a service by uav2, joined mid-sortie: {served_by(fleet)}\n{fleet.logs()}")
    print(f"joined mid-sortie: {served_by(fleet)}")
    check_fairness(fleet)
    assert users.stop() == 0
