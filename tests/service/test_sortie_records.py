"""The sortie state's records on their own (``schedule``, ``onboard``, ``holds``, ``life``):
each transition returns the new record and its effects, checked here without the machine."""

from __future__ import annotations

import math
from dataclasses import replace

from planner_service.service import events as ev
from planner_service.service.sortie import Binding, Holds, HoldWatch, Life, OnBoard, Sample, Schedule, VehicleSnapshot
from planner_service.service.sortie import effects as fx
from planner_service.service.sortie.hold import MAX_ARRIVAL_GAP_S
from planner_service.service.sortie.life import FLOWN_HEIGHT_M, START_LAPSE_S
from planner_service.service.sortie.mission import HeldMission
from planner_service.service.sortie.onboard import MAX_DOUBTED
from planner_service.service.sortie.schedule import Backoff
from protocol import GeoOrigin, HoverPoint, encode_path
from tests.service.test_sortie_logic import point

BACKOFF = Backoff(max_failures=3, retry_s=2.0, max_retry_s=5.0)
GROUND = VehicleSnapshot(connected=True, position_ok=True, boot_s=1.0, landed_known=True, mode="STABILIZE",
                         battery_fraction=0.97, battery_source="autopilot", time_rate=1.0)


def mission(plan_id: int, *users: str) -> HeldMission:
    pts = tuple(point(k, 100.0 * (k + 1), 50.0, u, k + 1) for k, u in enumerate(users))
    items = encode_path([HoverPoint(p.x_m, p.y_m, p.z_m, p.hold_s) for p in pts], GeoOrigin())
    return HeldMission.fresh(plan_id, items, pts, "ardupilot")


# --- Schedule ---------------------------------------------------------------------------------
def test_failures_wait_twice_as_long_each_time_up_to_the_cap_and_are_given_up_after_the_bound() -> None:
    s, said = Schedule(busy="plan").plan_returned(10.0).failed("plan 1 not flown: x", 10.0, BACKOFF)
    assert (s.failures, s.retry_at, s.dirty, s.busy, s.last_plan_at) == (1, 12.0, True, "", 10.0)
    assert [type(e) for e in said] == [fx.Emit, fx.Log] and isinstance(said[0].event, ev.UploadFailed)
    s, _ = s.failed("again", 20.0, BACKOFF)
    assert s.retry_at == 20.0 + 4.0
    s, said = s.failed("and again", 30.0, BACKOFF)
    assert s.failures == 3 and s.retry_at == math.inf, "given up at max_failures"
    assert isinstance(said[-1], fx.Emit) and isinstance(said[-1].event, ev.UploadAbandoned)
    assert [BACKOFF.wait_s(n) for n in (1, 2, 3, 4)] == [2.0, 4.0, 5.0, 5.0]


def test_a_request_revives_plans_given_up_on_and_only_those() -> None:
    given_up = Schedule(failures=3, retry_at=math.inf, dirty=False).request_in(BACKOFF, 10.0)
    assert (given_up.failures, given_up.retry_at, given_up.dirty) == (0, 0.0, True)
    waiting = Schedule(failures=2, retry_at=50.0, dirty=False).request_in(BACKOFF, 10.0)
    assert (waiting.failures, waiting.retry_at, waiting.dirty) == (2, 50.0, True)
    # requests since the last plan count from the first (the way home's turns: fleet.answer_rank)
    assert (waiting.dirty_at, waiting.request_in(BACKOFF, 12.0).dirty_at) == (10.0, 10.0)
    assert waiting.planning().request_in(BACKOFF, 12.0).dirty_at == 12.0


def test_a_refused_command_waits_as_a_failed_plan_does() -> None:
    s = Schedule(failures=3, commanding="start").command_answered().command_failed(100.0, BACKOFF)
    assert (s.failures, s.retry_at, s.commanding) == (4, 105.0, "")


def test_doubt_makes_plans_stale_and_the_read_back_go_at_once() -> None:
    s = Schedule(version=4, retry_at=99.0, readback_at=99.0, failures=2).in_doubt()
    assert (s.version, s.retry_at, s.readback_at, s.failures) == (5, 0.0, 0.0, 2)
    assert Schedule(retry_at=99.0, failures=5).link_restored(10.0) == Schedule(retry_at=10.0, failures=0)
    assert Schedule(busy="readback").read_back_failed(10.0, 1.5) == Schedule(readback_at=11.5)


