"""The sortie logic as a pure state machine: a whole sortie, holds judged from the vehicle's
own position, one decision per interval, doubt and read-back, authority, unknown battery
and bounded retries, each in milliseconds (no processes, no sockets)."""

from __future__ import annotations

import copy
import math
import pickle
from dataclasses import dataclass, field, replace
from typing import get_args

import pytest

from planner_service.model import preset
from planner_service.service.rows import RequestRow
from planner_service.service.planning import PlannedPath, PlannedPoint
from planner_service.service.sortie import Rules, Sortie, SortieLogic, VehicleSnapshot, new_sortie
from planner_service.service.sortie import effects as fx
from planner_service.service.sortie import inputs as ins
from planner_service.service.sortie.fleet import FleetView
from planner_service.service.sortie.authority import Authority, next_sortie
from planner_service.service.sortie.holds import Binding
from planner_service.service.sortie.machine import RETURN_ITEM_S
from protocol import Area, GeoOrigin
from protocol.errors import MissionError
from protocol.mission import NAV_RTL

SCENARIO = preset("field")


@dataclass
class FakeWorld:
    requests: dict[str, RequestRow] = field(default_factory=dict)
    served: dict[str, int] = field(default_factory=dict)
    elsewhere: dict[str, str] = field(default_factory=dict)
    """A fleet's: the users another member serves, and why."""

    def request_for(self, user_id: str) -> RequestRow | None:
        return self.requests.get(user_id)

    def served_elsewhere(self, user_id: str) -> str | None:
        return self.elsewhere.get(user_id)

    def services_of(self, user_id: str) -> int:
        return self.served.get(user_id, 0)

    def service_counts(self) -> dict[str, int]:
        return dict(self.served)

    def pending_count(self) -> int:
        return len(self.requests)

    def pending(self) -> list[RequestRow]:
        return [r for r in self.requests.values() if r.tasks > 0]

    def ask(self, user_id: str, x: float, y: float, tasks: int, rid: int) -> None:
        self.requests[user_id] = RequestRow(rid, user_id, x, y, 0.0, tasks, None, 0.0, "pending", "")


def point(k: int, x: float, y: float, user: str, rid: int, tasks: int = 10, hold_s: float = 60.0) -> PlannedPoint:
    return PlannedPoint(k, x, y, 100.0, hold_s, user, rid, tasks, tasks * 1e5, 5000.0, 0.4)


def path(*points: PlannedPoint) -> PlannedPath:
    return PlannedPath(tuple(points), 20_000.0, 50_000.0, "the planned line ends")


def rules(**kw: object) -> Rules:
    return Rules(SCENARIO, GeoOrigin(), Area(500.0, 120.0, 10.0), start_mission=True, **kw)  # type: ignore[arg-type]


def test_the_rules_derive_the_autopilot_once_and_refuse_an_unknown_flavour() -> None:
    px4 = rules(flavour="px4")
    assert px4.autopilot is px4.autopilot and px4.autopilot.name == "px4"
    assert replace(px4, flavour="ardupilot").autopilot.name == "ardupilot"  # derived again
    assert copy.deepcopy(px4) == px4 and pickle.loads(pickle.dumps(px4)).autopilot.name == "px4"
    with pytest.raises(MissionError, match="flavour"):
        rules(flavour="apm")  # when the rules are made, not at the first step that reads it


GROUND = VehicleSnapshot(connected=True, position_ok=True, xyz=(0.0, 0.0, 0.0), boot_s=1.0, landed_known=True,
                 mode="STABILIZE", battery_fraction=1.0, battery_source="autopilot", time_rate=1.0)


def kinds(effects: list[fx.Effect]) -> list[str]:
    return [type(e).__name__ for e in effects]


def only(effects: list[fx.Effect], kind: type) -> list:
    return [e for e in effects if isinstance(e, kind)]


class Run:
    """Drives the logic as the service does; keeps the effects of each step."""

    def __init__(self, world: FakeWorld, r: Rules | None = None) -> None:
        self.logic = SortieLogic(r or rules(), world)
        self.s: Sortie = new_sortie(1, self.logic.rules)
        self.v = GROUND
        self.now = 0.0
        self.effects: list[fx.Effect] = []

    def feed(self, event: ins.Input, **vehicle: object) -> list[fx.Effect]:
        if vehicle:
            self.v = replace(self.v, **vehicle)  # type: ignore[arg-type]
        self.now += 0.05
        self.s, out = self.logic.step(self.s, event, self.v, self.now)
        self.effects += out
        return out

    def tick(self, **vehicle: object) -> list[fx.Effect]:
        return self.feed(ins.Tick(self.now), **vehicle)


def fly_to_first_point(world: FakeWorld) -> tuple[Run, fx.Upload]:
    """Ground: a request, a plan of two points, upload, start, takeoff."""
    world.ask("a", 120.0, 200.0, 10, 1)
    world.ask("b", 320.0, 200.0, 12, 2)
    run = Run(world)
    out = run.tick()
    (plan,) = only(out, fx.MakePlan)
    assert plan.basis.keep_through is None
    out = run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1), point(7, 320.0, 200.0, "b", 2))))
    (up,) = only(out, fx.Upload)
    assert [i.seq for i in up.items] == [0, 1, 2, 3, 4] and up.current_seq is None, "a fresh vehicle is at 0"
    out = run.feed(ins.Uploaded(up))
    assert only(out, fx.Command)[0].kind == "start"
    run.feed(ins.CommandDone(fx.Command("start")), armed=True, mode="AUTO")
    run.tick(airborne=True, seq=1, xyz=(0.0, 0.0, 50.0), boot_s=5.0)
    run.tick(seq=2, xyz=(30.0, 50.0, 100.0), boot_s=8.0)  # on the way to the first point
    return run, up


def test_a_sortie_records_only_holds_the_vehicle_was_seen_at() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    assert run.s.life.flown
    # On the way to point 3 (item 2): not there yet, nothing judged.
    run.tick(seq=2, xyz=(60.0, 100.0, 100.0), boot_s=10.0)
    assert run.s.holds.watch is not None and run.s.holds.watch.phase == "approaching"
    # Arrives: the request in force is bound and the next point is decided from there.
    out = run.tick(seq=2, xyz=(119.0, 200.5, 100.0), boot_s=12.0)
    (plan,) = only(out, fx.MakePlan)
    assert plan.basis.keep_through == 2 and plan.basis.serving == "a" and plan.basis.at_point.hover_index == 3
    assert plan.basis.serving_reward == 0.4, "the planned q of the planned tasks, as the hold's end records it"
    assert run.s.holds.binding.request_id == 1 and run.s.holds.binding.planned
    out = run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2))))
    (up,) = only(out, fx.Upload)
    # Index-preserving: home, takeoff, point 3 kept; the new decision at item 3; RTL.
    assert [i.seq for i in up.items] == [0, 1, 2, 3, 4] and up.keep_through == 2 and up.current_seq is None
    kept, before = up.items[2], run.s.onboard.held.items[2]
    assert (kept.command, kept.x, kept.y, kept.z, kept.param1) == (before.command, before.x, before.y, before.z,
                                                                   before.param1)
    assert [i.seq for i in up.items if i.current] == [2], "the item held stays the one flown (PX4 flies the mark)"
    run.feed(ins.Uploaded(up))
    assert run.s.holds.watch.phase == "holding", "the hold goes on across the replacement"
    # Holds as long as the request needs, then the vehicle flies item 3.
    needed = run.s.holds.binding.needed_s
    end = 12 + math.ceil(needed)
    for t in range(13, end + 1):
        run.tick(seq=2, xyz=(120.5, 199.5, 100.0), boot_s=float(t))
    out = run.tick(seq=3, xyz=(140.0, 210.0, 100.0), boot_s=end + 1.0)
    (svc,) = only(out, fx.RecordService)
    assert (svc.user_id, svc.request_id, svc.tasks, svc.hover_index) == ("a", 1, 10, 3)
    assert svc.held_s == pytest.approx(end - 12.0)
    # Passes item 3's point without ever coming within the radius: no service.
    out = run.tick(seq=4, xyz=(300.0, 280.0, 100.0), boot_s=50.0)
    assert not only(out, fx.RecordService)
    assert [e.event.kind for e in only(out, fx.Emit)] == ["waypoint_skipped"]


