"""The link's pure judgements, in milliseconds: a position only when the autopilot has one,
an unknown battery kept unknown, the landed state derived where none is reported, restarts
believed on two readings, the telemetry asked for and missed, trust in the autopilot's own
(system, component) only, and wire text escaped. Messages are real pymavlink objects;
clocks are pinned."""

from __future__ import annotations

from typing import Any

import pytest
from pymavlink.dialects.v20 import ardupilotmega as M

from protocol.autopilot import ARDUPILOT, PX4
from protocol.text import printable
from planner_service.service.link import (ArmedChanged, Connected, OnGround, LinkEvent, ModeChanged, PositionChanged, Restarted,
                                          StatusText, TelemetryMissing)
from planner_service.service.link.asked import COMMANDED_WINDOW_S
from planner_service.service.link.state import DERIVED, SILENCE_S, VehicleState
from planner_service.service.link.streams import (MISSING_AFTER_S, REREQUEST_S, UNAVAILABLE_AFTER_S, Streams,
                                                  stream_plan)
from planner_service.service.link.progress import CurrentWatch
from planner_service.service.link.telemetry import (ClockRate, ClockWatch, PositionInputs, assess_position, battery_fraction,
                                                    derived_airborne, energy_used_j)

READY = PositionInputs(lat_e7=473977420, lon_e7=85455940, gps_fix=6, estimator_flags=0x33F, home_set=True)


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def with_(p: PositionInputs, **changes: Any) -> PositionInputs:
    return PositionInputs(**{**p.__dict__, **changes})


# --- a position only when the autopilot has one ------------------------------------------------
def test_a_position_needs_fix_estimator_home_and_not_zero() -> None:
    assert assess_position(READY) == ""
    assert "no GLOBAL_POSITION_INT" in assess_position(PositionInputs())
    assert "stopped arriving" in assess_position(with_(READY, position_fresh=False))
    assert "no GPS_RAW_INT" in assess_position(with_(READY, gps_fix=None))
    assert "no 3D fix (fix type 2)" in assess_position(with_(READY, gps_fix=2))
    # ArduCopter SITL before "EKF3 IMU0 is using GPS": constant-position mode, no absolute position.
    assert assess_position(with_(READY, estimator_flags=0xA7)) == (
        "position estimate: EKF has no GPS position yet (flags 0x00a7)")
    assert "uninitialised" in assess_position(with_(READY, estimator_flags=0x33F | 1024))
    assert "no EKF_STATUS_REPORT" in assess_position(with_(READY, estimator_flags=None))
    assert assess_position(with_(READY, home_set=False)) == "home position: not set yet"
    assert "0/0" in assess_position(with_(READY, lat_e7=0, lon_e7=0))


def test_a_criterion_the_autopilot_will_not_report_is_skipped() -> None:
    assert assess_position(with_(READY, estimator_flags=None, estimator_available=False)) == ""
    assert assess_position(with_(READY, gps_fix=None, gps_available=False)) == ""
    assert assess_position(with_(READY, home_set=False, home_available=False)) == ""
    # ...but never the 0/0 test.
    assert "0/0" in assess_position(with_(READY, lat_e7=0, lon_e7=0, estimator_available=False,
                                          gps_available=False, home_available=False))


# --- an unknown battery is unknown ----------------------------------------------------------------
@pytest.mark.parametrize("remaining, fraction", [(-1, None), (101, None), (127, None), (-128, None), (0, 0.0),
                                                 (55, 0.55), (100, 1.0)])
def test_battery_remaining_outside_0_to_100_is_unknown(remaining: int, fraction: float | None) -> None:
    assert battery_fraction(remaining) == fraction


def test_energy_consumed_is_kept_when_reported() -> None:
    assert energy_used_j(-1) is None
    assert energy_used_j(1234) == 123400.0


