"""The red team's findings against the fleet (issue 34, findings 1, 2, 4, 5, 6, 7), each played
as it was found, through real zenoh sessions on a loopback router, against real members
(``FleetPresence``: its roster and ledger): plain puts from any peer, a rogue token, forged
statuses, and a member whose key was stolen signing absurd claims in its own name. Each test
waits until the attack has reached the member (a witness subscriber on the member's own
session, which zenoh hands each sample after the member's, or the member's count of what it
ignored) and asserts the fleet unaffected."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any, Callable

import pytest
import zenoh
import zenoh.ext as zext

from planner_service.service.fleet.ledger import MAX_ROUTE
from planner_service.harness.processes import Child, free_port
from protocol import FleetKeys, Keys, Status, encode
from protocol.client import client_config
from protocol.messages import FleetIntentions, FleetServed, Intention
from tests.support.fleet import member, presence, put_position, signer, wait_until
from tests.support.zenoh_tls import VEHICLE_MARKS, add_entries, make_certs, shipped

KEYS = FleetKeys("attacktest")
DISCOVERY_S = 0.5
EVERY_POINT = list(range(64))
"""A route through every hovering point of the area (more than any sortie flies)."""


class Witness:
    """What reached a member's session on ``key`` (a subscriber of its own there, called after
    the member's: once the witness has a sample, the member has had it too)."""

    def __init__(self, session: Any, key: str) -> None:
        self.seen = 0
        self._sub = session.declare_subscriber(key, self._on)

    def _on(self, _sample: Any) -> None:
        self.seen += 1


def signed(vehicle: str, key: str, message: Any) -> bytes:
    """``message`` in ``vehicle``'s envelope, signed with its (stolen) key."""
    return signer(vehicle).seal(key, encode(message), time.time())


def test_finding_1_a_forged_service_from_any_peer_counts_for_nobody(mesh: Callable[[], Any]) -> None:
    """Two plain puts on ``fleet/served/ghost`` (and one in a member's name) naming a user:
    no member counts them (the user would have been 'already served 2 times')."""
    a_session = mesh()
    a = presence(KEYS, member("uav1", 100.0))
    a.join(a_session, DISCOVERY_S)
    b = presence(KEYS, member("uav2", 110.0))
    b.join(mesh(), DISCOVERY_S)
    witness = Witness(a_session, KEYS.all_served)
    attacker = mesh()
    wait_until(lambda: attacker.liveliness().get(KEYS.member("uav1"), timeout=1.0) is not None, 5.0, "the mesh")
    for n, vehicle in enumerate(("ghost", "ghost", "uav2")):
        attacker.put(KEYS.served(vehicle), encode(FleetServed(vehicle=vehicle, user_id="u-victim", tasks=5,
                                                              at_s=time.time() + n)))
    wait_until(lambda: witness.seen >= 3, 10.0, lambda: f"the forged services at uav1: {witness.seen}")
    assert a.ledger.take_served() == [], "a forged service was counted"
    assert a.roster.ignored >= 3
    a.leave()
    b.leave()


def rogue_member(session: Any, vehicle: str, sign: bool) -> Any:
    """A token under ``vehicle``, an armed vehicle's status and intentions whose route is every
    point (signed with ``vehicle``'s stolen key when ``sign``); returns the token."""
    token = session.liveliness().declare_token(KEYS.member(vehicle))
    now = time.time()
    intentions = FleetIntentions(vehicle=vehicle, time_s=now, route=EVERY_POINT)
    status = Status(vehicle=vehicle, armed=True, z_m=100.0)
    for _ in range(5):
        if sign:
            put_position(session, KEYS, status)
            session.put(KEYS.intentions(vehicle), signed(vehicle, KEYS.intentions(vehicle), intentions))
        else:
            session.put(Keys(KEYS.prefix, vehicle).status, encode(status))
            session.put(KEYS.position(vehicle), encode(status))
            session.put(KEYS.intentions(vehicle), encode(intentions))
        time.sleep(0.05)
    return token