def test_a_report_naming_no_item_ends_no_hold_and_skips_no_point() -> None:
    """PX4's MISSION_CURRENT 65535 after an upload marking no item, read by the link as -1
    (``link.progress``): between the vehicle's reports of item 2 it changes nothing."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    out = run.tick(seq=-1, xyz=(60.0, 100.0, 100.0), boot_s=10.0)
    assert not only(out, fx.Emit) and run.s.holds.judged == frozenset()
    run.tick(seq=2, xyz=(119.0, 200.5, 100.0), boot_s=12.0)
    assert run.s.holds.watch.phase == "holding"
    out = run.tick(seq=-1, xyz=(120.0, 200.0, 100.0), boot_s=13.0)
    assert run.s.holds.watch.phase == "holding" and not only(out, fx.RecordService), out
    assert not [e for e in only(out, fx.Emit) if e.event.kind == "waypoint_skipped"]


def test_a_hold_of_a_user_another_member_bound_first_records_nothing() -> None:
    """Two fleet members bound one user at once (each before the other's claim reached it):
    the user uploads to one UAV, the one that bound first; the other records nothing."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    b = run.s.holds.binding
    assert b is not None and b.request_id is not None
    world.elsewhere[b.user_id] = f"uav2 serves {b.user_id} (claimed it first)"
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0 + b.needed_s + 1.0)
    out = run.tick(seq=3, xyz=(200.0, 300.0, 100.0), boot_s=22.0 + b.needed_s)
    assert not only(out, fx.RecordService)
    assert any("nothing recorded: uav2 serves" in e.event.detail for e in only(out, fx.Emit))


def bound_to_a_user_uav2_owns(world: FakeWorld) -> tuple[Run, Binding]:
    """Arrived at the first point, its hold bound to a request, then uav2's claim on that user
    heard (uav2 bound it first): the run and the binding."""
    run, _ = fly_to_first_point(world)
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    b = run.s.holds.binding
    assert b is not None and b.request_id is not None
    run.feed(ins.FleetHeard(FleetView(owners={b.user_id: "uav2"})))
    return run, b


def test_a_hold_whose_user_another_member_bound_first_records_nothing_after_that_members_hold_ended() -> None:
    """Over a slow radio (100 ms, 5 % loss, N=5: user-12 served by uav2 and uav3) the other
    member's claim was heard during the hold, then went when its own hold ended, a second
    before this one's: the user is still the other's."""
    run, b = bound_to_a_user_uav2_owns(FakeWorld())
    run.feed(ins.FleetHeard(FleetView()))  # uav2 left the point: its claim is gone
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0 + b.needed_s + 1.0)
    out = run.tick(seq=3, xyz=(200.0, 300.0, 100.0), boot_s=22.0 + b.needed_s)
    assert not only(out, fx.RecordService)
    assert any("nothing recorded: uav2 serves" in e.event.detail for e in only(out, fx.Emit))


def test_a_hold_cut_short_serves_what_it_carried() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    needed = run.s.holds.binding.needed_s
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0 + needed / 2)
    out = run.tick(seq=2, xyz=(150.0, 200.0, 100.0), boot_s=21.0 + needed / 2)  # pushed away
    (svc,) = only(out, fx.RecordService)
    assert 0 < svc.tasks < 10


def test_a_second_service_cut_short_records_the_backlog_it_was_bound_to() -> None:
    # The fairness rule (3) lets a user be served again only with more than beta tasks: the
    # binding checks that on the backlog. A hold then cut short (the battery's reserve, in a
    # CI run: 1 task of 16 carried) is recorded with the backlog it was bound to, which the
    # audit judges, beside the tasks it carried.
    world = FakeWorld(served={"a": 1})
    run, _ = fly_to_first_point(world)
    beta = SCENARIO.fairness_threshold_tasks
    world.ask("a", 120.0, 200.0, beta + 1, 5)
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    assert run.s.holds.binding.user_id == "a" and run.s.holds.binding.tasks == beta + 1
    needed = run.s.holds.binding.needed_s
    out = run.tick(seq=3, xyz=(140.0, 200.0, 100.0), boot_s=20.0 + needed / (beta + 1))  # the hold ended early
    (svc,) = only(out, fx.RecordService)
    assert svc.user_id == "a" and svc.tasks < beta < svc.bound_tasks == beta + 1


def test_nothing_is_planned_while_the_vehicles_clock_rate_is_unknown() -> None:
    # A service restarted in the air beside a simulator at x80 planned its first seconds as
    # if the vehicle's clock ran at wall speed: the battery a second old counted as a second
    # of flight old, not 80, and the vehicle's own failsafe fired on the way home. Arriving
    # at a point, the decision waits for the rate; a decision already being searched when
    # the rate went unknown (a link reset) is dropped.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    out = run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0, time_rate=None)
    assert run.s.holds.watch.phase == "holding" and not only(out, fx.MakePlan)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=21.0, time_rate=80.0), fx.MakePlan)
    out = run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2))), time_rate=None)
    assert not only(out, fx.Upload) and run.s.schedule.dirty


def test_a_hold_longer_than_needed_ends_once_the_next_decision_is_on_board() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    out = run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    (plan,) = only(out, fx.MakePlan)
    needed = run.s.holds.binding.needed_s
    run.tick(seq=2, boot_s=20.0 + needed + 1)
    assert not only(run.effects, fx.Command)[1:], "no early end before the replacement is uploaded"
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    out = run.feed(ins.Uploaded(up))
    out += run.tick(seq=2, boot_s=20.0 + needed + 2)
    (cmd,) = only(out, fx.Command)
    assert (cmd.kind, cmd.seq) == ("set_current", 3)


@pytest.mark.parametrize("after", ["the pilot's LOITER and back to AUTO", "the journal failed"])
def test_a_hold_is_not_ended_early_without_the_authority_or_degraded(after: str) -> None:
    # Found by reading: the early end (MAV_CMD_DO_SET_MISSION_CURRENT) was sent without
    # the authority, and in the degraded state.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0), fx.MakePlan)
    needed = run.s.holds.binding.needed_s
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    run.feed(ins.Uploaded(up))
    if after == "the journal failed":
        run.feed(ins.PartFailed("the journal failed"))
    else:
        run.feed(ins.ModeChanged("LOITER", commanded=False), mode="LOITER")
        run.feed(ins.ModeChanged("AUTO", commanded=False), mode="AUTO")
    out = run.tick(seq=2, boot_s=20.0 + needed + 2)
    assert not only(out, fx.Command), after