# --- the landed state where the autopilot gives none ------------------------------------------------
def test_derived_airborne_has_a_hysteresis() -> None:
    assert not derived_airborne(False, 30.0, 0.0, True)  # disarmed: on the ground
    assert not derived_airborne(True, 0.6, 0.0, False)  # armed, on the ground
    assert derived_airborne(True, 1.5, 0.0, False)
    assert derived_airborne(True, 0.2, 1.0, False)  # climbing off the ground
    assert derived_airborne(True, 0.8, 0.0, True)  # hovering low stays airborne
    assert not derived_airborne(True, 0.3, 0.1, True)  # down and still


def test_the_vehicles_clock_rate_is_unknown_until_measured() -> None:
    rate = ClockRate()
    assert rate.update(100.0, 10.0) is None and rate.update(140.0, 10.5) is None, "half a second: unknown"
    assert rate.update(180.0, 11.0) == pytest.approx(80.0)  # x80, after the first second
    assert rate.update(200.0, 11.25) == pytest.approx(80.0), "then kept, and measured again every few seconds"


# --- restarts take several readings of the new clock ----------------------------------------------------
def test_one_reading_from_the_past_is_only_a_suspicion() -> None:
    watch = ClockWatch(slack_s=2.0, confirm_s=0.5)
    assert [watch.observe(t, 1.0, t) for t in (100.0, 100.25, 0.0, 100.5, 100.75)] == ["ok", "ok", "outlier", "ok",
                                                                                         "ok"]
    assert watch.boot_s == 100.75
    assert [watch.observe(t, 1.0, 100.0 + t) for t in (1.0, 1.25, 1.5, 1.75)] == ["outlier", "outlier", "restart",
                                                                                   "ok"]
    fast = ClockWatch(slack_s=2.0)
    assert [fast.observe(100.0, 1.0, 0.0), fast.observe(85.0, 10.0, 0.1)] == ["ok", "ok"]  # 10x: 20 vehicle s of slack
    assert fast.observe(70.0, 1.0, 0.2) == "outlier"


def test_readings_in_one_moment_are_no_restart_however_many() -> None:
    # A forged datagram held two GLOBAL_POSITION_INT of a new clock, 1000 and 1100 ms: it
    # was taken as a restart, which gave back an authority the pilot's LOITER had ended.
    watch = ClockWatch(slack_s=2.0, confirm_s=0.5)
    watch.observe(500.0, 1.0, 10.0)
    assert [watch.observe(t, 1.0, 10.01) for t in (1.0, 1.1, 1.2, 1.3)] == ["outlier"] * 4
    assert watch.observe(501.0, 1.0, 10.6) == "ok", "the old clock again: the suspicion is dropped"
    assert [watch.observe(1.4, 1.0, 10.7), watch.observe(1.9, 1.0, 11.3)] == ["outlier", "outlier"], "two readings"
    assert watch.observe(2.0, 1.0, 11.4) == "restart"


def test_one_reading_far_ahead_is_discarded_not_taken_as_the_clock() -> None:
    # Issue 34, finding 8: one GLOBAL_POSITION_INT from 1/1 with time_boot_ms far ahead was
    # taken as the clock, so the vehicle's own reports after it looked like a clock gone
    # back, and 0.5 s later a restart was believed.
    watch = ClockWatch()
    assert watch.observe(600.0, 1.0, 50.0) == "ok"
    assert watch.observe(4_000_000.0, 1.0, 50.05) == "outlier"
    assert [watch.observe(600.0 + 0.1 * i, 1.0, 50.0 + 0.1 * i) for i in range(1, 40)] == ["ok"] * 39
    assert watch.boot_s == pytest.approx(603.9)
    # Rate unknown (the first second): a reading that no simulator's pace could reach is an outlier too.
    young = ClockWatch()
    assert [young.observe(10.0, None, 0.0), young.observe(18.0, None, 0.1)] == ["ok", "ok"]  # x80 is possible
    assert young.observe(4_000_000.0, None, 0.2) == "outlier"


