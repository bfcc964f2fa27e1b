"""The service survives a lossy MAVLink link, a vehicle restart mid-sortie and its own
SIGKILL: whole sorties end to end (vehicle stub, lossy proxy, service, simulated users as
real processes on loopback), checked as test_one_sortie_end_to_end.py checks a clean one
and against the vehicle's own log (tests/support/sortie_checks.py). Each prints its figures."""

from __future__ import annotations

import os
import re
import signal
import statistics
import time

import pytest

from planner_service.model import field
from planner_service.harness.processes import Child
from protocol import Event
from protocol.client import ClientError
from tests.support.gcs import M, GroundStation
from tests.support.sortie_checks import check_sortie, read_sortie
from tests.support.stack import Stack

SPEEDUP = "40"
# Over the lossy link an upload takes 1-3 s of wall time (retried items): at 40x that is a
# minute or two of flight, and on a loaded machine the whole sortie could be over before a
# second mission went up. At 20x the sortie leaves room for the replans the test is about.
LOSSY_SPEEDUP = "20"
SERVICE = {"mavlink__start_mission": "true", "planner__min_requests": "5"}


def kill(child: Child) -> None:
    """SIGKILL, as a crash would: no shutdown path runs."""
    os.killpg(child.proc.pid, signal.SIGKILL)
    child.proc.wait(5)


def flight_commands(vehicle_log: str) -> int:
    """Commands in the vehicle's log but the telemetry requests (SET_MESSAGE_INTERVAL 511,
    REQUEST_MESSAGE 512) that a link sends on every connection."""
    return len(re.findall(r"command (?!511 |512 )\d+ ", vehicle_log))


def upload_ms(events: list[Event]) -> list[float]:
    return [float(re.search(r"upload_ms=([0-9.]+)", e.detail).group(1))  # type: ignore[union-attr]
            for e in events if e.event == "mission_uploaded"]


@pytest.mark.timeout(150)
def test_sortie_over_a_lossy_link(stack: Stack) -> None:
    scenario = field()
    vehicle = stack.vehicle("--speedup", LOSSY_SPEEDUP)
    port = stack.proxy("--drop", "0.2", "--dup", "0.05", "--delay-ms", "20", "--jitter-ms", "20", "--seed", "5")
    service = stack.service(mavlink__url=f"udpout:127.0.0.1:{port}", **SERVICE)
    users = stack.users("--count", "6", "--speedup", LOSSY_SPEEDUP, "--seed", "3")
    stack.wait_event(lambda e: e.event == "landed", 120.0, "landing")
    assert users.stop() == 0 and service.stop() == 0

    sortie = check_sortie(stack, scenario, "ardupilot", [vehicle.log()])
    proxy = next(c for c in stack.children if c.name == "sim_bridge lossy-proxy")
    assert proxy.stop() == 0
    stats = re.search(r"up (\{.*?\}), down (\{.*?\})", proxy.log())
    assert stats is not None and "'dropped': 0," not in stats.group(0), proxy.log()[-500:]
    times = upload_ms(stack.events)
    failed = stack.rows("SELECT plan_id, result FROM missions WHERE result != 'accepted'")
    print(f"\nlossy sortie (20 % drop each way, 5 % dup, 20+-20 ms): {len(times)} uploads accepted, "
          f"median {statistics.median(times):.0f} ms, max {max(times):.0f} ms; {len(failed)} failed {failed}; "
          f"{len(sortie.services)} services; proxy {stats.group(0)}")