def test_restart_read_back_and_a_lost_mission_resumed_from_where_it_is() -> None:
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    (searching,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0), fx.MakePlan)
    out = run.feed(ins.Restarted("its clock went back"), boot_s=1.0, mode="LOITER", seq=0)
    assert [e.event.kind for e in only(out, fx.Emit)][:2] == ["authority_revoked", "vehicle_restarted"]
    assert not only(out, fx.RecordService), "a hold of no measurable length serves nothing"
    # The decision being searched was made on the mission the restart lost: dropped.
    out = run.feed(ins.Planned(searching.basis, path(point(9, 400.0, 300.0, "b", 2))))
    assert not only(out, fx.Upload)
    assert only(out, fx.ReadBack), "read back before anything else"
    assert run.s.authority.state == "revoked", "a restart ends the authority"
    out = run.feed(ins.ReadBackDone(()))  # the mission is gone
    assert run.s.onboard.must_upload and run.s.onboard.resume_pending
    (plan,) = only(out, fx.MakePlan)
    assert plan.basis.keep_through is None and plan.basis.reason == "the vehicle lost its mission"
    (up2,) = only(run.feed(ins.Planned(plan.basis, path(point(7, 320.0, 200.0, "b", 2)))), fx.Upload)
    assert up2.current_seq == 2, "a fresh mission in the air is flown from its first point"
    out = run.feed(ins.Uploaded(up2))
    assert not only(out, fx.Command), "the mission is on board; only the operator resumes it"
    (asked,) = [e.event for e in only(out, fx.Emit) if e.event.kind == "resume_needed"]
    assert "plan 2" in asked.detail and "LOITER" in asked.detail, asked.detail
    assert not any(e.event.kind == "resume_needed" for e in only(run.tick(), fx.Emit)), "told once"
    # The link's own restart check can come after all that (its clock reports over 0.5 s; a
    # clean-clone run): the same restart, the mission read back is plan 2: not told again.
    out = run.feed(ins.Restarted("its clock went back"), boot_s=2.0, mode="LOITER", seq=2)
    only(out, fx.ReadBack)
    out = run.feed(ins.ReadBackDone(up2.items)) + run.tick(seq=2)
    assert run.s.onboard.known and run.s.onboard.held.plan_id == 2
    assert not any(e.event.kind == "resume_needed" for e in only(out, fx.Emit)), "one restart, told once"
    run.s, out, ok, _ = run.logic.operator(run.s, ins.OperatorAsked("start"), run.v, run.now)
    assert ok and run.s.authority.granted
    (plan,) = only(out, fx.MakePlan)  # from where the vehicle is now, then resumed
    (up3,) = only(run.feed(ins.Planned(plan.basis, path(point(7, 320.0, 200.0, "b", 2)))), fx.Upload)
    (cmd,) = only(run.feed(ins.Uploaded(up3)), fx.Command)
    assert (cmd.kind, cmd.seq) == ("resume", 2)


def test_a_hold_found_under_way_is_left_to_the_autopilot() -> None:
    # The service (re)started with the vehicle already holding: when the hold began is not
    # known, so no decision is made there (a replacement would start the hold again).
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.s = replace(run.s, holds=replace(run.s.holds, watch=None))
    out = run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    assert run.s.holds.watch.phase == "holding" and not run.s.holds.watch.approached
    assert not only(out, fx.MakePlan) and not only(run.tick(seq=2, boot_s=25.0), fx.MakePlan)


def test_a_link_gap_read_back_as_ours_keeps_the_hold() -> None:
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    (searching,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0), fx.MakePlan)
    run.feed(ins.Restored("AUTO"))
    out = run.feed(ins.Planned(searching.basis, path(point(9, 400.0, 300.0, "b", 2))))
    (rb,) = only(out, fx.ReadBack)
    out = run.feed(ins.ReadBackDone(up.items))
    assert run.s.onboard.known and run.s.holds.watch is not None and run.s.holds.watch.phase == "holding"
    # The decision dropped during the doubt is made again from the point.
    (plan,) = only(out, fx.MakePlan)
    assert plan.basis.keep_through == 2


def test_holds_flown_while_in_doubt_are_judged_once_the_read_back_shows_our_mission() -> None:
    # On a lossy link a read-back takes seconds, tens of seconds of flight at x40: a CI run
    # recorded 2 services of a sortie whose vehicle held at five points. The reports seen in
    # the doubt are kept and judged once the vehicle is known to fly our mission.
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    (rb,) = only(run.feed(ins.Restored("AUTO")), fx.ReadBack)
    for t in range(10, 80):  # the whole hold at point 3 (item 2), in doubt
        run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=float(t))
    run.tick(seq=3, xyz=(160.0, 200.0, 100.0), boot_s=82.0)  # and on to item 3
    assert not only(run.effects, fx.RecordService) and run.s.holds.watch.phase == "approaching"
    out = run.feed(ins.ReadBackDone(up.items))
    (svc,) = only(out, fx.RecordService)
    assert (svc.user_id, svc.tasks, svc.hover_index) == ("a", 10, 3) and svc.held_s == pytest.approx(69.0)
    assert run.s.holds.watch is not None and run.s.holds.watch.seq == 3 and run.s.onboard.doubted == ()


def test_reports_in_doubt_are_judged_against_the_upload_that_went_through() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=10.0), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    run.feed(ins.NotUploaded(up, "no ACK", outcome_unknown=True))
    for t in range(11, 80):
        run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=float(t))
    run.tick(seq=3, xyz=(160.0, 210.0, 100.0), boot_s=82.0)  # item 3: point 7 before, point 9 now
    out = run.feed(ins.ReadBackDone(up.items))  # the upload went through
    (svc,) = only(out, fx.RecordService)
    assert (svc.hover_index, svc.held_s) == (3, 69.0)
    watch = run.s.holds.watch
    assert watch.seq == 3 and watch.xyz == (400.0, 300.0, 100.0) and watch.phase == "approaching", \
        "item 3 is the new plan's point, not yet reached"


def test_holds_flown_while_an_upload_waits_for_its_ack_are_judged_against_the_mission_it_took() -> None:
    # A CI run at 20 % loss: the vehicle committed plan 2 at once, its ACK reached the
    # service 2 s later (80 s of flight at x40), and the holds flown meanwhile at plan 2's
    # points were judged against plan 1's (never reached: skipped): 2 services of 5 holds.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=10.0), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    for t in range(11, 60):  # the rest of the hold at point 3
        run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=float(t))
    for t in range(60, 130):  # then plan 2's item 3, point 9, held (plan 1's was point 7)
        run.tick(seq=3, xyz=(400.0, 300.0, 100.0), boot_s=float(t))
    run.tick(seq=4, xyz=(380.0, 280.0, 100.0), boot_s=131.0)
    assert not only(run.effects, fx.RecordService)
    out = run.feed(ins.Uploaded(up))
    assert [(s.hover_index, s.user_id) for s in only(out, fx.RecordService)] == [(3, "a"), (9, "b")]