def test_finding_2_a_rogue_member_gone_armed_keeps_no_airspace(mesh: Callable[[], Any],
                                                               caplog: pytest.LogCaptureFixture) -> None:
    """A token ``ghost``, an armed status, intentions whose route is every point, the token
    withdrawn: no member takes ghost for a member gone armed, nor plans without any point."""
    a_session = mesh()
    a = presence(KEYS, member("uav1", 100.0))
    a.join(a_session, DISCOVERY_S)
    tokens = Witness(a_session, KEYS.intentions("ghost"))
    attacker = mesh()
    with caplog.at_level(logging.INFO, logger="planner_service.fleet"):
        token = rogue_member(attacker, "ghost", sign=False)
        wait_until(lambda: tokens.seen >= 5, 10.0, "the rogue's intentions at uav1")
        gone = []
        a_session.liveliness().declare_subscriber(KEYS.member("ghost"), gone.append)
        token.undeclare()
        wait_until(lambda: bool(gone), 10.0, "the rogue's token withdrawn, at uav1")
    assert "ghost left with its vehicle armed" not in caplog.text
    assert a.roster.lost() == [] and a.ledger.blocked_points() == frozenset()
    assert a.check_separation().unknown == () or all("ghost" not in u for u in a.check_separation().unknown)
    a.leave()


def test_finding_2_a_compromised_member_keeps_its_airspace_for_a_flight_at_most(mesh: Callable[[], Any]) -> None:
    """The same by an enrolled member whose key was stolen (uav3, signing): its airspace is kept
    while it may be flying, but its route only to ``MAX_ROUTE`` points and for ``lost_s``."""
    a_session = mesh()
    a = presence(KEYS, member("uav1", 100.0), lost_s=2.0)
    a.join(a_session, DISCOVERY_S)
    attacker = mesh()
    announced = zext.declare_advanced_publisher(attacker, KEYS.announce("uav3"), cache=zext.CacheConfig(max_samples=1))
    token = attacker.liveliness().declare_token(KEYS.member("uav3"))

    def flying() -> bool:
        """uav3 a member, its vehicle armed and its route every point, as uav1 sees it."""
        announced.put(signed("uav3", KEYS.announce("uav3"), member("uav3", 140.0)))
        rogue_member(attacker, "uav3", sign=True).undeclare()  # the token above stays
        return ("uav3" in a.members() and "uav3" in a.ledger.intentions()
                and not any(u.startswith("uav3") for u in a.check_separation().unknown))
    wait_until(flying, 10.0, lambda: f"the compromised member at uav1: {a.members()}")
    token.undeclare()
    wait_until(lambda: a.roster.lost() == ["uav3"], 10.0, "uav3 gone with its vehicle armed")
    assert len(a.ledger.blocked_points()) == MAX_ROUTE < len(EVERY_POINT)
    wait_until(lambda: a.roster.lost() == [] and a.ledger.blocked_points() == frozenset(), 10.0,
               lambda: f"uav3's airspace kept past lost_s: {a.roster.lost()}, {sorted(a.ledger.blocked_points())}")
    a.leave()


def test_finding_4_a_rogue_token_or_a_huge_gap_bars_no_start(mesh: Callable[[], Any]) -> None:
    """A token ``fleet/members/uav2`` with no announcement: uav1 starts (no 'layer unknown'),
    uav2 starts (no 'already the member'); an announcement cached with ``min_gap_m: 1e9``
    (plain, and signed by a stolen key) bars nobody."""
    attacker = mesh()
    token = attacker.liveliness().declare_token(KEYS.member("uav2"))
    cached = zext.declare_advanced_publisher(attacker, KEYS.announce("uav4"), cache=zext.CacheConfig(max_samples=1))
    cached.put(encode(member("uav4", 500.0, gap_m=1e9)))
    huge = zext.declare_advanced_publisher(attacker, KEYS.announce("uav5"), cache=zext.CacheConfig(max_samples=1))
    huge.put(signed("uav5", KEYS.announce("uav5"), member("uav5", 500.0, gap_m=1e9)))
    tokens = [attacker.liveliness().declare_token(KEYS.member(v)) for v in ("uav4", "uav5")]
    uav1 = presence(KEYS, member("uav1", 100.0))
    uav1.join(mesh(), DISCOVERY_S)  # was: "uav2 is a member but its layer is unknown", "uav4 flies at 500 m..."
    uav2 = presence(KEYS, member("uav2", 110.0))
    uav2.join(mesh(), DISCOVERY_S)  # was: "another service is already the member for vehicle uav2"
    wait_until(lambda: set(uav1.members()) == {"uav1", "uav2"}, 10.0, lambda: f"uav1's members: {uav1.members()}")
    assert set(uav2.members()) == {"uav1", "uav2"}
    assert any("min_gap_m 1e+09" in r for r in uav1.roster.refused), list(uav1.roster.refused)
    for thing in (token, *tokens, cached, huge):
        thing.undeclare()
    uav1.leave()
    uav2.leave()