def test_a_sortie_ended_drops_only_the_plan_in_search_and_the_next_keeps_plan_ids() -> None:
    assert Schedule(busy="plan", version=2).ended() == Schedule(version=3)
    assert Schedule(busy="upload", version=2).ended().busy == "upload", "an upload in flight is still answered"
    nxt = Schedule(plan_id=7, version=3, failures=2, dirty=False, decided_at=4, last_hover_index=9).next_sortie()
    assert nxt == Schedule(plan_id=7, version=4)


# --- OnBoard ----------------------------------------------------------------------------------
def test_reports_are_kept_only_in_doubt_or_during_an_upload_in_order_and_bounded() -> None:
    known = OnBoard(held=mission(1, "a"), known=True)
    assert known.keep(Sample(1.0, (0.0, 0.0, 0.0), 2), uploading=False) is known
    doubt, said = known.doubting("the link was lost")
    assert (doubt.doubt, doubt.known) == ("the link was lost", False) and isinstance(said[0], fx.Log)
    kept = doubt.keep(Sample(2.0, (0.0, 0.0, 0.0), 2), False).keep(Sample(1.5, (0.0, 0.0, 0.0), 2), False)
    assert [x.boot_s for x in kept.doubted] == [2.0], "an older report is not kept after a newer one"
    many = known
    for i in range(MAX_DOUBTED + 5):
        many = many.keep(Sample(float(i), (0.0, 0.0, 0.0), 2), uploading=True)
    assert len(many.doubted) == MAX_DOUBTED and many.doubted[0].boot_s == 5.0
    emptied, taken = many.replayed()
    assert emptied.doubted == () and len(taken) == MAX_DOUBTED


def test_a_read_back_showing_the_unconfirmed_upload_makes_it_the_mission_held() -> None:
    old, new = mission(1, "a"), mission(2, "a", "b")
    s, _ = OnBoard(held=old, known=True).maybe(new).doubting("plan 2's upload is unknown")
    assert s.matching(new.items, "ardupilot") is new and s.matching(old.items, "ardupilot") is old
    s = replace(s, doubted=(Sample(1.0, (0.0, 0.0, 0.0), 2),))
    confirmed, said = s.confirmed(new, airborne=True)
    assert (confirmed.held, confirmed.known, confirmed.unconfirmed, confirmed.doubt) == (new, True, None, None)
    assert [type(e) for e in said] == [fx.RecordMission, fx.PublishPlan, fx.Log]
    assert len(confirmed.doubted) == 1 and not confirmed.resume_pending, "kept to be judged"
    restarted, said = replace(s, restarted=True).confirmed(old, airborne=True)
    assert [type(e) for e in said] == [fx.Log], "the mission held: nothing to record again"
    assert restarted.doubted == () and restarted.resume_pending and not restarted.restarted


def test_a_read_back_showing_none_of_ours_is_another_stations_or_a_lost_mission() -> None:
    s, _ = OnBoard(held=mission(1, "a"), known=True).doubting("the link was lost")
    assert s.foreign(items=9, home_slots=1) and not s.foreign(items=1, home_slots=1)
    assert not s.maybe(mission(2, "b")).foreign(items=9, home_slots=1), "an upload of ours cut short"
    theirs, said = s.lost(9, airborne=True, foreign=True)
    assert theirs == OnBoard() and "not ours (plan 1)" in said[0].text
    lost, said = s.lost(1, airborne=True, foreign=False)
    assert lost == OnBoard(must_upload=True, resume_pending=True)
    assert isinstance(said[-1], fx.Emit) and isinstance(said[-1].event, ev.VehicleRestarted)
    _, said = replace(s, doubt="the vehicle restarted: x").lost(1, airborne=False, foreign=False)
    assert [type(e) for e in said] == [fx.Log], "a restart is reported once, by the restart itself"