def test_a_hold_recorded_in_a_step_counts_at_the_next_arrival_of_that_step() -> None:
    """CI on PX4 SITL (x10, MAVSDK, a loaded machine): user-0 served twice, 5 tasks then 13,
    a repeat that the fairness rule (3) refuses at 13 tasks. The reports kept while an upload
    waited for its ACK held a whole hold and the arrival at the next point; replayed in one
    step, the first hold's record was an effect not yet in the journal when the arrival bound
    the nearest eligible user, so its user counted as never served and its request as pending."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=10.0), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 140.0, 220.0, "b", 2)))), fx.Upload)
    for t in range(11, 60):  # the rest of the hold at point 3 (a)
        run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=float(t))
    for t in range(60, 130):  # then point 9, nearer a than b
        run.tick(seq=3, xyz=(140.0, 220.0, 100.0), boot_s=float(t))
    run.tick(seq=4, xyz=(160.0, 240.0, 100.0), boot_s=131.0)
    out = run.feed(ins.Uploaded(up))
    assert [(s.hover_index, s.user_id) for s in only(out, fx.RecordService)] == [(3, "a"), (9, "b")]


def test_reports_in_doubt_count_for_nothing_when_the_vehicle_holds_another_mission() -> None:
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    run.feed(ins.Restored("AUTO"))
    for t in range(10, 80):
        run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=float(t))
    out = run.feed(ins.ReadBackDone(up.items[:2]))  # not ours: nothing it flew is ours to record
    assert not only(out, fx.RecordService) and run.s.onboard.doubted == ()


def test_another_stations_mission_ends_the_authority_and_is_left_alone() -> None:
    # A second ground station uploaded its own 4-item mission while the vehicle flew ours in
    # AUTO: the service saw nothing, and counted the landing as its own. MISSION_CURRENT's
    # count shows it; the read-back tells whose it is.
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    assert not only(run.tick(seq=2, mission_total=len(up.items) - 1, boot_s=9.0), fx.ReadBack), "ours, less home"
    out = run.tick(seq=1, mission_total=3, boot_s=10.0)
    (rb,) = only(out, fx.ReadBack)
    assert "counts 3 mission items" in rb.why
    theirs = tuple(replace(i, x=i.x + 1000) for i in up.items[:4])
    out = run.feed(ins.ReadBackDone(theirs))
    assert run.s.authority.state == "revoked" and "not ours" in run.s.authority.detail
    assert run.s.onboard.held is None and not run.s.onboard.must_upload and not run.s.onboard.resume_pending
    assert not only(out, fx.MakePlan) and not only(run.tick(seq=2, mission_total=3, boot_s=11.0), fx.MakePlan), \
        "another station's mission is not replaced"


def test_a_count_a_read_back_showed_to_be_ours_doubts_nothing_again() -> None:
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    (rb,) = only(run.tick(seq=2, mission_total=99, boot_s=10.0), fx.ReadBack)
    run.feed(ins.ReadBackDone(up.items))  # ours after all (the autopilot counts otherwise)
    assert run.s.authority.granted and run.s.onboard.held is not None
    assert not only(run.tick(seq=2, mission_total=99, boot_s=11.0), fx.ReadBack)


def test_uncommanded_mode_change_ends_authority_and_no_command_follows() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    out = run.feed(ins.ModeChanged("LOITER", commanded=False), mode="LOITER")
    assert [e.event.kind for e in only(out, fx.Emit)] == ["authority_revoked"]
    assert run.s.authority.state == "revoked"
    out = run.tick(battery_fraction=0.05)  # the battery guard would fire with authority
    assert not only(out, fx.Command)
    out = run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    assert not only(out, fx.MakePlan), "the pilot has the vehicle: no plans for a mission it does not fly"


def test_a_pilots_landing_ends_the_sortie_and_the_next_never_arms() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.ModeChanged("LAND", commanded=False), mode="LAND")
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False)
    assert run.s.life.over == "the vehicle landed"
    out = run.tick(armed=False)
    (begin,) = only(out, fx.BeginSortie)
    world.requests.clear()
    run.feed(ins.SortieBegun(2))
    assert run.s.life.number == 2 and run.s.authority.state == "none"
    world.ask("c", 200.0, 200.0, 9, 3)
    out = run.feed(ins.RequestIn("c", 9))
    (plan,) = only(out, fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(5, 200.0, 200.0, "c", 3)))), fx.Upload)
    out = run.feed(ins.Uploaded(up))
    out += run.tick()
    assert not only(out, fx.Command), "no arming after a landing the service did not command"
    s, out, ok, reply = run.logic.operator(run.s, ins.OperatorAsked("start"), run.v, run.now)
    assert ok and only(out, fx.Command)[0].kind == "start"


def test_after_its_own_landing_the_next_sortie_waits_for_the_operator() -> None:
    # The configuration's authority (start_mission) is for the first sortie of the process:
    # it armed again 1.3 s after the next request when a landing had been counted as its own.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.ModeChanged("RTL", commanded=True), mode="RTL")
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False, xyz=(0.0, 0.0, 0.3))
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False)  # reported after the disarming
    run.tick()
    assert run.s.authority.granted, "the autopilot's disarming on touching down at our return"
    (plan,) = only(run.feed(ins.SortieBegun(2)), fx.MakePlan)
    assert run.s.authority.state == "none"
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(5, 200.0, 200.0, "c", 3)))), fx.Upload)
    out = run.feed(ins.Uploaded(up)) + run.tick()
    assert not only(out, fx.Command), "no arming before the operator's start"
    s, out, ok, _ = run.logic.operator(run.s, ins.OperatorAsked("start"), run.v, run.now)
    assert ok and only(out, fx.Command)[0].kind == "start"


@pytest.mark.parametrize("armed, airborne, xyz, why", [
    (False, True, (120.0, 200.0, 100.0), "a disarming in the air (a motor kill)"),
    (False, False, (0.0, 0.0, 0.0), "a disarming on the ground before the flight"),
    (True, False, (0.0, 0.0, 0.0), "an arming by someone else"),
])
def test_an_arming_or_disarming_the_service_did_not_command_ends_the_authority(
        armed: bool, airborne: bool, xyz: tuple[float, float, float], why: str) -> None:
    world = FakeWorld()
    if airborne:
        run, _ = fly_to_first_point(world)
    else:
        world.ask("a", 120.0, 200.0, 10, 1)
        run = Run(world)
        run.tick(armed=not armed)
    out = run.feed(ins.ArmedChanged(armed, commanded=False), armed=armed, airborne=airborne, xyz=xyz)
    assert run.s.authority.state == "revoked", why
    assert "authority_revoked" in [e.event.kind for e in only(out, fx.Emit)]
    assert ("armed" if armed else "disarmed") in run.s.authority.detail
    out = run.tick(armed=False, airborne=False)
    assert not only(out, fx.Command), "nothing commanded after it"


def test_the_services_own_arming_and_its_landings_disarming_keep_the_authority() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    assert run.s.authority.granted
    run.feed(ins.ArmedChanged(True, commanded=True), armed=True)
    assert run.s.authority.granted
    # The disarming reported while the vehicle flies its mission, away from its return: not ours.
    assert run.s.authority.on_arming(False, commanded=False, landing=False).state == "revoked"
    # At the mission's return item: the touchdown's disarming, its report within 2 s.
    rtl = run.s.onboard.held.rtl_seq
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False, seq=rtl, xyz=(0.0, 0.0, 0.5))
    run.now += 1.5
    run.tick(airborne=False)
    run.now += 5.0
    run.tick()
    assert run.s.authority.granted
    # Reported landed first at the return item, then disarmed: the landing's.
    run2, _ = fly_to_first_point(FakeWorld())
    run2.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, seq=run2.s.onboard.held.rtl_seq, xyz=(0.0, 0.0, 0.1))
    run2.feed(ins.ArmedChanged(False, commanded=False), armed=False)
    assert run2.s.authority.granted


def test_a_disarming_on_the_way_home_not_followed_by_a_landing_is_nobodys() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False, seq=run.s.onboard.held.rtl_seq,
             xyz=(50.0, 50.0, 60.0))
    run.now += 1.0
    run.tick()
    assert run.s.authority.granted, "its landing's report may still come"
    run.now += 1.5
    out = run.tick()
    assert run.s.authority.state == "revoked" and "not reported landed within 2 s" in run.s.authority.detail
    assert "authority_revoked" in [e.event.kind for e in only(out, fx.Emit)]


def test_a_disarming_in_the_air_reported_landed_first_is_not_a_landing() -> None:
    # ArduCopter's land detector calls a vehicle disarmed in the air landed at once: its
    # EXTENDED_SYS_STATE may reach the service before the heartbeat showing the disarming.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, xyz=(30.0, 50.0, 40.0))
    assert run.s.life.over is not None
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False)
    assert run.s.authority.state == "revoked", "away from the mission's return: not ours"


def test_a_service_started_beside_a_vehicle_armed_on_the_ground_has_no_authority() -> None:
    world = FakeWorld()
    run = Run(world)
    run.s = replace(run.s, life=replace(run.s.life, just_started=True))
    out = run.tick(armed=True)
    assert run.s.authority.state == "revoked" and "armed on the ground" in run.s.authority.detail
    assert not only(out, fx.Command)


def test_unknown_battery_neither_plans_nor_arms() -> None:
    world = FakeWorld()
    world.ask("a", 120.0, 200.0, 10, 1)
    run = Run(world)
    out = run.tick(battery_fraction=None, battery_source="unknown")
    assert not only(out, fx.MakePlan)
    # A fallback estimate from the model plans, but arming waits for a reading.
    out = run.tick(battery_fraction=0.9, battery_source="model")
    (plan,) = only(out, fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1)))), fx.Upload)
    out = run.feed(ins.Uploaded(up))
    assert not only(out, fx.Command)
    out = run.tick(battery_fraction=0.9, battery_source="autopilot")
    assert only(out, fx.Command)[0].kind == "start"


def test_failed_uploads_back_off_and_stop_after_the_bound() -> None:
    world = FakeWorld()
    world.ask("a", 120.0, 200.0, 10, 1)
    run = Run(world, rules(max_failures=3))
    waits = []
    for n in range(3):
        run.now = max(run.now, run.s.schedule.retry_at)
        out = run.tick()
        (plan,) = only(out, fx.MakePlan)
        (up,) = only(run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1)))), fx.Upload)
        run.feed(ins.NotUploaded(up, "NO_ANSWER"))
        waits.append(run.s.schedule.retry_at - run.now)
    assert waits[0] == pytest.approx(1.0, abs=0.1) and waits[1] == pytest.approx(2.0, abs=0.1)
    assert math.isinf(run.s.schedule.retry_at)
    assert "upload_abandoned" in [e.event.kind for e in only(run.effects, fx.Emit)]
    run.now += 100.0
    assert not only(run.tick(), fx.MakePlan)
    run.feed(ins.RequestIn("a", 11))
    assert run.s.schedule.failures == 0


def test_operator_hold_releases_authority() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    s, out, ok, reply = run.logic.operator(run.s, ins.OperatorAsked("hold"), run.v, run.now)
    assert ok and only(out, fx.Command)[0].kind == "hold" and s.authority.state == "none"


def test_a_backlog_grown_since_the_plan_lengthens_the_hold_it_is_bound_to() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    world.ask("a", 120.0, 200.0, 20, 5)  # twice the tasks the plan saw, before the vehicle arrives
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0), fx.MakePlan)
    b = run.s.holds.binding
    assert (b.request_id, b.tasks, b.planned) == (5, 20, False)
    assert b.needed_s > 60.0, "the planned 60 s hold cannot carry 20 tasks"
    assert plan.basis.at_point.hold_s >= b.needed_s + 1.0, "the planner pays for the longer hold"
    # ... and counts the q the hold's end will record: 20 tasks for the planned energy
    assert plan.basis.serving_reward == pytest.approx(SCENARIO.task_reward_weight * 20 / SCENARIO.task_max
                                                 - 5000.0 / SCENARIO.energy_norm_j)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    assert up.items[2].param1 >= b.needed_s + 1.0 and up.mission.point_at(2).hold_s >= b.needed_s


def test_a_hold_the_battery_cannot_carry_is_cut_to_what_keeps_the_reserve() -> None:
    # A backlog grown tenfold: the hold it needs would leave the vehicle below its reserve
    # on the way home, by 2000 J. The planner, paying for the whole hold, finds nothing
    # more to fly; the hold is cut by the hovering those 2000 J buy.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    world.ask("a", 120.0, 200.0, 100, 5)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0), fx.MakePlan)
    bound = plan.basis.at_point.hold_s
    assert bound >= run.s.holds.binding.needed_s > 300.0
    home = PlannedPath((), 4000.0, SCENARIO.energy_floor_j - 2000.0, "the energy reserve")
    (up,) = only(run.feed(ins.Planned(plan.basis, home)), fx.Upload)
    cut = bound - 2000.0 / SCENARIO.hover_power_w
    assert up.mission.point_at(2).hold_s == pytest.approx(cut)
    assert up.items[2].param1 == math.ceil(cut) and up.items[3].command == NAV_RTL


def test_a_restart_never_gives_back_an_authority_the_pilot_ended() -> None:
    # A forged restart (two reports of a new clock in one datagram) 0.5 s after the pilot's
    # LOITER gave the authority back: the service switched the vehicle to AUTO again.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.ModeChanged("LOITER", commanded=False), mode="LOITER", boot_s=1.0)
    assert run.s.authority.state == "revoked"
    out = run.feed(ins.Restarted("its clock went back"))
    assert run.s.authority.state == "revoked" and "authority_granted" not in [e.event.kind for e in only(out, fx.Emit)]
    assert not only(run.effects[-len(out):], fx.Command)


def test_a_restart_ends_the_authority_and_after_it_any_mode_change_is_unexplained() -> None:
    # After a restart (forged or a brown-out) the pilot's LOITER and LAND ended nothing: the
    # mode expected was unset, and unset explained every change.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    out = run.feed(ins.Restarted("its clock went back"))
    assert run.s.authority.state == "revoked" and "authority_revoked" in [e.event.kind for e in only(out, fx.Emit)]
    given = Authority.by_operator("again")
    assert given.on_mode("LOITER", armed=True, mission_return=False).state == "revoked", "expected unknown"
    assert given.on_mode("LAND", armed=False, mission_return=True).state == "revoked"
    assert given.commanding("AUTO").on_mode("AUTO", armed=True, mission_return=False).granted


def test_a_restart_that_landed_the_vehicle_leaves_the_next_sortie_to_the_operator() -> None:
    # SITL killed in the air comes back on the ground, disarmed, in STABILIZE: the sortie
    # ends, and the next begins without authority whichever of the mode, the landing and
    # the restart is judged first.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.ModeChanged("STABILIZE", commanded=False), mode="STABILIZE", boot_s=1.0)
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, armed=False)
    assert run.s.life.over is not None and run.s.authority.state == "revoked"
    run.feed(ins.Restarted("its clock went back"))
    run.tick()
    run.feed(ins.SortieBegun(2))
    assert not run.s.authority.granted, run.s.authority


def test_a_restart_seen_after_the_next_sortie_began_reads_back_our_last_mission_not_a_strangers() -> None:
    # PX4 SITL restarted in a hold is back on the ground within a second, full battery: the
    # landing ends sortie 1 and sortie 2 begins before the restart is recognised; the
    # read-back then shows sortie 1's mission (PX4's dataman keeps it).
    run, up = fly_to_first_point(FakeWorld())
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, armed=False, boot_s=1.0)
    (plan,) = only(run.feed(ins.SortieBegun(2)), fx.MakePlan)
    run.feed(ins.Restarted("its clock went back"))
    out = run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1))))  # stale: not uploaded
    assert not only(out, fx.Upload) and only(out + run.tick(), fx.ReadBack)
    out = run.feed(ins.ReadBackDone(up.items))
    said = " ".join(e.text for e in only(out, fx.Log))
    assert "plan 1 of the sortie before" in said and "another station" not in said, said
    assert not [e for e in only(out, fx.Emit) if e.event.kind == "authority_revoked"]
    assert run.s.onboard.held is None and run.s.onboard.doubt is None
    # a mission no sortie of ours uploaded is still a stranger's
    run2, up2 = fly_to_first_point(FakeWorld())
    run2.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, armed=False, boot_s=1.0)
    (plan2,) = only(run2.feed(ins.SortieBegun(2)), fx.MakePlan)
    run2.feed(ins.Restarted("its clock went back"))
    run2.feed(ins.Planned(plan2.basis, path(point(3, 120.0, 200.0, "a", 1))))
    out = run2.feed(ins.ReadBackDone(tuple(replace(i, x=i.x + 5000) if i.x else i for i in up2.items)))
    assert "another station's" in " ".join(e.text for e in only(out, fx.Log))


def test_a_service_started_with_the_vehicle_in_the_air_has_no_authority() -> None:
    world = FakeWorld()
    run = Run(world)
    run.s = replace(run.s, life=replace(run.s.life, just_started=True))
    assert run.s.authority.granted  # the configuration's
    run.tick(airborne=None, landed_known=False)
    assert run.s.authority.granted and run.s.life.just_started, "not known yet whether it flies"
    out = run.tick(airborne=True, armed=True, landed_known=True, mode="AUTO")
    assert run.s.authority.state == "revoked" and "in the air" in run.s.authority.detail
    assert "authority_revoked" in [e.event.kind for e in only(out, fx.Emit)]
    grounded = Run(world)
    grounded.s = replace(grounded.s, life=replace(grounded.s.life, just_started=True))
    grounded.tick()
    assert grounded.s.authority.granted and not grounded.s.life.just_started


def test_the_holds_margins_are_paid_for_out_of_the_reserve() -> None:
    # A path whose last point leaves the battery just above the floor: the margins' hovering
    # (a command's latency at x80 is 8 s a point) would break it, so that point is cut.
    run = Run(FakeWorld())
    floor = SCENARIO.energy_floor_j
    tight = PlannedPath((point(3, 120.0, 200.0, "a", 1), point(7, 320.0, 200.0, "b", 2)), 20_000.0, floor + 1000.0,
                        "the planned line ends")
    fast = run.logic._with_margins(tight, 1.0 + 0.1 * 80)
    assert [p.user_id for p in fast.points] == ["a"] and fast.stop_reason.startswith("the energy reserve")
    assert fast.battery_after_j >= floor
    assert fast.battery_after_j + fast.predicted_energy_j == pytest.approx(tight.battery_after_j + tight.predicted_energy_j)
    slow = run.logic._with_margins(tight, 1.0)
    assert len(slow.points) == 2 and slow.points[0].hold_s == 61.0


def test_a_mission_on_the_ground_starts_at_its_takeoff_after_a_sortie() -> None:
    # The autopilot keeps its index across an upload: after a sortie it points at the last
    # mission's return; the next first mission must be flown from its takeoff.
    world = FakeWorld()
    world.ask("a", 120.0, 200.0, 10, 1)
    run = Run(world)
    run.v = replace(run.v, seq=6)
    (plan,) = only(run.tick(), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1)))), fx.Upload)
    assert up.current_seq == 1


def test_the_user_served_is_the_models_choice_at_arrival() -> None:
    # The plan counted on "a" at the first point; by the arrival "a" has nothing left and "c",
    # as near, has a backlog: the model's rule (the nearest eligible) serves "c".
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    world.ask("a", 120.0, 200.0, 0, 5)
    world.ask("c", 125.0, 195.0, 9, 6)
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    b = run.s.holds.binding
    assert (b.user_id, b.request_id, b.tasks, b.planned) == ("c", 6, 9, False)


def holding_at_the_first_point(world: FakeWorld) -> tuple[Run, float]:
    """Arrived at the first point, the decision made there on board, a quarter of the hold
    the bound request needs flown: the run and that need (s)."""
    run, _ = fly_to_first_point(world)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    run.feed(ins.Uploaded(up))
    needed = run.s.holds.binding.needed_s
    assert not only(run.tick(seq=2, boot_s=20.0 + needed / 4), fx.Command)
    return run, needed


def test_a_user_done_early_ends_the_hold_but_not_the_physics() -> None:
    world = FakeWorld()
    run, needed = holding_at_the_first_point(world)
    out = run.feed(ins.RequestIn("a", 0))  # "nothing more to offload"
    out += run.tick(seq=2, boot_s=21.0 + needed / 4)
    assert [(c.kind, c.seq) for c in only(out, fx.Command)] == [("set_current", 3)]
    (svc,) = only(run.tick(seq=3, xyz=(150.0, 200.0, 100.0), boot_s=22.0 + needed / 4), fx.RecordService)
    assert 0 < svc.tasks < 10, "a quarter of the hold carries about a quarter of the tasks"


def test_on_the_way_home_a_new_request_is_decided_on_only_if_the_battery_allows_a_point() -> None:
    # A decision whose first step (the model's, with the battery the vehicle reports)
    # has no point to fly to would find nothing whatever it searched: it is not made.
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    rtl = up.items[-1].seq
    run.tick(seq=rtl, xyz=(200.0, 150.0, 100.0), boot_s=60.0, battery_fraction=0.105)  # flying home
    run.now += 2.0
    world.ask("c", 300.0, 300.0, 10, 9)
    assert not only(run.feed(ins.RequestIn("c", 10)) + run.tick(), fx.MakePlan)
    assert not only(run.tick(), fx.MakePlan), "nor at a later tick"
    world.ask("d", 250.0, 200.0, 10, 10)
    before = run.s
    (plan,) = only(run.feed(ins.RequestIn("d", 10), battery_fraction=0.6), fx.MakePlan)
    assert plan.basis.reason == "new requests on the way home" and plan.basis.keep_through == rtl - 1
    # the configured margin is the planner's too: 50 % of the battery kept back leaves nothing
    run.s, run.logic = before, SortieLogic(rules(energy_margin_j=0.5 * SCENARIO.battery_j), world)
    assert not only(run.feed(ins.RequestIn("d", 10)), fx.MakePlan)


def _replacement_arriving_late(world: FakeWorld, then: PlannedPoint) -> tuple[Run, list[fx.Effect]]:
    """The decision made at point 3 goes up a slow link; meanwhile the vehicle ends that hold
    and arrives at the old mission's next point (7, item 3), where the new mission flies
    ``then``; the replacement is accepted there. What the vehicle did meanwhile is judged
    then, against the mission it took (it may have flown the new one before its ACK came)."""
    run, _ = fly_to_first_point(world)
    out = run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=12.0)
    (plan,) = only(out, fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(then, point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    run.tick(seq=3, xyz=(200.0, 200.0, 100.0), boot_s=60.0)  # the autopilot's timer ended the hold
    run.tick(seq=3, xyz=(319.0, 200.0, 100.0), boot_s=70.0)
    assert not only(run.effects, fx.RecordService) and run.s.holds.watch.seq == 2, "kept until the upload's outcome"
    out = run.feed(ins.Uploaded(up))
    assert [s.hover_index for s in only(out, fx.RecordService)] == [3]
    return run, out


def test_a_replacement_that_flies_the_point_reached_meanwhile_keeps_its_hold() -> None:
    # The new mission flies point 7 at item 3 too: the vehicle holds on there, one hold, one
    # service (judging it "replaced" and watching it again bound a second user at the same
    # point in the same stay: two services the vehicle's log shows as one).
    world = FakeWorld()
    run, out = _replacement_arriving_late(world, point(7, 320.0, 200.0, "b", 2))
    assert run.s.holds.watch.seq == 3 and run.s.holds.watch.phase == "holding" and run.s.holds.binding.user_id == "b"
    (plan,) = only(out, fx.MakePlan)  # and decides from there at once
    assert plan.basis.keep_through == 3 and plan.basis.at_point.hover_index == 7 and plan.basis.serving == "b"
    needed = run.s.holds.binding.needed_s
    run.tick(seq=3, xyz=(320.0, 200.0, 100.0), boot_s=70.0 + needed)
    out = run.tick(seq=4, xyz=(340.0, 230.0, 100.0), boot_s=72.0 + needed)
    assert [(s.hover_index, s.user_id, s.tasks) for s in only(out, fx.RecordService)] == [(7, "b", 12)]


def test_a_replacement_that_flies_elsewhere_judges_the_hold_it_replaced() -> None:
    world = FakeWorld()
    run, out = _replacement_arriving_late(world, point(8, 250.0, 350.0, "b", 2))
    # item 3 is now point 8, to be flown: nobody was bound at point 7 for it
    assert run.s.holds.watch.seq == 3 and run.s.holds.watch.phase == "approaching" and 3 not in run.s.holds.judged
    assert [(s.hover_index, s.user_id) for s in only(out, fx.RecordService)] == [(3, "a")]


def test_an_upload_failed_part_way_is_read_back_at_once_whatever_the_back_off() -> None:
    # ArduPilot writes an upload's items as they arrive: one that failed part-way may have
    # left the whole new mission (the RTL it lacked was already there). The read-back goes at
    # once, not after the plans' back-off: until it answers no hold is judged, and at x40 a
    # second of back-off is three points flown unrecorded.
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    (plan,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=12.0), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    out = run.feed(ins.NotUploaded(up, "MAV_MISSION_OPERATION_CANCELLED"))
    assert run.s.schedule.retry_at > run.now, "the next plan still backs off"
    (read,) = only(out, fx.ReadBack)
    assert "failed part-way" in read.why
    out = run.feed(ins.ReadBackDone(up.items))
    records = only(out, fx.RecordMission)
    assert [(r.plan_id, r.result) for r in records] == [(up.plan_id, "accepted")]
    # a read-back that fails is tried again after a wait
    run.s = replace(run.s, onboard=replace(run.s.onboard, doubt="test"))
    run.feed(ins.ReadBackFailed("NO_ANSWER"))
    assert run.s.schedule.readback_at > run.now and not only(run.tick(), fx.ReadBack)


def test_a_service_started_between_sorties_gives_the_configurations_authority_to_the_next() -> None:
    # Restarted after sortie 1 landed: the configuration's authority is this process's first
    # and unused, so sortie 2 begins with it; once used, it is not passed on again.
    run = Run(FakeWorld())
    run.s = replace(run.s, life=replace(run.s.life, over="the vehicle landed", flown=True, just_started=True))
    run.tick()
    run.feed(ins.SortieBegun(2))
    assert run.s.authority.granted and run.s.authority.unused
    used = run.s.authority.commanding("AUTO")
    assert not used.unused
    assert next_sortie(used).state == "none"


def test_nothing_is_planned_or_started_while_the_planner_warms_up() -> None:
    # A cold numba cache: the first plan waited 74 s for the compiler in the field.
    world = FakeWorld()
    world.ask("a", 120.0, 200.0, 10, 1)
    run = Run(world)
    run.s = replace(run.s, life=replace(run.s.life, warming=True))
    assert not only(run.tick(), fx.MakePlan)
    run.feed(ins.SortieBegun(run.s.life.number))  # (a sortie begun meanwhile keeps waiting)
    assert run.s.life.warming
    (plan,) = only(run.feed(ins.WarmedUp()), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1)))), fx.Upload)
    assert only(run.feed(ins.Uploaded(up)), fx.Command)[0].kind == "start"


def test_a_disarming_after_the_mission_index_went_back_to_0_on_touching_down_is_the_landings() -> None:
    # ArduCopter SITL with the MAVSDK backend: the disarming resets the mission index, and
    # MISSION_CURRENT 0 came before the heartbeat showing the disarming: the landing at the
    # end of our own return was taken for nobody's.
    run, _ = fly_to_first_point(FakeWorld())
    rtl = run.s.onboard.held.rtl_seq
    run.tick(seq=rtl, xyz=(10.0, 10.0, 30.0), boot_s=30.0)  # on the way home
    run.tick(seq=0, xyz=(0.0, 0.0, 0.2), boot_s=40.0)
    run.feed(ins.ArmedChanged(False, False), armed=False)
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False)
    run.now += 3.0
    run.tick()
    assert run.s.authority.granted, run.s.authority


QUIET_REPORTS = [ins.Reached(2, 1), ins.Current(2, 5, 1), ins.PositionChanged(False, "a GPS fix"),
                 ins.StatusText("EKF3 IMU0 is using GPS", 6), ins.TelemetryMissing(("BATTERY_STATUS",))]
"""Link events the logic takes and that change nothing: it reads progress and position from
the telemetry at each tick."""


def test_every_link_event_is_an_input() -> None:
    assert set(get_args(ins.LinkEvent)) <= set(get_args(ins.Input))
    acting = {ins.Connected, ins.Lost, ins.Restored, ins.Restarted, ins.ModeChanged, ins.ArmedChanged, ins.OnGround}
    assert acting | {type(r) for r in QUIET_REPORTS} == set(get_args(ins.LinkEvent))


@pytest.mark.parametrize("report", QUIET_REPORTS, ids=lambda r: type(r).__name__)
def test_reports_read_from_telemetry_change_nothing(report: ins.LinkEvent) -> None:
    run, _ = fly_to_first_point(FakeWorld())
    before = run.s
    assert run.feed(report) == [] and run.s == before


def test_a_refused_command_and_a_failed_part_are_announced() -> None:
    world = FakeWorld()
    world.ask("a", 120.0, 200.0, 10, 1)
    world.ask("b", 320.0, 200.0, 12, 2)
    run = Run(world)
    (plan,) = only(run.tick(), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1)))), fx.Upload)
    (start,) = only(run.feed(ins.Uploaded(up)), fx.Command)
    out = run.feed(ins.CommandNotDone(start, "MAV_RESULT_DENIED"))
    assert [(e.event.kind, e.event.detail) for e in only(out, fx.Emit)] == [("command_failed",
                                                                            "start: MAV_RESULT_DENIED")]
    out = run.feed(ins.PartFailed("journal: disk full"))
    assert [(e.event.kind, e.event.detail) for e in only(out, fx.Emit)] == [("degraded", "journal: disk full")]
    assert run.s.life.degraded == "journal: disk full" and not only(run.tick(), fx.Command)


def test_a_landing_away_from_the_missions_return_ends_the_authority() -> None:
    # No mode change, no disarming seen: the vehicle came down in AUTO at a point of ours
    # (a motor failure, ArduCopter's land detector after a forced disarming).
    run, _ = fly_to_first_point(FakeWorld())
    out = run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, seq=2, xyz=(60.0, 100.0, 0.0))
    assert run.s.authority.state == "revoked" and "landed away from its mission's return" in run.s.authority.detail
    assert "authority_revoked" in [e.event.kind for e in only(out, fx.Emit)] and run.s.life.over is not None
    # ... and at the return item it is the service's own landing
    run2, _ = fly_to_first_point(FakeWorld())
    run2.tick(seq=run2.s.onboard.held.rtl_seq, xyz=(5.0, 5.0, 20.0), boot_s=30.0)
    run2.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, seq=0, xyz=(0.0, 0.0, 0.0))
    assert run2.s.authority.granted and run2.s.life.over is not None


def fly_px4_to_last_point() -> tuple[Run, FakeWorld]:
    """A PX4 sortie of one point, flown in AUTO.MISSION, the vehicle at its point's item."""
    world = FakeWorld()
    world.ask("a", 120.0, 200.0, 10, 1)
    run = Run(world, rules(flavour="px4"))
    (plan,) = only(run.tick(mode="AUTO.LOITER"), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1)))), fx.Upload)
    assert up.items[0].command != NAV_RTL and up.items[-1].command == NAV_RTL
    run.feed(ins.Uploaded(up))
    run.feed(ins.CommandDone(fx.Command("start")), armed=True, mode="AUTO.MISSION")
    run.tick(airborne=True, seq=0, xyz=(0.0, 0.0, 50.0), boot_s=5.0)
    run.tick(seq=run.s.onboard.held.rtl_seq - 1, xyz=(120.0, 200.0, 100.0), boot_s=50.0)
    return run, world


