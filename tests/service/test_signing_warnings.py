"""What the service's signing warnings say about a dropped packet: real MAVLink bytes sent to
the service's UDP port on 127.0.0.1 beside a vehicle stub with the same key. A replay is
named a replay, a forgery in the vehicle's name a forgery, an unsigned packet unsigned; only a
bad signature from a sender nobody hears points to the key (the warning blamed a wrong key
on the vehicle for all of them: issue 23)."""

from __future__ import annotations

import re
import socket
import time
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as M

from planner_service.harness.processes import Child, free_port
from protocol.signing import Signer, load_key, write_key
from tests.support.stack import Stack

WARNING = "messages from the link dropped for their signature"


def heartbeat(system: int, key: bytes | None, link_id: int = 0) -> bytes:
    """A HEARTBEAT of ``system`` (component 1), signed with ``key`` now (unsigned if None)."""
    mav = M.MAVLink(None, srcSystem=system, srcComponent=1)
    if key is not None:
        Signer(key, link_id=link_id).attach(mav)
    return bytes(mav.heartbeat_encode(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav))


def warnings_of(service: Child) -> str:
    return "\n".join(line for line in service.log().splitlines() if WARNING in line)


def wait_warned(service: Child, *texts: str, timeout_s: float = 40.0) -> str:
    """The service's signing warnings once every one of ``texts`` is in them (a warning at
    most every 10 s: a burst may be told in two)."""
    deadline = time.monotonic() + timeout_s
    while not all(t in warnings_of(service) for t in texts):
        assert time.monotonic() < deadline, f"warnings never named {texts}:\n{service.log()[-3000:]}"
        time.sleep(0.1)
    return warnings_of(service)


@pytest.mark.timeout(120)
def test_each_drop_is_named_for_what_it_is(stack: Stack, tmp_path: Path) -> None:
    key_path = tmp_path / "uav.key"
    write_key(key_path)
    key = load_key(key_path)
    port = free_port(socket.SOCK_DGRAM)
    stack.vehicle("--signing-key", str(key_path), "--mavlink", f"udpout:127.0.0.1:{port}")
    service = stack.service(mavlink__signing_key_file=str(key_path), mavlink__url=f"udpin:127.0.0.1:{port}")
    stack.wait_log(service, "autopilot 1/1 connected", 30.0)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        captured = heartbeat(42, key, link_id=3)  # a correctly signed packet...
        tx.sendto(captured, ("127.0.0.1", port))
        time.sleep(0.2)
        tx.sendto(captured, ("127.0.0.1", port))  # ...and the same bytes again: a replay
        tx.sendto(heartbeat(1, bytes(32)), ("127.0.0.1", port))  # in the vehicle's name, another key
        tx.sendto(heartbeat(1, None), ("127.0.0.1", port))  # unsigned
        told = wait_warned(service, "replayed", "bad signature", "unsigned")
        replay = re.search(r"\d+ replayed, the last HEARTBEAT from system 42 component 1 \(link id 3\): its timestamp "
                           r"is 0\.00 s behind the last one heard on that stream: a replay of captured packets \(not a "
                           r"key problem\)", told)
        assert replay, told
        forged = re.search(r"\d+ bad signature, the last HEARTBEAT from system 1 component 1 \(link id 0\): the "
                           r"signature does not match our key while that sender's correctly signed messages pass: "
                           r"forged", told)
        assert forged, told
        assert "HEARTBEAT unsigned: the sender does not sign" in told, told
        assert "the vehicle signs with another key" not in told and "check that the vehicle holds the key" not in told, \
            "the vehicle's own messages pass: its key is not in question"
        # A sender nobody hears, with another key: that is the key's warning.
        tx.sendto(heartbeat(77, bytes(32)), ("127.0.0.1", port))
        told = wait_warned(service, "from system 77")
    finally:
        tx.close()
    last = told.splitlines()[-1]
    assert re.search(r"1 messages from the link dropped for their signature \(signing: 1 bad signature, the last "
                     r"HEARTBEAT from system 77 component 1 \(link id 0\): the signature does not match our key: the "
                     r"sender signs with another key \(or it is forged\); check that the vehicle holds the key in "
                     + re.escape(str(key_path)) + r"\)$", last), last
    assert "replayed" not in last, "a warning tells what came since the last one"
    assert "Traceback" not in service.log()
