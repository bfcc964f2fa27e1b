"""zenoh with mutual TLS and access control, from the shipped files: certificates made by
docs/zenoh/make-certs.sh (the openssl CLI, as an operator makes them; a user's certificate
names its user id), the service started on docs/zenoh/service-tls-acl.json5 with a second
user's entries added as make-certs.sh prints them, and users on docs/zenoh/user-tls.json5
(their paths substituted).

A user submits as itself and is acked; its certificate cannot submit as another user id
by any key (the other user's key, its own key with the other id, the plain key, a
wildcard), nor follow another user's place. The same user's publication on the status key,
queryable on the request keys and liveliness token on the alive key reach nobody, while
the service's status does, and a session holding the service's certificate may publish
there; a client without a certificate, with one from another CA, or over plain TCP cannot
connect."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import zenoh

from planner_service.harness.processes import REPO, free_port
from protocol import ErrorReply, Keys, Status, TaskAck, UserPlace, decode, decode_reply, encode
from protocol.client import ClientError, PlannerClient, client_config
from tests.support.stack import Stack
from tests.support.zenoh_tls import add_entries, make_certs, shipped


def session(endpoint: str, config_file: Path) -> Any:
    return zenoh.open(client_config([endpoint], "client", config_file=config_file))


def request(user: str, ref: str) -> bytes:
    return json.dumps({"kind": "task_request", "user_id": user, "x_m": 1.0, "y_m": 2.0, "tasks": 4,
                       "client_ref": ref}).encode()


def replies(s: Any, key: str, payload: bytes, timeout_s: float = 2.0) -> list[bytes]:
    return [r.ok.payload.to_bytes() for r in s.get(key, payload=payload, target=zenoh.QueryTarget.ALL,
                                                    consolidation=zenoh.ConsolidationMode.NONE, timeout=timeout_s)
            if r.ok is not None]


@pytest.mark.timeout(150)
def test_tls_and_access_control_from_the_shipped_configs(stack: Stack, tmp_path: Path) -> None:
    certs, rogue = tmp_path / "tls", tmp_path / "rogue"
    make_certs(certs)
    make_certs(certs, "--user", "u-1")  # the shipped example user
    printed = make_certs(certs, "--user", "u-2")
    make_certs(rogue)
    make_certs(rogue, "--user", "u-1")  # another CA, whose user certificate looks the same
    service_conf = shipped("service-tls-acl.json5", certs, tmp_path / "service.json5")
    add_entries(service_conf, printed)
    user_conf = shipped("user-tls.json5", certs, tmp_path / "user.json5", **{"/user.": "/u-1."})
    user2_conf = shipped("user-tls.json5", certs, tmp_path / "user2.json5", **{"/user.": "/u-2."})
    monitor_conf = shipped("user-tls.json5", certs, tmp_path / "monitor.json5", **{"/user.": "/service."})
    rogue_conf = shipped("user-tls.json5", rogue, tmp_path / "rogue.json5", **{"/user.": "/u-1."})
    keys = Keys()

    endpoint = f"tls/127.0.0.1:{free_port()}"
    stack.endpoint = endpoint
    stack.vehicle()
    stack.client = PlannerClient([endpoint], config_file=user_conf, timeout_s=2.0)  # the stack's client is u-1
    service = stack.service(zenoh__mode="router", zenoh__config_file=str(service_conf))
    assert f"base {service_conf}" in service.log()

    # each user is served as itself: the library, and the submit command
    ack = stack.client.submit("u-1", 100.0, 120.0, 9)
    assert ack.request_id == 1
    out = subprocess.run([sys.executable, "-m", "planner_service", "submit", "--user", "u-2", "--x", "50", "--y", "60",
                          "--tasks", "4", "--connect", endpoint, "--zenoh-config", str(user2_conf)],
                         cwd=REPO, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "accepted: request 2 for u-2" in out.stdout, out.stderr

    # u-1's certificate cannot submit as u-2, whatever the key
    u1 = stack.client.session
    with pytest.raises(ClientError, match="no reply on uavmec/uav1/request/u-2"):
        stack.client.submit("u-2", 1.0, 2.0, 4)  # u-2's own key: not u-1's to query
    own_key = [decode_reply(r) for r in replies(u1, keys.user_request("u-1"), request("u-2", "a"))]
    assert len(own_key) == 1 and isinstance(own_key[0], ErrorReply) and own_key[0].field == "user_id"
    assert replies(u1, keys.request, request("u-2", "b")) == []  # the plain key: not open to users
    for wildcard in (keys.user_requests, f"{keys.prefix}/{keys.vehicle}/request/**", keys.all):
        answers = [decode_reply(r) for r in replies(u1, wildcard, request("u-2", "c"))]
        assert all(isinstance(a, ErrorReply) and a.field == "key" for a in answers), (wildcard, answers)

    # listeners: another user and a session holding the service's certificate
    heard: dict[str, list[bytes]] = {"user2": [], "monitor": []}
    places: list[tuple[str, str]] = []
    user2, monitor, bad = session(endpoint, user2_conf), session(endpoint, monitor_conf), session(endpoint, user_conf)
    try:
        for name, s in (("user2", user2), ("monitor", monitor)):
            s.declare_subscriber(keys.status, lambda sample, n=name: heard[n].append(sample.payload.to_bytes()))
        # u-1 follows its own place, and tries u-2's and everyone's
        for key in (keys.user("u-1"), keys.user("u-2"), keys.users):
            bad.declare_subscriber(key, lambda sample, k=key: places.append(
                (k, decode(sample.payload.to_bytes(), UserPlace).user_id)))
        # the misbehaving user (a valid user certificate) impersonates the service three ways
        bad.declare_queryable(keys.request, lambda q: (q.reply(keys.request, b'{"kind": "evil"}'), q.drop()))
        bad.declare_queryable(keys.user_requests, lambda q: (q.reply(str(q.key_expr), b'{"kind": "evil"}'), q.drop()))
        # (a token on the alive key would merge with the service's: one more key shows it)
        bad_tokens = [bad.liveliness().declare_token(k) for k in (keys.alive, f"{keys.prefix}/{keys.vehicle}/up")]
        forged = json.dumps({"kind": "status", "vehicle": "forged"}).encode()
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            bad.put(keys.status, forged)
            monitor.put(keys.user("u-2"), encode(UserPlace(user_id="u-2", plan_id=1)))  # as the service would
            monitor.put(keys.user("u-1"), encode(UserPlace(user_id="u-1", plan_id=1)))
            time.sleep(0.05)
        monitor.put(keys.status, b"from-the-service-identity")  # allowed: the service's certificate
        time.sleep(0.5)

        # u-2 submits again on its own key: the one answer is the service's ack
        answers = replies(user2, keys.user_request("u-2"), request("u-2", "d"), 3.0)
        # the monitor may look at every token of the vehicle (a user may only ask for the alive key)
        tokens = [str(r.ok.key_expr) for r in monitor.liveliness().get(keys.all, timeout=1.0) if r.ok]
        for token in bad_tokens:
            token.undeclare()
    finally:
        for s in (bad, monitor, user2):
            s.close()

    statuses = {n: [p for p in payloads if p != b"from-the-service-identity"] for n, payloads in heard.items()}
    print(f"\nstatus messages heard: user2 {len(statuses['user2'])}, monitor {len(statuses['monitor'])}; forged "
          f"{sum(p == forged for ps in heard.values() for p in ps)}; replies to a request: {len(answers)}; "
          f"alive tokens: {len(tokens)}; places heard by u-1: {len(places)}")
    for name, payloads in statuses.items():
        assert payloads, f"{name} heard no status from the service"
        assert all(decode(p, Status).vehicle == "uav1" for p in payloads), f"{name} heard a forged status"
    assert b"from-the-service-identity" in heard["user2"]  # the path for a client's put exists
    assert len(answers) == 1 and isinstance(decode_reply(answers[0]), TaskAck)  # the user's queryables got nothing
    assert tokens == [keys.alive]
    assert places and {user for _, user in places} == {"u-1"}, places  # its own place, nobody else's

    # no certificate, another CA's certificate, plain TCP: no session at all
    no_cert = tmp_path / "no-cert.json5"
    no_cert.write_text(json.dumps({"transport": {"link": {"tls": {"root_ca_certificate": str(certs / "ca.pem")}}}}))
    for label, connect, conf in (("no certificate", endpoint, no_cert), ("another CA", endpoint, rogue_conf),
                                 ("plain tcp", endpoint.replace("tls/", "tcp/"), None)):
        with pytest.raises(ClientError, match="cannot open a zenoh session"):
            PlannerClient([connect], mode="client", config_file=conf)
        print(f"{label}: refused")
    assert service.proc.poll() is None and "Traceback" not in service.log()
    assert [r[0] for r in stack.rows("SELECT user_id FROM requests ORDER BY request_id")] == ["u-1", "u-2", "u-2"]