def fly_px4_home() -> Run:
    """A PX4 sortie flown to its mission's return item, where PX4 hands over to AUTO.RTL."""
    run, world = fly_px4_to_last_point()
    rtl = run.s.onboard.held.rtl_seq
    run.tick(seq=rtl, xyz=(120.0, 200.0, 100.0), boot_s=60.0)
    world.ask("b", 320.0, 200.0, 12, 2)
    run.now += 5.0
    out = run.feed(ins.RequestIn("b", 12)) + run.tick(xyz=(110.0, 190.0, 100.0), boot_s=61.0)
    assert not only(out, fx.MakePlan), "PX4's RTL mode, next, cannot be turned back by an upload"
    run.feed(ins.ModeChanged("AUTO.RTL", commanded=False), mode="AUTO.RTL")
    assert run.s.authority.granted, "the mission's own return item"
    return run


def test_px4s_return_mode_before_its_return_item_is_reported_is_its_own_once_the_item_shows() -> None:
    # MAVSDK on PX4 SITL: the heartbeat showing AUTO.RTL came 80 ms before the MISSION_CURRENT
    # showing the return item (one sortie in three)
    run, _ = fly_px4_to_last_point()
    rtl = run.s.onboard.held.rtl_seq
    out = run.feed(ins.ModeChanged("AUTO.RTL", commanded=False), mode="AUTO.RTL")
    assert run.s.authority.granted and run.s.authority.expected_mode == "AUTO.MISSION", "not judged yet"
    assert not only(out, fx.Emit)
    out = run.tick()
    assert not [e for e in out if isinstance(e, (fx.MakePlan, fx.Upload, fx.Command, fx.ReadBack))]
    out = run.tick(seq=rtl)
    assert run.s.authority.granted and run.s.authority.expected_mode == "AUTO.RTL"
    assert "returning" in [e.event.kind for e in only(out, fx.Emit)]
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, xyz=(0.0, 0.0, 0.1))
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False)
    assert run.s.authority.granted and run.s.life.over == "the vehicle landed"