def test_a_real_restart_is_believed_from_its_stream_within_half_a_second() -> None:
    # As ArduPilot and PX4 (and the stub's --state-file restart) do: time_boot_ms starts near
    # 0 again and grows at the vehicle's rate, GLOBAL_POSITION_INT at 10 Hz once asked for.
    watch = ClockWatch()
    for i in range(20):
        assert watch.observe(600.0 + 0.8 * i, 8.0, 100.0 + 0.1 * i) == "ok"  # x8
    verdicts = [watch.observe(3.0 + 0.8 * i, 8.0, 102.0 + 0.1 * i) for i in range(8)]
    assert verdicts[:5] == ["outlier"] * 5 and verdicts[5] == "restart", verdicts
    assert verdicts[6:] == ["ok", "ok"]


def test_a_new_clock_needs_readings_that_agree_and_grow() -> None:
    watch = ClockWatch()
    watch.observe(600.0, 1.0, 0.0)
    # forged readings scattered in time, each a different clock: never one new clock
    assert [watch.observe(t, 1.0, 0.3 * i) for i, t in enumerate((5.0, 300.0, 60.0, 9.0, 200.0), 1)] == ["outlier"] * 5
    # one reading repeated (a replayed datagram): not a clock that runs
    assert [watch.observe(5.0, 1.0, 2.0 + 0.2 * i) for i in range(5)] == ["outlier"] * 5
    # a clock ahead that goes on (a simulator sped up): taken, as no restart
    ahead = ClockWatch()
    ahead.observe(100.0, 1.0, 0.0)
    assert [ahead.observe(500.0 + 0.1 * i, 1.0, 0.1 * i) for i in range(1, 7)] == ["outlier"] * 5 + ["jump"]
    assert ahead.observe(500.7, 1.0, 0.7) == "ok"


# --- MISSION_CURRENT believed when the stream agrees ----------------------------------------------------
def test_one_mission_current_naming_another_item_is_not_believed() -> None:
    # Issue 34, finding 8: one forged MISSION_CURRENT far ahead marked every planned point
    # before it skipped and ended the hold flown.
    watch = CurrentWatch(confirm_s=0.2)
    assert [watch.observe(3, t) for t in (0.0, 0.5)] == [False, True], "the first report is confirmed by the next"
    assert watch.observe(40, 1.0) is False
    assert watch.observe(3, 1.5) is True and watch.believed == 3, "the stream goes on: the forged one is forgotten"
    assert watch.observe(40, 1.6) is False, "and a second forged one begins again"
    assert watch.observe(40, 1.61) is False, "two in one datagram confirm nothing"
    assert [watch.observe(4, 2.0), watch.observe(4, 2.5), watch.believed] == [False, True, 4], "a real advance"
    assert watch.observe(-1, 3.0) is True and watch.believed == 4, "naming no item: passed on, nothing changed"


def test_the_item_the_service_asked_for_is_believed_at_once() -> None:
    watch = CurrentWatch()
    watch.observe(2, 0.0)
    watch.observe(2, 1.0)
    watch.expect(7)
    assert watch.observe(7, 1.1) is True and watch.believed == 7
    assert watch.observe(2, 1.2) is False, "the item before is news again: it needs the stream's word"
    watch.observe(2, 1.3)
    watch.observe(2, 1.6)
    watch.reached(5)
    assert watch.observe(6, 1.7) is False, "an item reached that is not the one flown says nothing"
    watch.reached(2)
    assert watch.observe(3, 1.8) is True, "the item after the one reached: at once"
    watch.expect(9)
    watch.reset()  # a restart: nothing before holds
    assert watch.believed is None and watch.observe(9, 2.0) is False