@pytest.mark.timeout(150)
@pytest.mark.parametrize("backend, flavour", [("pymavlink", "ardupilot"), ("mavsdk", "px4")])
def test_vehicle_restart_mid_sortie(stack: Stack, backend: str, flavour: str) -> None:
    scenario = field()
    state = stack.tmp / "vehicle-state.json"
    args = ("--speedup", SPEEDUP, "--state-file", str(state), "--flavour", flavour)
    first = stack.vehicle(*args)
    service = stack.service(mavlink__backend=backend, mavlink__flavour=flavour, **SERVICE)
    users = stack.users("--count", "6", "--speedup", SPEEDUP, "--seed", "3")
    stack.wait_event(lambda e: e.event == "user_served", 60.0, "a first service")
    kill(first)
    time.sleep(1.0)
    back_at = time.time()
    second = stack.vehicle(*args)  # the same port, the same state file
    assert "restarted from" in second.log() and "airborne" in second.log()
    # A restart ends the authority: the mission goes up again, and nothing more until the
    # operator's start (the restarted vehicle holds where it came back).
    revoked = stack.wait_event(lambda e: e.event == "authority_revoked" and e.time_s > back_at, 30.0,
                               "the authority ended by the restart")
    uploaded = stack.wait_event(lambda e: e.event == "mission_uploaded" and e.time_s > back_at, 30.0,
                                "a mission after the restart")
    time.sleep(1.0)  # 40 s of the vehicle's time: the service commands nothing of its own
    # (a mission uploaded may set its current item, 224: that moves no vehicle out of a hold)
    assert not re.findall(r"command (?:176|300|400|20|21|22) ", second.log()), second.log()[-2000:]
    assert not any(e.event == "mission_resumed" for e in stack.events)
    needed = stack.wait_event(lambda e: e.event == "resume_needed" and e.time_s > back_at, 30.0,
                              "the operator told to resume")
    assert needed.time_s >= uploaded.time_s, (needed, uploaded)
    client = stack.client
    assert client is not None and stack.operator("start", "resume after the restart").accepted
    resumed = stack.wait_event(lambda e: e.event == "mission_resumed", 30.0, "the mission resumed")
    stack.wait_event(lambda e: e.event == "landed", 120.0, "landing")
    assert users.stop() == 0 and service.stop() == 0

    kinds = [e.event for e in stack.events]
    # ended by the mode the vehicle came back in, or by the restart: whichever is seen first
    assert "vehicle_restarted" in kinds and ("restarted" in revoked.detail or "mode changed" in revoked.detail), kinds
    check_sortie(stack, scenario, flavour, [first.log(), second.log()])
    print(f"\nvehicle restart ({backend}): new mission accepted {uploaded.time_s - back_at:.2f} s after the vehicle was started "
          f"again, resumed at {resumed.time_s - back_at:.2f} s ({uploaded.detail.split(';')[0]})")


@pytest.mark.timeout(150)
def test_a_restart_without_authority_asks_the_operator_to_resume(stack: Stack) -> None:
    """The operator took the authority back (``hold``) before the autopilot restarted in the
    air: the mission it lost goes up again, and ``resume_needed`` tells the operator that
    nothing flies it until ``operator start`` (docs/PROTOCOL.md)."""
    scenario = field()
    state = stack.tmp / "vehicle-state.json"
    args = ("--speedup", SPEEDUP, "--state-file", str(state))
    first = stack.vehicle(*args)
    service = stack.service(**SERVICE)
    users = stack.users("--count", "6", "--speedup", SPEEDUP, "--seed", "3")
    stack.wait_event(lambda e: e.event == "user_served", 60.0, "a first service")
    assert stack.operator("hold", "before the restart").accepted
    stack.wait_event(lambda e: e.event == "authority_released", 10.0, "the authority handed back")
    kill(first)
    time.sleep(1.0)
    back_at = time.time()
    second = stack.vehicle(*args)
    assert "restarted from" in second.log() and "airborne" in second.log()
    uploaded = stack.wait_event(lambda e: e.event == "mission_uploaded" and e.time_s > back_at, 30.0,
                                "a mission after the restart")
    needed = stack.wait_event(lambda e: e.event == "resume_needed" and e.time_s > back_at, 30.0,
                              "the operator told to resume")
    assert needed.time_s >= uploaded.time_s and "operator start" in needed.detail, needed
    kinds = [e.event for e in stack.events if e.time_s > back_at]
    assert "vehicle_restarted" in kinds and "authority_revoked" not in kinds, kinds  # there was none to end
    assert kinds.count("resume_needed") == 1, kinds
    assert not re.findall(r"command (?:176|300|400|20|21|22) ", second.log()), second.log()[-2000:]
    assert stack.operator("start", "resume after the restart").accepted
    stack.wait_event(lambda e: e.event == "mission_resumed" and e.time_s > needed.time_s, 30.0, "the mission resumed")
    stack.wait_event(lambda e: e.event == "landed", 120.0, "landing")
    assert users.stop() == 0 and service.stop() == 0
    check_sortie(stack, scenario, "ardupilot", [first.log(), second.log()])
    print(f"\nrestart without authority: mission accepted {uploaded.time_s - back_at:.2f} s after the vehicle was "
          f"started again, resume_needed at {needed.time_s - back_at:.2f} s")