def test_px4s_land_detector_blinking_at_the_arming_is_no_landing() -> None:
    # PX4 SITL under MAVSDK, twice in CI: armed on the ground in AUTO.LOITER, its land detector
    # said "in the air" then "on the ground" within milliseconds (Takeoff detected, Landing
    # detected), before AUTO.MISSION showed. Taken as a landing away from the return, it revoked
    # the authority and ended the sortie; the mission then flew, and PX4 returned on its own.
    world = FakeWorld()
    world.ask("a", 120.0, 200.0, 10, 1)
    run = Run(world, rules(flavour="px4"))
    (plan,) = only(run.tick(mode="AUTO.LOITER"), fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", 1)))), fx.Upload)
    (start,) = only(run.feed(ins.Uploaded(up)), fx.Command)
    assert start.kind == "start"
    run.feed(ins.ArmedChanged(True, commanded=True), armed=True)
    run.tick(airborne=True, seq=0, xyz=(0.0, 0.0, 0.1), boot_s=5.0)  # the blink, seen at a tick
    out = run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False)
    assert run.s.authority.granted and run.s.life.over is None and not run.s.life.flown
    assert not only(out, fx.Emit)
    run.feed(ins.CommandDone(start), mode="AUTO.MISSION")
    run.tick(airborne=True, xyz=(0.0, 0.0, 0.8), boot_s=6.0)
    assert not run.s.life.flown, "not yet off the ground by the vehicle's own height"
    out = run.tick(xyz=(0.0, 0.0, 1.5), boot_s=7.0)
    assert run.s.life.flown and fx.MarkFlown() in out
    # ... and a landing now is one: away from the return, nobody's
    run.tick(seq=0, xyz=(60.0, 100.0, 50.0), boot_s=20.0)
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, xyz=(60.0, 100.0, 0.0))
    assert run.s.authority.state == "revoked" and run.s.life.over == "the vehicle landed"