def steal_users(attacker: Any, vehicle: str, users: list[str]) -> None:
    """Signed intentions in ``vehicle``'s name claiming ``users`` due 1e15 s ago, repeated."""
    key = KEYS.intentions(vehicle)
    message = FleetIntentions(vehicle=vehicle, time_s=time.time(), users=[Intention(u, -1e15) for u in users],
                              claims=users)
    for _ in range(5):
        attacker.put(key, signed(vehicle, key, message))
        time.sleep(0.02)


def test_finding_5_a_compromised_members_claims_take_no_users(mesh: Callable[[], Any]) -> None:
    """uav3's stolen key claims users due -1e15 s, repeatedly: uav1 keeps its own."""
    a_session = mesh()
    a = presence(KEYS, member("uav1", 100.0))
    a.join(a_session, DISCOVERY_S)
    b = presence(KEYS, member("uav2", 110.0))
    b.join(mesh(), DISCOVERY_S)
    now = time.time()
    a.ledger.intend({"u-1": now + 30}, now, claims=["u-1"], points=[2])
    b.ledger.intend({"u-2": now + 30}, now, claims=["u-2"], points=[3])
    wait_until(lambda: b.ledger.owners() == {"u-1": "uav1"}, 10.0, lambda: f"uav2 reads uav1's claim: {b.ledger.owners()}")
    witness = Witness(a_session, KEYS.intentions("uav3"))
    attacker = mesh()
    announced = zext.declare_advanced_publisher(attacker, KEYS.announce("uav3"), cache=zext.CacheConfig(max_samples=1))
    token = attacker.liveliness().declare_token(KEYS.member("uav3"))
    wait_until(lambda: announced.put(signed("uav3", KEYS.announce("uav3"), member("uav3", 140.0))) is None
               and "uav3" in a.members(), 10.0, "the compromised uav3 a member")
    steal_users(attacker, "uav3", ["u-1", "u-2"])
    wait_until(lambda: witness.seen >= 5, 10.0, "the claims at uav1")
    assert a.ledger.owners() == {"u-2": "uav2"} and a.ledger.taken() == {"u-2"}, a.ledger.owners()
    token.undeclare()
    announced.undeclare()
    a.leave()
    b.leave()


def test_finding_7_a_forged_status_neither_raises_nor_hides_a_loss_of_separation(mesh: Callable[[], Any]) -> None:
    """Forged statuses on ``{prefix}/uav2/status`` (and unsigned positions on the fleet's key):
    uav1 judges on the members' signed positions only; no false SEPARATION LOST, and a real
    one is not hidden."""
    a_session, b_session, attacker = mesh(), mesh(), mesh()
    a = presence(KEYS, member("uav1", 100.0))
    a.join(a_session, DISCOVERY_S)
    b = presence(KEYS, member("uav2", 110.0))
    b.join(b_session, DISCOVERY_S)
    witness = Witness(a_session, Keys(KEYS.prefix, "uav2").status)

    def fly(b_x: float, forged_x: float) -> Callable[[], Any]:
        def put() -> Any:
            put_position(a_session, KEYS, Status(vehicle="uav1", armed=True, x_m=0.0, z_m=100.0))
            put_position(b_session, KEYS, Status(vehicle="uav2", armed=True, x_m=b_x, z_m=104.0))
            forged = Status(vehicle="uav2", armed=True, x_m=forged_x, z_m=104.0)
            attacker.put(Keys(KEYS.prefix, "uav2").status, encode(forged))
            attacker.put(KEYS.position("uav2"), encode(forged))
            return a.check_separation()
        return put
    apart = fly(300.0, 5.0)  # apart in truth; the forgery puts uav2 5 m from uav1
    wait_until(lambda: apart().unknown == () and witness.seen >= 3, 10.0, "both positions known at uav1")
    for _ in range(5):
        assert apart().conflicts == (), "a forged status raised a loss of separation"
    close = fly(6.0, 300.0)  # close in truth; the forgery says 300 m apart
    wait_until(lambda: close().conflicts != (), 10.0, "the real loss of separation seen")
    for _ in range(5):
        assert close().conflicts[0].startswith("uav1-uav2: 6 m apart"), "a forged status hid the loss"
    a.leave()
    b.leave()