# --- the telemetry asked for ----------------------------------------------------------------------------
def test_every_message_is_asked_for_and_a_refusal_falls_back() -> None:
    clock = Clock()
    streams = Streams(stream_plan("ardupilot"), clock)
    requests = streams.begin()
    names = [r.spec.name for r in requests]
    assert all(r.kind == "interval" for r in requests)
    assert {"GLOBAL_POSITION_INT", "SYS_STATUS", "BATTERY_STATUS", "EXTENDED_SYS_STATE", "MISSION_CURRENT",
            "GPS_RAW_INT", "HOME_POSITION", "EKF_STATUS_REPORT"} == set(names)
    assert "ESTIMATOR_STATUS" in [s.name for s in stream_plan("px4")]
    assert streams.on_interval_result("GLOBAL_POSITION_INT", "MAV_RESULT_ACCEPTED") == []
    [fallback] = streams.on_interval_result("EKF_STATUS_REPORT", "NO_ANSWER")
    assert (fallback.kind, fallback.spec.group) == ("stream", M.MAV_DATA_STREAM_EXTRA3)
    assert streams.available("EKF_STATUS_REPORT")  # not answered: the fallback may still bring it
    [fallback] = streams.on_interval_result("HOME_POSITION", "MAV_RESULT_UNSUPPORTED")
    assert fallback.kind == "message"
    assert not streams.available("HOME_POSITION")  # the autopilot accepted others: it has not this one
    streams.heard(M.MAVLINK_MSG_ID_HOME_POSITION)
    assert streams.available("HOME_POSITION")  # ...until it comes all the same
    [fallback] = streams.on_interval_result("EXTENDED_SYS_STATE", "NO_ANSWER")
    assert fallback.kind == "message"  # in no stream group: asked for once, and again while missing
    assert streams.missing() == ()  # not yet: the autopilot is given MISSING_AFTER_S
    streams.heard(M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT)
    clock.now += MISSING_AFTER_S
    assert "GLOBAL_POSITION_INT" not in streams.missing() and "EKF_STATUS_REPORT" in streams.missing()
    clock.now += max(UNAVAILABLE_AFTER_S - MISSING_AFTER_S, 0.0)
    assert not streams.available("EKF_STATUS_REPORT") and streams.available("SYS_STATUS")
    clock.now += REREQUEST_S
    again = {r.spec.name: r.kind for r in streams.due()}
    assert again["EKF_STATUS_REPORT"] == "stream" and again["SYS_STATUS"] == "interval"
    assert "GLOBAL_POSITION_INT" in again  # not heard since: missing now
    assert streams.due() == []  # not again before REREQUEST_S


def test_messages_that_stop_are_asked_for_again_at_once() -> None:
    # An autopilot that restarts without the link noticing (its heartbeat back within the
    # link's timeout) comes back with its rates reset: its telemetry is asked for again as
    # soon as it is missing, not at the next tick of a clock, so the first reports carry a
    # clock young enough to show the restart (test_faults: a restart at x40 went unseen).
    clock = Clock()
    streams = Streams(stream_plan("ardupilot"), clock)
    streams.begin()
    ids = [getattr(M, f"MAVLINK_MSG_ID_{s.name}") for s in stream_plan("ardupilot")]
    for _ in range(int(3 * REREQUEST_S)):  # everything arrives, due() polled all along
        clock.now += 1.0
        for msg_id in ids:
            streams.heard(msg_id)
        assert streams.due() == []
    clock.now += MISSING_AFTER_S + 0.01  # then nothing arrives any more
    missing = streams.missing()
    assert "GLOBAL_POSITION_INT" in missing  # the slower messages follow within their 3 intervals
    assert {r.spec.name for r in streams.due()} == set(missing)
    assert streams.due() == []  # and again only after REREQUEST_S
    clock.now += REREQUEST_S
    assert streams.due() != []


# --- trust only the autopilot ------------------------------------------------------------------------------
def heartbeat(mode: int = 0, armed: bool = False, autopilot: int = M.MAV_AUTOPILOT_ARDUPILOTMEGA) -> Any:
    base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    return M.MAVLink_heartbeat_message(M.MAV_TYPE_QUADROTOR, autopilot, base, mode, 4, 3)


def position(boot_ms: int, alt_mm: int = 30000, vz: int = 0) -> Any:
    return M.MAVLink_global_position_int_message(boot_ms, 473977420, 85455940, 488000 + alt_mm, alt_mm, 0, 0, vz, 0)