@pytest.mark.timeout(150)
def test_service_killed_mid_sortie_resumes_from_the_journal(stack: Stack) -> None:
    scenario = field()
    # x20, not x40: the restarted service reads the mission back, measures the vehicle's clock
    # rate and loads its planner (1-2 s of wall time on a loaded machine) before it plans;
    # at x40 the vehicle once finished the three points it held meanwhile and landed first
    speedup = "20"
    vehicle = stack.vehicle("--speedup", speedup)
    first = stack.service(**SERVICE)
    users = stack.users("--count", "6", "--speedup", speedup, "--seed", "3")
    client = stack.client
    assert client is not None
    acked = [client.submit("probe-1", 250.0, 250.0, 12).request_id]
    stack.wait_event(lambda e: e.event == "user_served", 60.0, "a first service")
    stack.wait_event(lambda e: e.event == "mission_uploaded" and " 0 points" not in e.detail
                     and e.time_s > max(x.time_s for x in stack.events if x.event == "user_served"), 30.0,
                     "a mission after the first service")
    plans_before = max(p for (p,) in stack.rows("SELECT plan_id FROM missions"))
    kill(first)
    assert stack.rows("SELECT COUNT(*) FROM services")[0][0] >= 1
    back_at = time.time()
    second = stack.service(**SERVICE)
    # started with the vehicle in the air: what was done to it meanwhile is unknown
    stack.wait_log(second, "authority ended: revoked: the service started with the vehicle in the air", 30.0)
    acked.append(client.submit("probe-2", 100.0, 400.0, 15).request_id)
    uploaded = stack.wait_event(lambda e: e.event == "mission_uploaded" and e.time_s > back_at, 30.0,
                                "a mission after the restart")
    stack.wait_event(lambda e: e.event == "landed", 120.0, "landing")
    assert users.stop() == 0

    plan_id = int(uploaded.detail.split(":")[0].split()[1])
    assert plan_id > plans_before, (plan_id, plans_before)
    acked += [int(n) for n in re.findall(r"-> request (\d+)", users.log())]
    closed = dict(stack.rows("SELECT request_id, status FROM requests"))
    assert all(closed.get(rid) in ("served", "replaced", "not_served") for rid in acked), \
        [(rid, closed.get(rid)) for rid in acked if closed.get(rid) not in ("served", "replaced", "not_served")]
    check_sortie(stack, scenario, "ardupilot", [vehicle.log()], unjournaled_commits=1)
    print(f"\nservice SIGKILL: plan {plan_id} accepted {uploaded.time_s - back_at:.2f} s after the restart began "
          f"(plans before the kill: {plans_before}); {len(acked)} acked requests all closed")