@pytest.mark.timeout(120)
def test_finding_6_a_stolen_uav_certificate_and_key_do_1_2_and_5_in_their_own_name_to_no_effect(
        tmp_path: Path) -> None:
    """Under the shipped TLS + access control, uav1's certificate and fleet key (a compromised
    companion computer) in uav1's own name: a service for a user it never claimed (1), a
    route through every point (2), claims due -1e15 s (5). uav2 counts no service, keeps its
    own users and at most a sortie's route."""
    certs = tmp_path / "tls"
    make_certs(certs)
    make_certs(certs, "--vehicle", "uav1")
    make_certs(certs, "--vehicle", "uav2")
    printed = make_certs(certs, "--vehicle", "uav3")
    conf = shipped("fleet-router-tls-acl.json5", certs, tmp_path / "router.json5")
    add_entries(conf, printed, VEHICLE_MARKS)
    confs = {v: shipped("vehicle-tls.json5", certs, tmp_path / f"{v}.json5", **{"/vehicle.": f"/{v}."})
             for v in ("uav1", "uav2")}
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = Child("sim_bridge", ["router", "--listen", endpoint, "--zenoh-config", str(conf)], tmp_path / "r.log")
    sessions: list[Any] = []

    def session(vehicle: str) -> Any:
        c = client_config([endpoint], "client", config_file=confs[vehicle])
        c.insert_json5("timestamping/enabled", "true")
        sessions.append(zenoh.open(c))
        return sessions[-1]
    keys = FleetKeys("uavmec")
    try:
        router.wait_ready("router listening")
        uav2_session = session("uav2")
        uav2 = presence(keys, member("uav2", 110.0))
        uav2.join(uav2_session, DISCOVERY_S)
        uav1 = presence(keys, member("uav1", 100.0))
        uav1.join(session("uav1"), DISCOVERY_S)
        wait_until(lambda: "uav1" in uav2.members(), 10.0, "uav1 a member at uav2")
        now = time.time()
        uav2.ledger.intend({"u-2": now + 30}, now, claims=["u-2"], points=[3])
        witness = Witness(uav2_session, keys.all_served)
        thief = session("uav1")
        served = keys.served("uav1")
        for n in range(2):  # 1: a service to a user uav1 never claimed
            thief.put(served, signer("uav1").seal(served, encode(FleetServed(
                vehicle="uav1", user_id="u-victim", tasks=5, at_s=now + n)), time.time()))
        intentions = keys.intentions("uav1")  # 2 and 5: every point, and uav2's user due 1e15 s ago
        thief.put(intentions, signer("uav1").seal(intentions, encode(FleetIntentions(
            vehicle="uav1", time_s=now, users=[Intention("u-2", -1e15)], claims=["u-2"], route=EVERY_POINT)),
            time.time()))
        thief.put(intentions, signer("uav1").seal(intentions, encode(FleetIntentions(
            vehicle="uav1", time_s=now, route=EVERY_POINT)), time.time()))
        wait_until(lambda: witness.seen >= 2 and uav2.ledger.intentions().get("uav1") is not None, 10.0,
                   "the thief's messages at uav2")
        assert uav2.ledger.take_served() == []
        assert uav2.ledger.owners() == {}  # u-2 is still uav2's
        assert uav2.ledger._routes["uav1"] == set(range(MAX_ROUTE))
        uav1.leave()
        uav2.leave()
    finally:
        for s in sessions:
            s.close()
        router.stop()