def feed(state: VehicleState, msg: Any, source: tuple[int, int] = (1, 1)) -> bool:
    return state.on_message(msg.get_type(), msg.get_msgId(), *source, msg)


def vehicle(clock: Clock) -> tuple[VehicleState, list[LinkEvent]]:
    events: list[LinkEvent] = []
    state = VehicleState("ardupilot", events.append, clock=clock)
    assert not state.on_heartbeat(1, 190, heartbeat(autopilot=M.MAV_AUTOPILOT_INVALID))  # a ground station
    assert not state.on_heartbeat(1, 2, heartbeat())  # not the autopilot's component
    assert state.on_heartbeat(1, 1, heartbeat(mode=3, armed=True))
    state.streams.begin()
    return state, events


def test_forged_messages_from_another_component_change_nothing() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    assert isinstance(events[0], Connected) and state.autopilot == (1, 1)
    for t in range(10):
        feed(state, position(50_000 + 250 * t))
        clock.now += 0.25
    feed(state, M.MAVLink_extended_sys_state_message(0, M.MAV_LANDED_STATE_IN_AIR))
    before = state.telemetry
    forged = [position(0), position(1), M.MAVLink_extended_sys_state_message(0, M.MAV_LANDED_STATE_ON_GROUND),
              M.MAVLink_battery_status_message(0, 0, 0, 0, [0] * 10, 0, 0, 0, 3),
              M.MAVLink_statustext_message(M.MAV_SEVERITY_CRITICAL, b"PreArm: forged")]
    for msg in forged:
        assert not feed(state, msg, (1, 2))
    assert not state.on_heartbeat(1, 2, heartbeat(mode=6))  # RTL, says another component
    assert state.telemetry == before and state.untrusted == len(forged) + 1
    assert [e for e in events if isinstance(e, (Restarted, OnGround, StatusText, ModeChanged))] == []


def test_a_restart_is_believed_only_on_reports_spread_over_time() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    for t in range(8):
        feed(state, position(80_000 + 250 * t))
    assert not feed(state, position(0))  # forged with the autopilot's own ids, or reordered: ignored
    assert state.telemetry.position_boot_s == 81.75
    feed(state, position(82_000))
    assert not [e for e in events if isinstance(e, Restarted)]
    feed(state, position(500))
    assert not feed(state, position(600)), "a second report at once (one datagram) is no evidence"
    clock.now += 0.25
    assert not feed(state, position(800)), "two readings of the new clock, a quarter second apart: not yet"
    clock.now += 0.25
    feed(state, position(1_000))  # the new clock goes on: a real restart
    assert [e for e in events if isinstance(e, Restarted)] and state.telemetry.position_boot_s == 1.0
    assert not state.telemetry.home_set and not state.telemetry.position_ok


def test_an_autopilot_heard_after_a_silence_is_asked_for_its_telemetry_at_once() -> None:
    # A restart too short for a lost link: the new boot streams nothing until asked, and the
    # restart shows only in its reports' clock (test_faults: at x40 the re-ask came 5 s late).
    clock = Clock()
    state, events = vehicle(clock)
    asked: list[float] = []
    state.request_streams = lambda: asked.append(clock.now)
    for t in range(8):  # heartbeats and reports as usual: nothing asked
        feed(state, position(10_000 + 250 * t))
        clock.now += 0.25
        if t % 4 == 0:
            state.on_heartbeat(1, 1, heartbeat(mode=3, armed=True))
    assert asked == []
    clock.now += SILENCE_S + 0.2  # the autopilot dies and comes back
    state.on_heartbeat(1, 1, heartbeat(mode=5, armed=True))
    assert asked == [clock.now] and not state.lost
    assert [e for e in events if isinstance(e, ModeChanged)][-1].mode == "LOITER"
    clock.now += 0.5
    state.on_heartbeat(1, 1, heartbeat(mode=5, armed=True))
    assert len(asked) == 1


