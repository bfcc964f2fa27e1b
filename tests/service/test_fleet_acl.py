"""A fleet under mutual TLS and access control, from the shipped files: two meshed ground
routers (``sim_bridge router``) on docs/zenoh/fleet-router-tls-acl.json5 with a third vehicle's
entries added as ``make-certs.sh --vehicle`` printed them, each UAV's session on
docs/zenoh/vehicle-tls.json5 with its own certificate.

Each UAV joins the fleet under its own name and reads the others' layers and statuses. A
certificate taken from one UAV speaks for that UAV only: its token, announcement and status
in another vehicle's name reach nobody, so it can neither bar that vehicle from the fleet nor
give it a false layer or position, nor intentions nor services (which would take users from
it, or close their requests). A user's certificate joins nobody's fleet: its token and
announcement go nowhere. And a real ``serve`` behind the routers serves its user, on its
vehicle's keys and through the fleet's, and is watched by the operator, each with their own
certificates."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh

from planner_service.harness.processes import REPO, Child, free_port
from planner_service.service.fleet.presence import FleetPresence
from protocol import FleetKeys, Keys, Status, decode, encode
from protocol.client import PlannerClient, client_config, request_for
from protocol.messages import FleetIntentions, FleetServed, Intention, UserPlace
from tests.support.fleet import ROSTER, fleet_settings, member, presence, wait_until
from tests.support.stack import Stack
from tests.support.zenoh_tls import VEHICLE_MARKS, add_entries, make_certs, shipped

KEYS = FleetKeys("uavmec")
DISCOVERY_S = 0.5


@pytest.mark.timeout(120)
def test_each_uav_certificate_speaks_for_its_own_vehicle_only(tmp_path: Path) -> None:
    certs = tmp_path / "tls"
    make_certs(certs)  # the CA and the routers' certificate (CN uavmec-service)
    for vehicle in ("uav1", "uav2"):  # the shipped examples
        make_certs(certs, "--vehicle", vehicle)
    printed = make_certs(certs, "--vehicle", "uav3")
    make_certs(certs, "--user", "u-1")
    router_conf = shipped("fleet-router-tls-acl.json5", certs, tmp_path / "router.json5")
    add_entries(router_conf, printed, VEHICLE_MARKS)
    confs = {name: shipped("vehicle-tls.json5", certs, tmp_path / f"{name}.json5", **{"/vehicle.": f"/{name}."})
             for name in ("uav1", "uav2", "uav3", "u-1")}

    # two ground routers, meshed with the routers' certificate: uav1, the thief and the user on
    # the first, uav2 and uav3 on the second
    first, second = f"tls/127.0.0.1:{free_port()}", f"tls/127.0.0.1:{free_port()}"
    routers: list[Child] = []
    sessions: list[Any] = []

    def session(cert: str, endpoint: str = first) -> Any:
        conf = client_config([endpoint], "client", config_file=confs[cert])
        conf.insert_json5("timestamping/enabled", "true")  # as the service's own, in a fleet
        s = zenoh.open(conf)
        sessions.append(s)
        return s

    def sees(s: Any, key: str) -> bool:
        return any(r.ok is not None for r in s.liveliness().get(key, timeout=1.0))

    presences: list[FleetPresence] = []
    try:
        for n, (listen, connect) in enumerate(((first, []), (second, ["--connect", first])), 1):
            routers.append(Child("sim_bridge", ["router", "--listen", listen, *connect, "--zenoh-config",
                                                str(router_conf)], tmp_path / f"router-{n}.log"))
            routers[-1].wait_ready("router listening")
        uav1 = presence(KEYS, member("uav1", 80.0))
        uav1.join(session("uav1"), DISCOVERY_S)
        presences.append(uav1)
        uav2_session = session("uav2", second)
        wait_until(lambda: sees(uav2_session, KEYS.member("uav1")), 10.0, "the mesh: uav1's token on the second")

        # uav1's certificate (taken from it) claims uav2 (a token, a layer on uav1's own) and
        # uav3 (a token, which would bar uav3 from joining: "already the member")
        thief = session("uav1")
        forged = [thief.liveliness().declare_token(KEYS.member(v)) for v in ("uav2", "uav3")]
        for _ in range(10):
            thief.put(KEYS.announce("uav2"), encode(member("uav2", 80.0)))
            time.sleep(0.05)
        # a user's certificate tries to join as uav4: it sees the members' tokens (a user waits
        # for the fleet's) but not their layers, so it refuses itself; its token reached nobody
        user = presence(KEYS, member("uav4", 120.0))
        user.join(session("u-1"), DISCOVERY_S)  # it reads no signed announcement: no member, no clash
        presences.append(user)

        # the real uav2 and uav3 join, each layer read as its own
        uav2 = presence(KEYS, member("uav2", 90.0))
        uav2.join(uav2_session, DISCOVERY_S)
        presences.append(uav2)
        uav3 = presence(KEYS, member("uav3", 100.0))
        uav3.join(session("uav3", second), DISCOVERY_S)
        presences.append(uav3)
        every = {v: member(v, layer) for v, layer in (("uav1", 80.0), ("uav2", 90.0), ("uav3", 100.0))}
        for p in (uav1, uav2, uav3):
            wait_until(lambda p=p: p.members() == every, 10.0,
                       lambda p=p: f"{p.own.vehicle} reads the three members: {p.members()}")

        # intentions and services in uav2's name: uav2's own reach uav1 (across the two
        # routers), the thief's none (it would take users from uav2, or close their requests)
        now = time.time()
        uav2.ledger.intend({"u-real": now + 60}, now, claims=["u-real"])
        # a service counts only for a user its member claimed: the claim first (on another key, so
        # it may arrive after a service sent at once; in flight a hold comes seconds after its claim)
        wait_until(lambda: "u-real" in uav1.ledger.intentions().get("uav2", {}), 10.0,
                   lambda: f"uav2's intentions at uav1: {uav1.ledger.intentions()}")
        uav2.ledger.served("u-real", 3, now + 1.0)
        for _ in range(20):
            thief.put(KEYS.intentions("uav2"), encode(FleetIntentions(vehicle="uav2", time_s=0.0,
                                                                      users=[Intention("u-forged", 0.0)])))
            thief.put(KEYS.served("uav2"), encode(FleetServed(vehicle="uav2", user_id="u-forged", tasks=9, at_s=2.0)))
            time.sleep(0.05)
        heard_served: list[tuple[str, str]] = []
        wait_until(lambda: bool(heard_served.extend((d.vehicle, d.user_id) for d in uav1.ledger.take_served())
                                or heard_served), 10.0, "uav2's service heard at uav1")
        time.sleep(0.5)  # the thief's last puts have had time to arrive: none may count
        heard_served += [(d.vehicle, d.user_id) for d in uav1.ledger.take_served()]
        assert uav1.ledger.intentions()["uav2"] == {"u-real": now + 60}
        assert heard_served == [("uav2", "u-real")], heard_served

        # a status in uav2's name: uav2's own reaches uav1, the thief's none
        status_key = Keys("uavmec", "uav2").status
        heard: list[Status] = []
        sub = session("uav1").declare_subscriber(status_key,
                                                 lambda sample: heard.append(decode(sample.payload.to_bytes(), Status)))
        for _ in range(20):
            thief.put(status_key, encode(Status(vehicle="uav2", armed=True, x_m=1.0)))
            uav2_session.put(status_key, encode(Status(vehicle="uav2", armed=False, x_m=500.0)))
            time.sleep(0.05)
        time.sleep(0.3)
        print(f"\nmembers as uav1 sees them: {sorted(uav1.members())}; statuses in uav2's name heard: "
              f"{len(heard)}, forged among them: {sum(s.armed for s in heard)}")
        assert heard and all(not s.armed and s.x_m == 500.0 for s in heard), heard
        assert "uav4" not in uav1.members()
        sub.undeclare()
        for token in forged:
            token.undeclare()
    finally:
        for p in presences:
            p.leave()
        for s in sessions:
            s.close()
        for router in routers:
            assert router.stop() == 0, router.log()[-2000:]


@pytest.mark.timeout(150)
def test_a_fleet_service_behind_the_routers_access_control(stack: Stack, tmp_path: Path) -> None:
    """A real ``serve`` in a fleet, a client of the ground router with its vehicle's
    certificate: it joins, its user submits through the router and is acked, and the
    operator's watch through the router shows the fleet."""
    certs = tmp_path / "tls"
    make_certs(certs)
    make_certs(certs, "--vehicle", "uav1")
    make_certs(certs, "--user", "u-1")
    router_conf = shipped("fleet-router-tls-acl.json5", certs, tmp_path / "router.json5")
    vehicle_conf = shipped("vehicle-tls.json5", certs, tmp_path / "uav1.json5", **{"/vehicle.": "/uav1."})
    user_conf = shipped("user-tls.json5", certs, tmp_path / "user.json5", **{"/user.": "/u-1."})
    operator_conf = shipped("operator-tls.json5", certs, tmp_path / "operator.json5")
    endpoint = f"tls/127.0.0.1:{free_port()}"
    router = Child("sim_bridge", ["router", "--listen", endpoint, "--zenoh-config", str(router_conf)],
                   tmp_path / "router.log")
    stack.children.append(router)
    router.wait_ready("router listening")

    stack.endpoint = endpoint
    stack.vehicle()
    stack.client = PlannerClient([endpoint], mode="client", config_file=user_conf, timeout_s=3.0)
    service = stack.service(zenoh__mode="client", zenoh__connect=endpoint, zenoh__listen="",
                            zenoh__config_file=str(vehicle_conf), fleet__enabled="true", fleet__discovery_s="1.0",
                            **{k.replace(".", "__"): v for k, v in fleet_settings().items()})
    assert "fleet: joined as uav1, layer 100 m" in service.log()
    ack = stack.client.submit("u-1", 100.0, 120.0, 9)
    assert ack.request_id == 1
    assert stack.client.wait_for_fleet(10.0)  # the user's certificate may see the members...
    places = stack.client.follow_fleet_place("u-1")  # ...follow its place on every member's key...
    answer = stack.client.submit_to_fleet(request_for("u-1", 100.0, 130.0, 9))  # ...and ask the fleet
    assert answer.holders == ("uav1",) and answer.ack.request_id == 2, answer
    wait_until(lambda: places.members().get("uav1", UserPlace("u-1")).request_id == 2, 20.0,
               lambda: f"u-1's place from uav1, through the router: {places.members()}\n{service.log()[-2000:]}")
    watch = subprocess.run([sys.executable, "-m", "planner_service", "operator", "watch", "--once", "--plain",
                            "--connect", endpoint, "--zenoh-config", str(operator_conf),
                            "--operator-key", str(stack.operator_key_path), "--fleet-roster", str(ROSTER)],
                           cwd=REPO, capture_output=True, text=True, timeout=60)
    assert watch.returncode == 0, watch.stderr
    assert "fleet      1 member: uav1 100 m (this)" in watch.stdout, watch.stdout
    assert "separation ok" in watch.stdout, watch.stdout  # its position from its own status, live
    assert service.proc.poll() is None and "Traceback" not in service.log()


def test_no_certificate_for_a_vehicle_named_fleet_nor_a_user_in_the_vehicles_names(tmp_path: Path) -> None:
    """A user whose id were uavmec-vehicle-uav1 would be uav1 to the routers; "fleet" is no
    vehicle (its keys are the fleet's)."""
    make_certs(tmp_path)
    for args, said in ((("--vehicle", "fleet"), "no vehicle may be named fleet"),
                       (("--user", "uavmec-vehicle-uav1"), "is reserved"),
                       (("--vehicle", "uav*"), "is not a vehicle id")):
        with pytest.raises(subprocess.CalledProcessError) as err:
            make_certs(tmp_path, *args)
        assert err.value.returncode == 2 and said in err.value.stderr, err.value.stderr
    assert not (tmp_path / "fleet.pem").exists() and not (tmp_path / "uavmec-vehicle-uav1.pem").exists()