def test_a_return_mode_the_return_item_does_not_follow_is_somebodys() -> None:
    run, _ = fly_px4_to_last_point()  # a station's Return at the last point: the mission stays at its item
    run.feed(ins.ModeChanged("AUTO.RTL", commanded=False), mode="AUTO.RTL")
    run.now += RETURN_ITEM_S - 0.2
    run.tick()
    assert run.s.authority.granted
    run.now += 0.2
    out = run.tick()
    assert run.s.authority.state == "revoked" and "did not show its mission's return item" in run.s.authority.detail
    assert "authority_revoked" in [e.event.kind for e in only(out, fx.Emit)]


def test_a_return_mode_left_before_its_return_item_shows_is_somebodys() -> None:
    run, _ = fly_px4_to_last_point()
    run.feed(ins.ModeChanged("AUTO.RTL", commanded=False), mode="AUTO.RTL")
    run.feed(ins.ModeChanged("AUTO.MISSION", commanded=False), mode="AUTO.MISSION")  # back to the mode expected
    assert run.s.authority.state == "revoked", "switched to Return and back: not the autopilot's own"


def test_a_return_mode_away_from_the_last_item_is_judged_at_once() -> None:
    run, _ = fly_px4_to_last_point()
    run.tick(seq=run.s.onboard.held.rtl_seq - 2)
    run.feed(ins.ModeChanged("AUTO.RTL", commanded=False), mode="AUTO.RTL")
    assert run.s.authority.state == "revoked"