@pytest.mark.timeout(120)
def test_a_landing_while_the_service_is_down_ends_the_sortie(stack: Stack) -> None:
    """The service never sees the landing (it is dead meanwhile): started again, it finds the
    vehicle on the ground and disarmed after a sortie that flew, and ends the sortie rather
    than plan a second flight into it."""
    vehicle = stack.vehicle("--speedup", SPEEDUP)
    settings = {**SERVICE, "planner__min_requests": "1", "sortie__repeat": "false"}
    first = stack.service(**settings)
    client = stack.client
    assert client is not None
    served = client.submit("u1", 120.0, 150.0, 12).request_id
    stack.wait_event(lambda e: e.event == "user_served" and e.request_id == served, 60.0, "the first service")
    waiting = client.submit("u2", 400.0, 420.0, 14).request_id
    kill(first)
    gcs = GroundStation(f"udpout:127.0.0.1:{stack.mav_port}")
    try:
        gcs.wait_vehicle()
        assert gcs.command(M.MAV_CMD_NAV_LAND) == M.MAV_RESULT_ACCEPTED
        deadline = time.monotonic() + 30.0
        while not re.search(r"disarmed( \(landed\))? at", vehicle.log()):
            assert time.monotonic() < deadline, vehicle.log()[-2000:]
            time.sleep(0.1)
    finally:
        gcs.close()
    plans_before = max(p for (p,) in stack.rows("SELECT plan_id FROM missions"))
    commands_before = flight_commands(vehicle.log())
    stack.service(**settings)
    deadline = time.monotonic() + 20.0
    while not stack.rows("SELECT ended_at_s FROM sorties WHERE number = 1 AND ended_at_s IS NOT NULL"):
        assert time.monotonic() < deadline, stack.children[-1].log()[-3000:]
        time.sleep(0.1)
    (why,) = stack.rows("SELECT why FROM sorties WHERE number = 1")[0]
    assert why == "the vehicle was found landed"
    (status, reason) = stack.rows(f"SELECT status, reason FROM requests WHERE request_id = {waiting}")[0]
    assert status == "not_served" and "sortie ended" in reason, (status, reason)
    with pytest.raises(ClientError, match="sortie over"):
        client.submit("u3", 200.0, 200.0, 9)
    time.sleep(1.0)  # a plan, an upload or an arm command would have come by now
    assert max(p for (p,) in stack.rows("SELECT plan_id FROM missions")) == plans_before
    assert flight_commands(vehicle.log()) == commands_before, vehicle.log()[-1500:]


@pytest.mark.timeout(90)
def test_a_mission_that_goes_up_while_the_service_stops_is_journalled(stack: Stack) -> None:
    """SIGINT while a mission goes up a slow link: the service lets the upload finish (up to
    ``GRACE_S``), and the mission the vehicle then holds is in the journal, accepted (was:
    the upload's outcome was dropped once the service was stopping, so the vehicle held a
    mission the journal never knew; seen at the end of a lossy sortie, a way-home plan
    still going up when the test stopped the service after the landing)."""
    vehicle = stack.vehicle()
    port = stack.proxy("--delay-ms", "120")
    service = stack.service(mavlink__url=f"udpout:127.0.0.1:{port}")
    client = stack.client
    assert client is not None
    client.submit("u-1", 100.0, 100.0, 5, timeout_s=10.0)
    deadline = time.monotonic() + 30.0
    while "decision (" not in service.log():  # the upload begins as the decision is logged
        assert time.monotonic() < deadline, service.log()[-2000:]
        time.sleep(0.02)
    t0 = time.monotonic()
    assert service.stop() == 0
    stopped_s = time.monotonic() - t0
    log = service.log()
    print(f"stopped {stopped_s:.1f} s after the decision; the upload: "
          + next((line.split(" INFO ")[-1] for line in log.splitlines() if "uploaded (" in line), "none logged"))
    sortie = read_sortie(stack, [vehicle.log()], "ardupilot")
    assert "uploaded (" in log and sortie.commits, "the upload did not finish before the service stopped"
    assert sortie.commits == sortie.accepted, (sortie.commits, sortie.accepted)
