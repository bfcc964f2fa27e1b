"""The members' exchange in flight (``planner_service.service.fleet.ledger``), its rules on their own:
who owns a user several members claim, the points a member plans without, and what it keeps
of a member gone with its vehicle armed. Samples are made here as zenoh hands them over; the
exchange through real routers is tests/service/test_fleet_flight.py's and test_fleet_acl.py's."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import pytest
import zenoh

from planner_service.model.fleet.claims import BOUND, PLANNED, owned_by_others, owner
from planner_service.service.fleet.ledger import FleetLedger
from planner_service.service.fleet.roster import ANNOUNCE_STALE_S, FleetRoster
from planner_service.service.fleet.settle import ClaimSettling
from protocol import FleetKeys
from protocol.messages import FleetIntentions, FleetMember, FleetPosition, FleetServed, Intention, encode
from tests.support.fleet import member, signer, verifier

KEYS = FleetKeys("ledgertest")


@dataclass
class Payload:
    data: bytes

    def to_bytes(self) -> bytes:
        return self.data


@dataclass
class Sample:
    key_expr: str
    payload: Payload
    kind: zenoh.SampleKind = field(default_factory=lambda: zenoh.SampleKind.PUT)


T = time.time()


@pytest.fixture(autouse=True)
def now_for_each_test() -> None:
    """``T`` is the wall clock when each test starts, not when the module was imported: the
    claims' bounds and the signatures' freshness are judged against the reader's clock, and
    under ``make test`` a module runs minutes after it was collected."""
    global T
    T = time.time()
"""Wall clock at the tests' start: a claim's due is bounded by its signed time."""


def said(ledger: FleetLedger, message: FleetIntentions | FleetServed, vehicle: str | None = None) -> None:
    """``message`` signed by ``vehicle`` (its own by default) and handed over as zenoh would."""
    v = vehicle or message.vehicle
    key = KEYS.intentions(v) if isinstance(message, FleetIntentions) else KEYS.served(v)
    sample = Sample(key, Payload(signer(v).seal(key, encode(message), time.time())))
    if isinstance(message, FleetIntentions):
        ledger._on_intentions(sample)
    else:
        ledger._on_served(sample)


def ledger_of(vehicle: str, alive: set[str], lost: set[str] | None = None) -> FleetLedger:
    return FleetLedger(KEYS, vehicle, lambda: alive, lambda: lost or set(), None, verifier())


def test_the_earliest_claim_owns_a_user_and_a_hold_beats_any_estimate() -> None:
    claims = {"uav1": {"u": (PLANNED, 100.0)}, "uav2": {"u": (PLANNED, 90.0)}, "uav3": {"v": (PLANNED, 5.0)}}
    assert owner("u", claims) == "uav2" and owner("w", claims) is None
    assert owned_by_others("uav1", claims, ["uav1", "uav2", "uav3"]) == {"u": "uav2", "v": "uav3"}
    assert owned_by_others("uav1", claims, ["uav1", "uav3"]) == {"v": "uav3"}  # uav2 gone: its claim with it
    claims["uav1"]["u"] = (BOUND, 120.0)  # uav1 bound u (its hold began), though uav2 predicted earlier
    assert owner("u", claims) == "uav1"
    assert owner("u", {"uav2": {"u": (PLANNED, 1.0)}, "uav1": {"u": (PLANNED, 1.0)}}) == "uav1"  # a tie


def test_points_claimed_by_live_members_and_a_lost_members_route_are_planned_without() -> None:
    alive, lost = {"uav1", "uav2"}, set()
    ledger = ledger_of("uav1", alive, lost)
    said(ledger, FleetIntentions(vehicle="uav2", time_s=T, users=[Intention("u", T + 10), Intention("v", T + 20)],
                                 claims=["u"], points=[3], route=[3, 5, 7]))
    ledger.intend({"w": T + 5}, T, ["w"], [4], [4, 6])  # its own are never blocked for it
    assert ledger.taken() == {"u"} and ledger.owners() == {"u": "uav2"}
    assert ledger.blocked_points() == {3}
    alive.discard("uav2")
    lost.add("uav2")  # gone with its vehicle armed: it flies its mission home
    assert ledger.taken() == set() and ledger.blocked_points() == {3, 5, 7}
    lost.discard("uav2")  # back (or never armed): nothing kept
    assert ledger.blocked_points() == frozenset()


def test_of_two_members_holding_one_point_claimed_at_once_the_one_whose_id_sorts_first_keeps_it() -> None:
    """Each judges the same from the other's intentions: uav5 yields point 6 to uav3, uav3 to
    nobody; a point flown to by another that claimed it later, or held by a member gone, asks
    nothing, one flown to by a member that claimed it first ends the hold (before it arrives);
    a holding that is not one of the points claimed is not believed."""
    alive = {"uav3", "uav5", "uav7"}
    uav3, uav5 = ledger_of("uav3", alive), ledger_of("uav5", alive)
    uav3.intend({}, T, points=[6], holding=6)
    uav5.intend({}, T, points=[6], holding=6)
    said(uav5, FleetIntentions(vehicle="uav3", time_s=T, points=[6], holding=6))
    said(uav3, FleetIntentions(vehicle="uav5", time_s=T, points=[6], holding=6))
    assert uav5.yield_points() == {6: "uav3"} and uav3.yield_points() == {}
    said(uav5, FleetIntentions(vehicle="uav3", time_s=T + 1, points=[6], holding=None))  # flying to it
    assert uav5.yield_points() == {}
    said(uav5, FleetIntentions(vehicle="uav7", time_s=T + 1, points=[6], points_at_s=[T - 1]))  # claimed first
    assert uav5.yield_points() == {6: "uav7"}
    said(uav5, FleetIntentions(vehicle="uav7", time_s=T + 2, points=[4]))
    said(uav5, FleetIntentions(vehicle="uav3", time_s=T + 2, points=[2], holding=6))  # 6 not among its points
    assert uav5.yield_points() == {}
    said(uav5, FleetIntentions(vehicle="uav3", time_s=T + 3, points=[6], holding=6))
    alive.discard("uav3")
    assert uav5.yield_points() == {}


def test_of_members_that_claimed_one_point_the_first_to_claim_it_keeps_it_whatever_its_id() -> None:
    """Finding (20 UAVs over radios): uav6 claimed point 10, uav18 and uav13 claimed it 1.3
    and 1.9 s later (neither had heard uav6): the first id, uav13, kept it, and uav6 and uav18,
    arrived first, held it with it until they heard uav13's hold. Now the first to claim keeps
    it, by the claimants' own times carried in their claims; at the same time, the first id.
    Here uav2 claims first and uav1, whose id sorts first, 1.9 s later."""
    alive = {"uav2", "uav1", "uav3"}
    early, late = ledger_of("uav2", alive), ledger_of("uav1", alive)
    early.intend({}, T + 2, points=[10], points_at={10: T})
    late.intend({}, T + 2, points=[10], points_at={10: T + 1.9})
    said(early, FleetIntentions(vehicle="uav1", time_s=T + 2, points=[10], points_at_s=[T + 1.9]))
    said(late, FleetIntentions(vehicle="uav2", time_s=T + 2, points=[10], points_at_s=[T]))
    said(late, FleetIntentions(vehicle="uav3", time_s=T + 2, points=[10, 4], points_at_s=[T + 1.3, T + 1.3]))
    assert 10 not in early.blocked_points() and 10 in late.blocked_points()
    # both arrived before hearing the other: the later claimant ends its hold
    early.intend({}, T + 3, points=[10], holding=10, points_at={10: T})
    late.intend({}, T + 3, points=[10], holding=10, points_at={10: T + 1.9})
    said(early, FleetIntentions(vehicle="uav1", time_s=T + 3, points=[10], holding=10, points_at_s=[T + 1.9]))
    said(late, FleetIntentions(vehicle="uav2", time_s=T + 3, points=[10], holding=10, points_at_s=[T]))
    assert early.yield_points() == {} and late.yield_points() == {10: "uav2"}
    # a point's claim time is bounded as a flight's, and one per point at most
    said(late, FleetIntentions(vehicle="uav3", time_s=T + 4, points=[10], points_at_s=[T - 1e6]))
    assert late.refused[-1].endswith("from its signed time (not a flight's)"), late.refused[-1]
    said(late, FleetIntentions(vehicle="uav3", time_s=T + 4, points=[10], points_at_s=[T, T]))
    assert late.refused[-1].endswith("2 claim times for 1 points"), late.refused[-1]


def test_the_members_that_would_answer_a_new_request_are_those_on_their_way_home_that_say_so() -> None:
    """Of the members on their way home the nearest answers first (``sortie.fleet.answer_rank``):
    each says so in its signed intentions; one that claims a point is not answering whatever
    it says, one gone is not, and this member is not among the others."""
    alive = {"uav1", "uav2", "uav3", "uav4"}
    ledger = ledger_of("uav1", alive)
    ledger.intend({}, T, answering=True)
    said(ledger, FleetIntentions(vehicle="uav1", time_s=T, answering=True))  # its own, as if heard back
    said(ledger, FleetIntentions(vehicle="uav2", time_s=T, answering=True))
    said(ledger, FleetIntentions(vehicle="uav3", time_s=T, points=[5], answering=True))
    said(ledger, FleetIntentions(vehicle="uav4", time_s=T))
    assert ledger.answering() == {"uav2"}
    said(ledger, FleetIntentions(vehicle="uav2", time_s=T + 1, points=[7]))  # it answered
    said(ledger, FleetIntentions(vehicle="uav4", time_s=T + 1, answering=True))
    assert ledger.answering() == {"uav4"}
    alive.discard("uav4")
    assert ledger.answering() == set()


def test_a_member_speaks_for_itself_and_a_service_heard_twice_counts_once() -> None:
    ledger = ledger_of("uav1", {"uav1", "uav2"})
    said(ledger, FleetIntentions(vehicle="uav3", time_s=T, users=[Intention("u", T + 1)], claims=["u"]), "uav2")
    assert ledger.taken() == set() and ledger.refused[-1].endswith("names vehicle 'uav3'")
    said(ledger, FleetIntentions(vehicle="uav2", time_s=T, users=[Intention("u", T + 1)], claims=["u"]))
    done = FleetServed(vehicle="uav2", user_id="u", tasks=4, at_s=10.0)
    said(ledger, done)
    said(ledger, done)  # history and live delivery
    said(ledger, FleetServed(vehicle="uav1", user_id="u", tasks=4, at_s=11.0))  # its own: not the others'
    assert ledger.take_served() == [done] and ledger.take_served() == []


def test_a_member_claims_only_what_it_can_fly() -> None:
    """Issue 34, finding 5 on its own: a claim due 1e15 s early, more users or points than a
    next point and a hold, a bound time out of a hold's reach are refused whole (counted); a
    route is kept to its first ``MAX_ROUTE`` points; a service counts only for a user the
    member claimed."""
    from planner_service.service.fleet.ledger import MAX_ROUTE

    ledger = ledger_of("uav1", {"uav1", "uav2"})
    refused_before = ledger._verifier.ignored
    for bad in (FleetIntentions(vehicle="uav2", time_s=T, users=[Intention("u", -1e15)], claims=["u"]),
                FleetIntentions(vehicle="uav2", time_s=T, users=[Intention(u, T + 1) for u in "abc"],
                                claims=["a", "b", "c"]),
                FleetIntentions(vehicle="uav2", time_s=T, points=[1, 2, 3]),
                FleetIntentions(vehicle="uav2", time_s=T, bound="u", bound_at_s=T - 1e10)):
        said(ledger, bad)
    assert ledger.taken() == set() and ledger.claims() == {}
    assert ledger._verifier.ignored == refused_before + 4
    said(ledger, FleetServed(vehicle="uav2", user_id="u", tasks=9, at_s=T))  # never claimed: not counted
    assert ledger.take_served() == [] and "never claimed" in ledger.refused[-1]
    said(ledger, FleetIntentions(vehicle="uav2", time_s=T, users=[Intention("v", T + 30)], claims=["v"],
                                 bound="u", bound_at_s=T - 10, route=list(range(100))))
    assert ledger.claims()["uav2"] == {"v": (PLANNED, T + 30), "u": (BOUND, T - 10)}
    assert ledger._routes["uav2"] == set(range(MAX_ROUTE))
    said(ledger, FleetServed(vehicle="uav2", user_id="u", tasks=9, at_s=T))
    assert [d.user_id for d in ledger.take_served()] == ["u"]


def test_a_member_gone_armed_keeps_the_point_it_held_as_well_as_its_route() -> None:
    """Finding (20 UAVs over radios, 2026-12-07): uav15's session lost its router for 3 s and
    every member left its view; uav12, holding point 1 for 70 s, was lost with its vehicle
    armed and its route kept, but its route is the plan flown *after* the point held: uav15
    planned point 1 at once and held it beside uav12 for 6 s. A member gone armed keeps the
    points it last claimed (its hold's, its next) too."""
    alive, lost = {"uav1", "uav2"}, set()
    ledger = ledger_of("uav1", alive, lost)
    said(ledger, FleetIntentions(vehicle="uav2", time_s=T, users=[Intention("u", T + 10)], claims=["u"],
                                 points=[1, 5], holding=1, points_at_s=[T - 60, T], route=[5, 7]))
    assert ledger.blocked_points() == {1, 5}
    alive.discard("uav2")
    lost.add("uav2")
    assert ledger.blocked_points() == {1, 5, 7}
    lost.discard("uav2")
    assert ledger.blocked_points() == frozenset()


def test_a_member_gone_armed_stays_lost_until_it_has_announced_itself_again() -> None:
    """Found at 20 UAVs (x2.5, the machine saturated): uav19's token went with its vehicle
    armed and came back 6 s later; from its token's return until its announcement was heard
    again it was neither a member (its last announcement older than 10 s) nor lost (the
    token's return ended that), and uav9 planned the point uav19 was holding 53 ms after the
    token came back."""
    roster = FleetRoster(KEYS, verifier())

    def token(kind: zenoh.SampleKind) -> None:
        roster._on_token(Sample(KEYS.member("uav2"), Payload(b""), kind))

    def signed(key: str, message: FleetMember | FleetPosition) -> Sample:
        return Sample(key, Payload(signer("uav2").seal(key, encode(message), time.time())))

    def announce() -> None:
        roster._on_announce(signed(KEYS.announce("uav2"), member("uav2", 120.0)))
    token(zenoh.SampleKind.PUT)
    announce()
    roster._on_position(signed(KEYS.position("uav2"), FleetPosition(x_m=0.0, y_m=0.0, z_m=120.0, armed=True)))
    assert list(roster.members()) == ["uav2"] and roster.lost() == []
    token(zenoh.SampleKind.DELETE)
    assert roster.lost() == ["uav2"]
    roster._said_at["uav2"] -= ANNOUNCE_STALE_S  # its announcements stopped long before its token went
    token(zenoh.SampleKind.PUT)  # its session back: the token first
    assert roster.lost() == ["uav2"] and list(roster.members()) == [], "not announced since: still lost"
    time.sleep(0.01)  # (a later signed time: the replay rule takes the newest only)
    announce()
    assert list(roster.members()) == ["uav2"] and roster.lost() == []


def test_a_claim_settles_on_every_vehicle_that_may_be_a_member() -> None:
    """Found at 20 UAVs (x2.5): uav17's session stalled; the others' announcements went stale,
    so it had no members, and its claim on point 19 settled in 0.36 s: it flew to the point
    uav10 had claimed 8 s before (unheard by it). A claim settles on every enrolled token
    alive (silent ones too) and on every vehicle whose token went a moment ago."""
    roster = FleetRoster(KEYS, verifier())
    for v in ("uav2", "uav3"):
        roster._on_token(Sample(KEYS.member(v), Payload(b""), zenoh.SampleKind.PUT))
    assert roster.unsure(10.0) == {"uav2", "uav3"}, "no announcement heard: members or not, they may claim"
    roster._on_token(Sample(KEYS.member("uav3"), Payload(b""), zenoh.SampleKind.DELETE))
    assert roster.unsure(10.0) == {"uav2", "uav3"}, "uav3's token went a moment ago"
    roster._left_at["uav3"] -= 11.0
    assert roster.unsure(10.0) == {"uav2"}
    ledger = ledger_of("uav1", set())
    assert ledger.heard_since() == math.inf, "no member: nothing to wait for"
    assert ledger.heard_since(roster.unsure(10.0)) == -math.inf, "uav2 never heard"
    said(ledger, FleetIntentions(vehicle="uav2", time_s=T))
    assert T <= ledger.heard_since(roster.unsure(10.0)) <= time.time()


def test_a_claim_settles_on_the_vehicles_that_could_claim_when_it_was_made() -> None:
    """Found at 20 UAVs over radios (x2.5): uav1's radio was cut; it bound user-4 three seconds
    into the cut, the others' leases ran out 10 s later, and 10.07 s after their tokens went
    its binding settled on nobody, 0.4 s before it heard the fleet again and with it uav2's
    earlier binding of user-4: both recorded the service. A claim settles on every vehicle
    alive when it was made, however long ago its token went since."""
    roster = FleetRoster(KEYS, verifier())
    for v in ("uav2", "uav3", "uav4"):
        roster._on_token(Sample(KEYS.member(v), Payload(b""), zenoh.SampleKind.PUT))
    now = time.monotonic()
    for v in ("uav2", "uav3", "uav4"):
        roster._on_token(Sample(KEYS.member(v), Payload(b""), zenoh.SampleKind.DELETE))
    claimed_at = now - 13.0
    roster._left_at["uav2"] = now - 10.1  # its lease ran out 2.9 s after the claim
    roster._left_at["uav3"] = now - 16.0  # gone 3 s before the claim, out of the window since
    roster._left_at["uav4"] = now - 5.0  # gone a moment ago
    assert roster.unsure(10.0) == {"uav4"}, "the window alone: uav2 went more than 10 s ago"
    assert roster.unsure(10.0, claimed_at) == {"uav2", "uav4"}
    roster._on_token(Sample(KEYS.member("uav5"), Payload(b""), zenoh.SampleKind.PUT))
    assert roster.unsure(10.0, claimed_at) == {"uav2", "uav4", "uav5"}, "and every token alive now"
    # The service's judge of its claims, on the wall clock: a binding made 13 s ago has not
    # settled while uav2, uav4 and uav5 are unheard since.
    wall_claimed = time.time() - 13.0
    settling = ClaimSettling(roster, ledger_of("uav1", set()), within_s=10.0, margin_s=0.1)
    assert settling.waited_on(wall_claimed) == {"uav2", "uav4", "uav5"}
    assert not settling.settled(wall_claimed) and settling.unheard(wall_claimed) == ["uav2", "uav4", "uav5"]
    for v in ("uav2", "uav4", "uav5"):
        said(settling.ledger, FleetIntentions(vehicle=v, time_s=time.time()))
    assert settling.settled(wall_claimed) and settling.unheard(wall_claimed) == []
