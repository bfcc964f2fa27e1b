"""A fleet split in two and healed (docs/OPERATIONS.md, "A fleet"): two zenoh routers whose
only link is cut silently, as a radio link fades, one member behind each. Apart, each side
plans on what it knows: the other is gone with its vehicle armed, so its users are free and
its route's points kept out. Healed, each reads what the other said and flew in between
(zenoh.ext's history and recovery, nothing replayed by hand) and both agree again on who owns
each user, by the one rule."""

from __future__ import annotations

import time
from typing import Any, Iterator

import pytest
import zenoh

from planner_service.model.fleet.claims import PLANNED, owner
from planner_service.harness.processes import free_port
from protocol import FleetKeys, Status
from protocol.messages import FleetServed
from protocol.zenoh_config import session_config
from tests.support.fleet import member, presence, put_position, wait_until
from tests.support.link_cut import LinkCut

KEYS = FleetKeys("partitiontest")
DISCOVERY_S = 0.5
LEASE_MS = 2000
"""The routers' lease (zenoh's default is 10 s): a silent cut is seen within it."""
APART_S = 30.0
"""How long each side may take to see the other gone (a lease, on a slow machine) or back
(a reconnection try, at most every second, then the routers' exchange)."""


def router(listen: int, connect: int | None = None) -> Any:
    conf = session_config("router", listen=[f"tcp/127.0.0.1:{listen}"],
                          connect=[f"tcp/127.0.0.1:{connect}"] if connect else [])
    conf.insert_json5("transport/link/tx/lease", str(LEASE_MS))
    # a handshake begun while the link is cut must not hold the retry for zenoh's 10 s
    conf.insert_json5("transport/unicast/open_timeout", str(LEASE_MS))
    conf.insert_json5("transport/unicast/accept_timeout", str(LEASE_MS))
    conf.insert_json5("scouting/gossip/enabled", "false")  # the two sides meet through the link only
    return zenoh.open(conf)


def client(port: int) -> Any:
    conf = session_config("client", connect=[f"tcp/127.0.0.1:{port}"])
    conf.insert_json5("timestamping/enabled", "true")
    return zenoh.open(conf)


@pytest.fixture
def sides() -> Iterator[tuple[Any, Any, LinkCut]]:
    """Router A, router B connected to A through a ``LinkCut``, a client session on each."""
    a_port, b_port = free_port(), free_port()
    a_router = router(a_port)
    link = LinkCut(a_port)
    b_router = router(b_port, link.port)
    a_session, b_session = client(a_port), client(b_port)
    try:
        yield a_session, b_session, link
    finally:
        for closing in (a_session, b_session, b_router, a_router):
            closing.close()
        link.close()


def armed(session: Any, vehicle: str, x_m: float) -> None:
    """The member's signed position, as its service publishes it: its vehicle armed, in flight."""
    put_position(session, KEYS, Status(vehicle=vehicle, armed=True, x_m=x_m, z_m=100.0))


def test_a_fleet_split_in_two_plans_on_what_each_side_knows_and_agrees_once_healed(sides: Any) -> None:
    a_session, b_session, link = sides
    a = presence(KEYS, member("uav1", 100.0))
    a.join(a_session, DISCOVERY_S)
    b = presence(KEYS, member("uav2", 110.0))
    b.join(b_session, DISCOVERY_S)
    a_heard: list[FleetServed] = []
    b_heard: list[FleetServed] = []

    def both_seen() -> bool:
        armed(a_session, "uav1", 0.0)
        armed(b_session, "uav2", 60.0)
        return a.check_separation().unknown == () and b.check_separation().unknown == ()
    wait_until(both_seen, APART_S, "each member sees the other's vehicle armed")
    t = time.time()  # a claim's due lies within a flight of its signed time
    b.ledger.intend({"u": t + 100, "v": t + 200}, t, claims=["u"], points=[3], route=[3, 5])
    a.ledger.intend({"w": t + 50}, t, claims=["w"], points=[4], route=[4, 6])
    wait_until(lambda: a.ledger.owners() == {"u": "uav2"} and b.ledger.owners() == {"w": "uav1"}, APART_S,
               lambda: f"each reads the other's claims: {a.ledger.owners()}, {b.ledger.owners()}")
    assert a.ledger.blocked_points() == {3} and b.ledger.blocked_points() == {4}

    link.cut()
    wait_until(lambda: list(a.members()) == ["uav1"] and list(b.members()) == ["uav2"], APART_S,
               lambda: f"each side sees the other gone: {list(a.members())}, {list(b.members())}")
    # apart, each plans on what it knows: the other's users free, its airspace (the route its
    # vehicle was flying when last seen armed) kept out until it is heard again
    assert a.roster.lost() == ["uav2"] and b.roster.lost() == ["uav1"]
    assert a.ledger.taken() == set() and b.ledger.taken() == set()
    assert a.ledger.blocked_points() == {3, 5} and b.ledger.blocked_points() == {4, 6}
    a.ledger.intend({"w": t + 50, "u": t + 150}, t + 1, claims=["w", "u"], points=[7], route=[7, 4, 6])
    a.ledger.served("w", 4, 60.0)  # each serves a user the other heard it claim (any other is not counted)
    b.ledger.served("u", 3, 61.0)
    b.ledger.intend({"u": t + 100}, t + 1, claims=["u"], points=[3], route=[3])

    link.heal()
    wait_until(lambda: list(a.members()) == list(b.members()) == ["uav1", "uav2"], APART_S,
               lambda: f"each side sees the other back: {list(a.members())}, {list(b.members())}")

    def heard() -> bool:
        a_heard.extend(a.ledger.take_served())
        b_heard.extend(b.ledger.take_served())
        return bool(a_heard) and bool(b_heard)
    # what each flew while apart reaches the other: its backlog and fairness count it
    wait_until(heard, APART_S, lambda: f"the services flown apart: {a_heard}, {b_heard}")
    assert a_heard == [FleetServed(vehicle="uav2", user_id="u", tasks=3, at_s=61.0)]
    assert b_heard == [FleetServed(vehicle="uav1", user_id="w", tasks=4, at_s=60.0)]
    # ...and so does what each said: its last intentions (a cache of one), which claim u on both sides
    wait_until(lambda: a.ledger.intentions().get("uav2") == {"u": t + 100}
               and b.ledger.intentions().get("uav1") == {"w": t + 50, "u": t + 150}, APART_S,
               lambda: f"the intentions said apart: {a.ledger.intentions()}, {b.ledger.intentions()}")
    # both claimed u apart; healed, both sides give it to the same member: uav2's claim is earlier
    assert b.ledger.claims()["uav1"] == {"w": (PLANNED, t + 50), "u": (PLANNED, t + 150)}
    assert owner("u", a.ledger.claims()) == owner("u", b.ledger.claims()) == "uav2"
    assert a.ledger.owners() == {"u": "uav2"} and b.ledger.owners() == {"w": "uav1"}
    # nobody is lost any more: only the points the other claims now are kept out
    assert a.roster.lost() == [] and b.roster.lost() == []
    assert a.ledger.blocked_points() == {3} and b.ledger.blocked_points() == {7}
    a.leave()
    b.leave()
