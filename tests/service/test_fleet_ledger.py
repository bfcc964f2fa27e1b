"""The members' exchange in flight (``planner_service.fleet_ledger``), its rules on their own:
who owns a user several members claim, the points a member plans without, and what it keeps
of a member gone with its vehicle armed. Samples are made here as zenoh hands them over; the
exchange through real routers is tests/service/test_fleet_flight.py's and test_fleet_acl.py's."""

from __future__ import annotations

from dataclasses import dataclass, field

import zenoh

from planner_service.fleet_ledger import FleetLedger, bound_due, owned_by_others, owner
from protocol import FleetKeys
from protocol.messages import FleetIntentions, FleetServed, Intention, encode

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


def said(ledger: FleetLedger, message: FleetIntentions | FleetServed, vehicle: str | None = None) -> None:
    v = vehicle or message.vehicle
    if isinstance(message, FleetIntentions):
        ledger._on_intentions(Sample(KEYS.intentions(v), Payload(encode(message))))
    else:
        ledger._on_served(Sample(KEYS.served(v), Payload(encode(message))))


def test_the_earliest_claim_owns_a_user_and_a_hold_beats_any_estimate() -> None:
    claims = {"uav1": {"u": 100.0}, "uav2": {"u": 90.0}, "uav3": {"v": 5.0}}
    assert owner("u", claims) == "uav2" and owner("w", claims) is None
    assert owned_by_others("uav1", claims, ["uav1", "uav2", "uav3"]) == {"u": "uav2", "v": "uav3"}
    assert owned_by_others("uav1", claims, ["uav1", "uav3"]) == {"v": "uav3"}  # uav2 gone: its claim with it
    claims["uav1"]["u"] = bound_due(120.0)  # uav1 bound u (its hold began), though uav2 predicted earlier
    assert owner("u", claims) == "uav1"
    assert owner("u", {"uav2": {"u": 1.0}, "uav1": {"u": 1.0}}) == "uav1"  # a tie: the smaller id


def test_points_claimed_by_live_members_and_a_lost_members_route_are_planned_without() -> None:
    alive, lost = {"uav1", "uav2"}, set()
    ledger = FleetLedger(KEYS, "uav1", lambda: alive, lambda: lost)
    said(ledger, FleetIntentions(vehicle="uav2", time_s=0.0, users=[Intention("u", 10.0), Intention("v", 20.0)],
                                 claims=["u"], points=[3], route=[3, 5, 7]))
    ledger.intend({"w": 5.0}, 0.0, ["w"], [4], [4, 6])  # its own are never blocked for it
    assert ledger.taken() == {"u"} and ledger.owners() == {"u": "uav2"}
    assert ledger.blocked_points() == {3}
    alive.discard("uav2")
    lost.add("uav2")  # gone with its vehicle armed: it flies its mission home
    assert ledger.taken() == set() and ledger.blocked_points() == {3, 5, 7}
    lost.discard("uav2")  # back (or never armed): nothing kept
    assert ledger.blocked_points() == frozenset()


def test_a_member_speaks_for_itself_and_a_service_heard_twice_counts_once() -> None:
    ledger = FleetLedger(KEYS, "uav1", lambda: {"uav1", "uav2"})
    said(ledger, FleetIntentions(vehicle="uav3", time_s=0.0, users=[Intention("u", 1.0)], claims=["u"]), "uav2")
    assert ledger.taken() == set() and ledger.refused[-1].endswith("names vehicle 'uav3'")
    done = FleetServed(vehicle="uav2", user_id="u", tasks=4, at_s=10.0)
    said(ledger, done)
    said(ledger, done)  # history and live delivery
    said(ledger, FleetServed(vehicle="uav1", user_id="u", tasks=4, at_s=11.0))  # its own: not the others'
    assert ledger.take_served() == [done] and ledger.take_served() == []