def test_px4s_way_back_to_its_mission_mode_after_the_returns_landing_is_its_own() -> None:
    run = fly_px4_home()
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, xyz=(0.0, 0.0, 0.1))
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False)
    run.feed(ins.ModeChanged("AUTO.MISSION", commanded=False), mode="AUTO.MISSION")
    assert run.s.authority.granted
    # Any other change on the ground after that landing is somebody's.
    run.feed(ins.ModeChanged("POSCTL", commanded=False), mode="POSCTL")
    assert run.s.authority.state == "revoked"


def test_px4s_hold_mode_after_the_landing_of_a_return_is_its_own_too() -> None:
    run = fly_px4_home()  # after a return the service commanded it went back to its boot mode (SITL)
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False, xyz=(0.0, 0.0, 0.1))
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False)
    run.feed(ins.ModeChanged("AUTO.LOITER", commanded=False), mode="AUTO.LOITER")
    assert run.s.authority.granted


def test_px4s_mission_mode_while_still_armed_after_the_return_is_not_explained() -> None:
    run = fly_px4_home()
    run.feed(ins.ModeChanged("AUTO.MISSION", commanded=False), mode="AUTO.MISSION")
    assert run.s.authority.state == "revoked", "in the air, a switch back to the mission is a station's"


def test_px4s_switch_after_the_returns_disarming_is_its_own_before_its_landed_state_comes() -> None:
    run = fly_px4_home()  # MAVSDK on PX4 SITL: the heartbeat's disarming and mode before EXTENDED_SYS_STATE
    run.feed(ins.ArmedChanged(False, commanded=False), armed=False, xyz=(0.0, 0.0, 0.2))
    run.feed(ins.ModeChanged("AUTO.LOITER", commanded=False), mode="AUTO.LOITER")
    run.feed(ins.OnGround("EXTENDED_SYS_STATE"), airborne=False)
    assert run.s.authority.granted


def test_of_two_members_holding_one_point_the_one_whose_id_sorts_after_ends_its_hold() -> None:
    """Over 100 ms radios (N = 10, x10) uav3 and uav5 both chose point 6 within half a second,
    each before hearing the other, arrived, and held there together for 6 s: a hold of two at
    one point. Heard during the hold, the member the other keeps the point for ends its own,
    as a hold whose user is done ends, and records what it carried."""
    world = FakeWorld()
    run, needed = holding_at_the_first_point(world)
    assert run.s.claims.holding is not None
    out = run.feed(ins.FleetHeard(FleetView(yield_to={run.s.claims.holding: "uav3"})))
    out += run.tick(seq=2, boot_s=21.0 + needed / 4)
    (cmd,) = only(out, fx.Command)
    assert (cmd.kind, cmd.seq) == ("set_current", 3) and "uav3 claims point" in cmd.why
    (svc,) = only(run.tick(seq=3, xyz=(150.0, 200.0, 100.0), boot_s=22.0 + needed / 4), fx.RecordService)
    assert 0 < svc.tasks < 10