def test_commanded_and_foreign_mode_changes_are_told_apart() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    state.mode_asked.ask("RTL")
    state.on_heartbeat(1, 1, heartbeat(mode=6, armed=True))
    state.mode_asked.answered(clock.now, refused=False)
    clock.now += 10.0
    state.on_heartbeat(1, 1, heartbeat(mode=9, armed=True))  # LAND by a pilot
    assert [e for e in events if isinstance(e, ModeChanged)] == [ModeChanged("RTL", True), ModeChanged("LAND", False)]


def test_commanded_and_foreign_armings_are_told_apart() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=False))
    del events[:]
    asked = state.arming_asked
    asked.ask(True)
    clock.now += 1.0
    asked.answered(clock.now, refused=False)
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=True))  # the service's arming
    clock.now += 1.0
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=True))  # no change, no event
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=False))  # a pilot's disarming
    asked.ask(True)
    asked.answered(clock.now, refused=False)
    clock.now += COMMANDED_WINDOW_S + 1.0  # later than the window after the answer: not the arming asked for
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=True))
    assert [e for e in events if isinstance(e, ArmedChanged)] == [
        ArmedChanged(True, True), ArmedChanged(False, False), ArmedChanged(True, False)]


def test_an_arming_shown_while_its_command_is_in_flight_is_the_services() -> None:
    # The clean clone of 2026-12-07: on a loaded machine MAVSDK sent the service's arming
    # (through its executor) more than 5 s after it was asked for; the heartbeat showing it
    # came later than a window counted from the asking, and the service took its own arming
    # for somebody else's (the authority revoked at its own start).
    clock = Clock()
    state, events = vehicle(clock)
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=False))
    del events[:]
    state.arming_asked.ask(True)
    clock.now += COMMANDED_WINDOW_S + 3.0  # the command still in flight
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=True))
    clock.now += 1.0
    state.arming_asked.answered(clock.now, refused=False)
    assert [e for e in events if isinstance(e, ArmedChanged)] == [ArmedChanged(True, True)]


def test_a_change_after_a_refusal_is_somebody_elses_and_after_no_answer_may_be_ours() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=False))
    del events[:]
    state.arming_asked.ask(True)
    state.arming_asked.answered(clock.now, refused=True)  # the autopilot refused to arm
    clock.now += 0.5
    state.on_heartbeat(1, 1, heartbeat(mode=4, armed=True))  # a pilot armed it
    state.mode_asked.ask("RTL")
    state.mode_asked.answered(clock.now, refused=False)  # no answer: it may have been done
    clock.now += 1.0
    state.on_heartbeat(1, 1, heartbeat(mode=6, armed=True))
    assert [e for e in events if isinstance(e, (ArmedChanged, ModeChanged))] == [
        ArmedChanged(True, False), ModeChanged("RTL", True)]


def test_landed_state_is_derived_and_said_so_where_the_autopilot_gives_none() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    state.streams.on_interval_result("EXTENDED_SYS_STATE", "MAV_RESULT_UNSUPPORTED")
    boot = 10_000
    for alt_mm, vz in [(0, 0), (500, -100), (5000, -100), (20000, 0)]:  # armed, climbing out
        clock.now += 1.0
        boot += 1000
        feed(state, position(boot, alt_mm, vz))
    t = state.telemetry
    assert t.airborne and t.landed_known and t.landed_source == DERIVED
    for alt_mm in (2000, 200, 0):
        clock.now += 1.0
        boot += 1000
        feed(state, position(boot, alt_mm, 0))
    assert not state.telemetry.airborne and OnGround(DERIVED) in events


def test_the_position_event_says_what_is_awaited() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    feed(state, position(1000))
    feed(state, M.MAVLink_gps_raw_int_message(0, 6, 473977420, 85455940, 0, 0, 0, 0, 0, 10))
    feed(state, M.MAVLink_ekf_status_report_message(0xA7, 0, 0, 0, 0, 0))
    feed(state, M.MAVLink_home_position_message(473977420, 85455940, 488000, 0, 0, 0, [1, 0, 0, 0], 0, 0, 0))
    assert state.telemetry.waiting_for.startswith("position estimate") and not state.telemetry.position_ok
    feed(state, M.MAVLink_ekf_status_report_message(0x33F, 0, 0, 0, 0, 0))
    assert state.telemetry.position_ok and PositionChanged(True, "") in events