# --- Holds ------------------------------------------------------------------------------------
def test_points_flown_unseen_are_skipped_once_and_a_judged_hold_is_closed() -> None:
    held = mission(1, "a", "b", "c")  # points at items 2, 3, 4
    holds, said = Holds(judged=frozenset({2})).skipped_unseen(held, 4)
    assert holds.judged == {2, 3} and len(said) == 1 and said[0].event.user_id == "b"
    assert holds.skipped_unseen(held, 4)[1] == [], "not skipped twice"
    watching = Holds(watch=HoldWatch(4, (0.0, 0.0, 100.0), 5.0), binding=Binding(4, "c", 3), judged=frozenset({2}))
    assert watching.closed(4) == Holds(judged=frozenset({2, 4}))
    assert watching.abandoned("lost").watch.abandoned and Holds().abandoned("lost") == Holds()
    assert watching.kept_through(3).judged == {2} and watching.kept_through(None).judged == frozenset()


def test_a_hold_is_served_when_the_reports_show_the_time_needed_or_the_user_is_done() -> None:
    w = HoldWatch(3, (0.0, 0.0, 100.0), 5.0, approached=True).feed(Sample(10.0, (50.0, 0.0, 100.0), 3))
    w = w.feed(Sample(11.0, (0.0, 0.0, 100.0), 3)).feed(Sample(20.0, (0.0, 0.0, 100.0), 3))
    assert w.covered_s == 9.0 + min(1.0, MAX_ARRIVAL_GAP_S)
    bound = Holds(watch=w, binding=Binding(3, "u", 7, tasks=10, needed_s=12.0))
    assert bound.served_why() is None, "10 s covered of 12 s needed"
    done = bound.user_said_done("u", 0)
    assert done.binding.done and done.served_why() == "the user's upload is done"
    assert bound.user_said_done("other", 0) is bound and bound.user_said_done("u", 5) is bound
    longer = replace(bound, watch=w.feed(Sample(22.0, (0.0, 0.0, 100.0), 3)))
    assert "12.0 s the bound request needs" in (longer.served_why() or "")
    assert replace(bound, binding=Binding(3, "u", None, why_not="nobody")).served_why() == "nothing to serve (nobody)"
    assert replace(done, early_end=3).served_why() is None, "ended once already"


# --- Life -------------------------------------------------------------------------------------
def test_a_sortie_is_flown_once_ended_once_and_the_next_asked_when_the_vehicle_is_ready() -> None:
    up = replace(GROUND, armed=True, airborne=True, xyz=(0.0, 0.0, FLOWN_HEIGHT_M))
    assert Life().airborne(replace(up, xyz=(0.0, 0.0, FLOWN_HEIGHT_M - 0.1))) == (Life(), []), \
        "the autopilot's word without the height: not flown"
    assert Life().airborne(replace(up, position_ok=False)) == (Life(), [])
    assert Life().airborne(replace(up, airborne=False)) == (Life(), []), "high on the ground: a roof, not a flight"
    life, said = Life().airborne(up)
    assert life.flown and said == [fx.MarkFlown()] and life.airborne(up) == (life, [])
    over, said = life.ended("the vehicle landed")
    assert over.over == "the vehicle landed" and said == [fx.EndSortie("the vehicle landed")]
    assert over.airborne(up) == (over, []), "a sortie over does not fly again"
    begin, said = over.next_wanted(GROUND, repeat=True, next_battery_fraction=0.95)
    assert begin.beginning and said == [fx.BeginSortie(0.97)]
    assert begin.next_wanted(GROUND, repeat=True, next_battery_fraction=0.95) == (begin, []), "asked once"
    assert over.next_wanted(GROUND, repeat=False, next_battery_fraction=0.95) == (over, [])
    assert over.next_wanted(replace(GROUND, battery_fraction=0.9), repeat=True, next_battery_fraction=0.95)[1] == []
    assert replace(over, services=3, warming=True).next_sortie(2) == Life(number=2, warming=True)


def test_a_start_lapses_after_its_bound_on_the_ground_and_degrading_keeps_the_first_reason() -> None:
    started = Life().started_now(100.0)
    assert started.start_lapsed(GROUND, 100.0 + START_LAPSE_S - 0.1, granted=True) == (started, [])
    lapsed, said = started.start_lapsed(GROUND, 100.0 + START_LAPSE_S, granted=False)
    assert not lapsed.started and "the operator's start starts it again" in said[0].text
    degraded, said = Life().degrade("the journal failed")
    assert degraded.degraded == "the journal failed" and [type(e) for e in said] == [fx.Emit, fx.Log]
    assert degraded.degrade("another") == (degraded, [])
    assert degraded.start_refusal(GROUND) == "the service is degraded: the journal failed"
    assert Life().start_refusal(GROUND) is None and Life().served().services == 1