def test_what_does_not_arrive_is_missing_and_said_once() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    clock.now += MISSING_AFTER_S + 0.1
    state.heard()
    state.tick()
    state.tick()
    missing = [e for e in events if isinstance(e, TelemetryMissing)]
    assert len(missing) == 1 and "GLOBAL_POSITION_INT" in missing[0].missing
    assert state.telemetry.missing == missing[0].missing


def test_an_unknown_battery_reading_is_never_full() -> None:
    clock = Clock()
    state, _ = vehicle(clock)
    feed(state, M.MAVLink_sys_status_message(0, 0, 0, 0, 12600, 0, -1, 0, 0, 0, 0, 0, 0))
    assert state.telemetry.battery_fraction is None
    feed(state, M.MAVLink_battery_status_message(0, 0, 0, 0, [12600] + [65535] * 9, 0, 0, 420, 64))
    assert state.telemetry.battery_fraction == 0.64 and state.telemetry.energy_used_j == 42000.0


# --- wire text ------------------------------------------------------------------------------------------------
def test_wire_text_is_escaped_of_control_characters() -> None:
    assert printable("PreArm: \x1b[31mred\x1b[0m\nfake log line\r\x00") == (
        "PreArm: \\x1b[31mred\\x1b[0m\\x0afake log line\\x0d\\x00")
    assert printable("ok \u2028 \x85") == "ok \\u2028 \\x85"
    assert printable("é ü Zürich") == "é ü Zürich"
    assert len(printable("x" * 1000, 256)) == 256


def test_statustext_is_escaped_before_it_is_told() -> None:
    clock = Clock()
    state, events = vehicle(clock)
    feed(state, M.MAVLink_statustext_message(M.MAV_SEVERITY_WARNING, b"Arm: \x1b[2Jcleared\nscreen"))
    assert StatusText("Arm: \\x1b[2Jcleared\\x0ascreen", M.MAV_SEVERITY_WARNING) in events


def test_px4_at_rest_reports_constant_position_mode_with_its_gps_position() -> None:
    # PX4 SITL on the ground, ready to fly: ESTIMATOR_STATUS flags 0x3ff (EKF2 sets
    # CONST_POS_MODE whenever the vehicle is at rest); the same bit on ArduPilot means no GPS.
    at_rest = with_(READY, estimator_flags=0x3FF, estimator_name="ESTIMATOR_STATUS")
    assert assess_position(with_(at_rest, estimator_unaided_flags=PX4.estimator_unaided_flags)) == ""
    assert "no GPS position yet (flags 0x03ff)" in assess_position(
        with_(at_rest, estimator_unaided_flags=ARDUPILOT.estimator_unaided_flags))


def test_another_autopilot_than_configured_is_never_taken_for_it() -> None:
    # `demo --config docs/sitl-px4.toml` once flew PX4 SITL with ArduPilot's conventions (the
    # demo's --flavour default won): it armed a PX4 with a mission shifted by a home slot.
    events: list[LinkEvent] = []
    state = VehicleState("ardupilot", events.append, clock=Clock())
    assert not state.on_heartbeat(1, 1, heartbeat(autopilot=M.MAV_AUTOPILOT_PX4))
    assert state.autopilot is None and events == []
    assert state.wrong_autopilot == ("the autopilot 1/1 is px4 (HEARTBEAT autopilot 12), not ardupilot "
                                     "as mavlink.flavour says")
    px4 = VehicleState("px4", events.append, clock=Clock())
    assert px4.on_heartbeat(1, 1, heartbeat(autopilot=M.MAV_AUTOPILOT_PX4)) and px4.wrong_autopilot == ""
