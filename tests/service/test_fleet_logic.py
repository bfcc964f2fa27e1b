"""Every claim decision of a fleet member, in milliseconds (issue 35): what the sortie logic
claims as it flies (``sortie.fleet``, told with ``Intend``), what it does with what it hears
of the others (``FleetHeard``), and the claim rule shared with the offline planner
(``model.fleet.claims``): two members deciding at once, a member's intentions late or lost,
a member gone armed, clocks skewed."""

from __future__ import annotations

from dataclasses import replace

from planner_service.model.fleet.claims import BOUND, PLANNED, keeper, lost_points, others_points, owned_by_others, owner
from planner_service.service.sortie import effects as fx
from planner_service.service.sortie import inputs as ins
from planner_service.service.sortie import SortieLogic
from planner_service.service.sortie.fleet import Claims, FleetView, answer_rank
from planner_service.service.sortie.machine import first_point
from planner_service.service.planning import PlannedPath
from planner_service.service.sortie.holds import Binding
from tests.service.test_sortie_logic import (SCENARIO, FakeWorld, Run, bound_to_a_user_uav2_owns, fly_to_first_point,
                                             only, path, point, rules)


def intents(effects: list[fx.Effect]) -> list[Claims]:
    return [e.claims for e in only(effects, fx.Intend)]


def test_a_member_claims_the_point_it_flies_to_from_the_upload_until_it_leaves_it() -> None:
    """Finding 1: the claims named the point held or just left, never the one flown to."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    # on board from the upload (before the takeoff): point 3 and its user a
    assert intents(run.effects)[0] == Claims(flying_to=3, next_user="a")
    assert run.s.claims == Claims(flying_to=3, next_user="a")
    # arrived at 3: it holds 3 (bound to a) and claims 7, the point it flies to next
    out = run.tick(seq=2, xyz=(119.0, 200.5, 100.0), boot_s=12.0)
    assert intents(out) == [Claims(flying_to=7, next_user="b", holding=3, bound="a")]
    # the decision made there replaces 7 by 9: claimed once the replacement is on board
    (plan,) = only(out, fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    out = run.feed(ins.Uploaded(up))
    assert run.s.claims == Claims(flying_to=9, next_user="b", holding=3, bound="a"), run.s.claims
    # left 3 for 9: 3 is free, 9 still claimed
    end = 12 + int(run.s.holds.binding.needed_s) + 2
    for t in range(13, end):
        run.tick(seq=2, xyz=(120.5, 199.5, 100.0), boot_s=float(t))
    out = run.tick(seq=3, xyz=(160.0, 220.0, 100.0), boot_s=end + 1.0)
    assert run.s.claims == Claims(flying_to=9, next_user="b"), run.s.claims
    assert intents(out)[-1] == Claims(flying_to=9, next_user="b")


def test_nothing_is_claimed_on_the_way_home_or_after_the_sortie() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.tick(seq=4, xyz=(60.0, 60.0, 100.0), boot_s=20.0)  # the RTL item: no point after it
    assert run.s.claims.points == frozenset() and run.s.claims.next_user is None
    assert run.s.claims.answering, "on its way home, it would answer a new request"
    # the operator took the authority back: the vehicle is the pilot's, it answers nothing
    run.s, _, ok, _ = run.logic.operator(run.s, ins.OperatorAsked("hold"), run.v, run.now)
    assert ok
    run.tick(seq=4, xyz=(50.0, 50.0, 100.0), boot_s=21.0, mode="LOITER")
    assert not run.s.claims.answering and intents(run.effects)[-1] == Claims()


def on_the_way_home(vehicle: str) -> tuple[Run, FakeWorld]:
    """``vehicle`` flies its mission's way home at (200, 150), nothing pending."""
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    run.logic = SortieLogic(replace(run.logic.rules, vehicle=vehicle), world)
    world.requests.clear()
    run.tick(seq=up.items[-1].seq, xyz=(200.0, 150.0, 100.0), boot_s=60.0, battery_fraction=0.6)
    run.now += 2.0
    assert not only(run.tick(), fx.MakePlan)
    return run, world


def test_of_members_on_their_way_home_the_nearest_answers_a_new_request_first() -> None:
    """Finding (20 UAVs over radios): a new request woke every member idle on its way home at
    once, and three planned the same user, flew to it and served it at once, each before the
    others' claims came over the radio. Now the nearest answers first; the others wait a step
    for each member nearer, and find its claim when their turn comes."""
    step = 2.0
    run, world = on_the_way_home("uav2")
    # uav1 is nearer to the new user: uav2 waits one step
    run.feed(ins.FleetHeard(FleetView(answering={"uav1": (280.0, 280.0)})))
    world.ask("c", 300.0, 300.0, 10, 9)
    assert not only(run.feed(ins.RequestIn("c", 10)) + run.tick(), fx.MakePlan)
    run.now += step - 0.5
    assert not only(run.tick(), fx.MakePlan)
    run.now += 0.5
    (plan,) = only(run.tick(), fx.MakePlan)
    assert plan.basis.reason == "new requests on the way home"

    # uav1 answered within the step: its claim is heard, c is not uav2's to plan
    run, world = on_the_way_home("uav2")
    run.feed(ins.FleetHeard(FleetView(answering={"uav1": (280.0, 280.0)})))
    world.ask("c", 300.0, 300.0, 10, 9)
    run.feed(ins.RequestIn("c", 10))
    run.feed(ins.FleetHeard(FleetView(owners={"c": "uav1"})))
    run.now += step
    assert not only(run.tick(), fx.MakePlan)

    # uav2 is the nearest (uav3 farther by more than the tie): it answers at once
    run, world = on_the_way_home("uav2")
    run.feed(ins.FleetHeard(FleetView(answering={"uav3": (0.0, 0.0)})))
    world.ask("c", 300.0, 300.0, 10, 9)
    (plan,) = only(run.feed(ins.RequestIn("c", 10)), fx.MakePlan)

    # side by side (within the tie): the id sorting first answers first, the other waits
    run, world = on_the_way_home("uav2")
    run.feed(ins.FleetHeard(FleetView(answering={"uav1": (190.0, 150.0), "uav3": (210.0, 150.0)})))
    world.ask("c", 300.0, 300.0, 10, 9)
    assert not only(run.feed(ins.RequestIn("c", 10)), fx.MakePlan)
    run.now += step
    (plan,) = only(run.tick(), fx.MakePlan)


def test_a_member_waits_at_most_its_rank_bound_for_the_nearer_ones() -> None:
    run, world = on_the_way_home("uav9")
    near = {f"uav{k}": (300.0, 290.0 - k) for k in range(1, 9)}  # eight nearer members
    run.feed(ins.FleetHeard(FleetView(answering=near)))
    world.ask("c", 300.0, 300.0, 10, 9)
    run.feed(ins.RequestIn("c", 10))
    bound = run.logic.rules.max_answer_rank * run.logic.rules.answer_step_s
    run.now += bound - 0.2
    assert not only(run.tick(), fx.MakePlan)
    run.now += 0.2
    assert only(run.tick(), fx.MakePlan), "the nearer ones may be unable to answer"


def test_the_answer_rank() -> None:
    users = [(300.0, 300.0), (0.0, 500.0)]
    assert answer_rank("uav2", (200.0, 200.0), {}, users, 50.0) == 0
    assert answer_rank("uav2", (200.0, 200.0), {"uav1": (0.0, 0.0)}, [], 50.0) == 0  # nothing to answer
    assert answer_rank("uav2", (200.0, 200.0), {"uav1": (10.0, 480.0)}, users, 50.0) == 1  # nearer another user
    assert answer_rank("uav2", (200.0, 200.0), {"uav3": (210.0, 200.0)}, users, 50.0) == 0  # a tie, uav2 first
    assert answer_rank("uav2", (200.0, 200.0), {"uav1": (190.0, 200.0)}, users, 50.0) == 1  # a tie, uav1 first
    assert answer_rank("uav2", (200.0, 200.0), {"uav1": (150.0, 150.0)}, users, 50.0) == 0  # farther, beyond the tie
    assert answer_rank("uav2", (200.0, 200.0), {"uav2": (300.0, 300.0)}, users, 50.0) == 0  # itself is no other
    # ids compare as the fleet spells them: "uav10" sorts before "uav2"
    assert answer_rank("uav2", (200.0, 200.0), {"uav10": (200.0, 205.0)}, users, 50.0) == 1


def test_two_members_that_chose_one_point_at_once_both_give_it_up() -> None:
    """Both claimed point 3 in the same moment (neither had heard the other): each hears the
    other's claim and plans again from where it is, keeping what it flew; neither holds there."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    assert run.s.claims.flying_to == 3
    out = run.feed(ins.FleetHeard(FleetView(blocked=frozenset({3}))))
    (plan,) = only(out, fx.MakePlan)
    assert plan.basis.reason == "point 3 claimed by another member" and plan.basis.keep_through == 1
    # the planner plans without 3 (the service gives it the blocked points); the replacement
    # keeps home and takeoff and flies to 9 from where the vehicle is
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    assert up.keep_through == 1
    out = run.feed(ins.Uploaded(up))
    assert run.s.claims == Claims(flying_to=9, next_user="b") and intents(out) == [run.s.claims]
    assert not only(run.tick(seq=2, xyz=(60.0, 90.0, 100.0), boot_s=10.0), fx.MakePlan)  # given up once
    assert lost_points({3}, {3, 8}) == {3} and lost_points({3}, {8}) == frozenset()


def test_of_two_members_that_chose_one_point_at_once_the_first_id_keeps_it() -> None:
    """Both giving it up made two members that decide alike (side by side, hearing the same
    request) give up one point after another together until they arrived at one at once (20
    UAVs over radios). Now the first id keeps it: it is not blocked to uav1, which plans
    with it and flies on; uav2 gives it up. Every member computes the same from the same
    claims; a third claimant sorting first takes it from both."""
    points = {"uav1": [3], "uav2": [3, 8]}
    alive = {"uav1", "uav2"}
    assert others_points("uav1", points, alive) == {8}
    assert others_points("uav2", points, alive) == {3}
    assert lost_points({3}, others_points("uav1", points, alive)) == frozenset()
    assert lost_points({3, 8}, others_points("uav2", points, alive)) == {3}
    assert others_points("uav1", {**points, "uav0": [3]}, alive | {"uav0"}) == {3, 8}
    assert others_points("uav1", {**points, "uav0": [3]}, alive) == {8}  # uav0 is not alive
    # ids are compared as the fleet spells them: "uav10" sorts before "uav2"
    assert others_points("uav10", {"uav10": [5], "uav2": [5]}, {"uav10", "uav2"}) == frozenset()
    # claimed at different moments (each before hearing the other): the first to claim keeps it
    since = {"uav1": {3: 100.4}, "uav2": {3: 100.0, 8: 100.0}}
    assert others_points("uav1", points, alive, since) == {3, 8}
    assert others_points("uav2", points, alive, since) == frozenset()
    assert keeper(3, points, alive, since) == "uav2" and keeper(3, points, alive) == "uav1"
    assert keeper(3, points, {"uav1"}, since) == "uav1" and keeper(9, points, alive, since) is None
    assert keeper(3, points, alive, {"uav1": {3: 5.0}}) == "uav1"  # a time not said is no claim to be first


def test_a_user_another_member_owns_is_neither_planned_bound_nor_recorded_here() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.FleetHeard(FleetView(owners={"a": "uav2"})))
    out = run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)  # arrives at a's point
    b = run.s.holds.binding
    assert b is not None and b.user_id != "a", b  # a is uav2's: the rule binds another, or none
    (plan,) = only(out, fx.MakePlan)
    assert plan.basis.serving != "a"


def test_a_hold_of_a_user_another_member_bound_first_records_nothing() -> None:
    """Two members bound one user at once (each before the other's claim reached it): the one
    whose claim wins keeps it; this one hears it and records nothing."""
    run, b = bound_to_a_user_uav2_owns(FakeWorld())
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0 + b.needed_s + 1.0)
    out = run.tick(seq=3, xyz=(200.0, 300.0, 100.0), boot_s=22.0 + b.needed_s)
    assert not only(out, fx.RecordService)
    assert any("nothing recorded: uav2 serves" in e.event.detail for e in only(out, fx.Emit))


def test_users_a_member_no_longer_owns_are_planned_again() -> None:
    """A member's intentions lost (its service gone) or changed: the users it owned are this
    member's again at its next decision."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    run.feed(ins.FleetHeard(FleetView(owners={"b": "uav2"})))
    run.s = replace(run.s, schedule=replace(run.s.schedule, dirty=False))  # planned since
    run.feed(ins.FleetHeard(FleetView(owners={"b": "uav2"}, blocked=frozenset({12}))))
    assert not run.s.schedule.dirty  # nobody freed
    run.feed(ins.FleetHeard(FleetView()))
    assert run.s.schedule.dirty  # b is this member's to plan again


def test_ownership_late_or_lost_intentions_and_a_member_gone_armed() -> None:
    claims = {"uav1": {"u": (PLANNED, 100.0)}, "uav2": {"u": (PLANNED, 90.0)}, "uav3": {"u": (BOUND, 500.0)}}
    assert owner("u", claims) == "uav3"  # a hold under way beats any plan
    # uav3's intentions lost (its service gone): the earlier plan wins among the live
    assert owned_by_others("uav1", claims, {"uav1", "uav2"}) == {"uav2": "uav2"}.__class__(u="uav2")
    # uav2's message late: until it comes uav1 owns u; once it comes both agree on uav2
    assert owned_by_others("uav1", {"uav1": claims["uav1"]}, {"uav1", "uav2"}) == {}
    assert owned_by_others("uav2", claims, {"uav1", "uav2"}) == {}
    # a member gone armed keeps its route out of everyone's plans (the ledger adds it); its
    # claims go with its token
    assert others_points("uav1", {"uav1": [1], "uav2": [4, 5], "uav3": [6]}, {"uav1", "uav2"}) == {4, 5}


def test_every_member_computes_one_owner_whatever_its_own_clock() -> None:
    """Clocks skewed: the rule compares the claimants' own times, never a reader's, so two
    members whose clocks differ by any amount agree on the owner; a skew only biases which
    claim is earlier (bounded at join: ``fleet.max_clock_offset_s``)."""
    skew = 1.7  # uav2's clock reads 1.7 s ahead of uav1's
    claims = {"uav1": {"u": (PLANNED, 1000.0 + 30.0)}, "uav2": {"u": (PLANNED, 1000.0 + skew + 29.0)}}
    seen_by_uav1 = owned_by_others("uav1", claims, {"uav1", "uav2"})
    seen_by_uav2 = owned_by_others("uav2", claims, {"uav1", "uav2"})
    assert seen_by_uav1 == {} and seen_by_uav2 == {"u": "uav1"}  # both say uav1
    tie = {"uav1": {"u": (PLANNED, 5.0)}, "uav2": {"u": (PLANNED, 5.0)}}
    assert owner("u", tie) == "uav1"  # ties to the smaller id, on every member


SETTLE_S = 10.0


def settling(run: Run, world: FakeWorld) -> Run:
    """``run``'s member with the fleet's settling on (``fleet.settle_max_s``)."""
    run.logic = SortieLogic(replace(run.logic.rules, settle_max_s=SETTLE_S), world)
    return run


def decided_on_the_way_home(vehicle: str, k: int) -> tuple[Run, fx.Upload | None, list[fx.Effect]]:
    """``vehicle`` on its way home, alone in its view (no member heard answering), hears a new
    request and decides point ``k``: its upload if sent at once, and the decision's effects."""
    run, world = on_the_way_home(vehicle)
    settling(run, world)
    world.ask("c", 300.0, 300.0, 10, 9)
    (plan,) = only(run.feed(ins.RequestIn("c", 10)), fx.MakePlan)
    assert plan.basis.reason == "new requests on the way home"
    out = run.feed(ins.Planned(plan.basis, path(point(k, 300.0, 290.0, "c", 9))))
    ups = only(out, fx.Upload)
    return run, ups[0] if ups else None, out


def test_of_two_members_that_chose_one_point_within_a_hearing_delay_only_the_first_to_claim_flies_there() -> None:
    """Finding (20 UAVs over radios, 2026-12-07): three members became idle on their way home
    within 1.4 s, and a new request found each alone in its view (their ``answering`` heard 2
    s later); all three decided for point 9 within 1 s, flew there and held it together
    before any heard another's claim. Now a decision made away from a hold claims its first
    point and flies there once the claim has settled: every other member's intentions
    signed after it were heard, so the claim rule has judged every claim made before it.
    uav1 claimed first and flies; uav2, hearing uav1's claim by then, decides again."""
    first, up1, out1 = decided_on_the_way_home("uav1", 9)
    second, up2, out2 = decided_on_the_way_home("uav2", 9)
    assert up1 is None and up2 is None, "neither flies a point before its claim has settled"
    assert intents(out1)[-1].flying_to == 9 and intents(out2)[-1].flying_to == 9, "both claim it meanwhile"
    assert first.s.claims.next_user == "c" and first.s.schedule.busy == "settle"
    assert not only(first.tick(), fx.Upload), "nothing heard yet"
    # each hears the other's intentions signed after its own claim: uav1's was first
    (up,) = only(first.feed(ins.FleetHeard(FleetView(settled=frozenset({9})))), fx.Upload)
    assert first_point_of(up) == 9 and first.s.schedule.busy == "upload"
    out = second.feed(ins.FleetHeard(FleetView(blocked=frozenset({9}))))
    assert not only(out, fx.Upload) and second.s.schedule.busy == ""
    assert "point 9 was claimed first by another member" in " ".join(e.text for e in only(out, fx.Log))
    assert second.s.claims.flying_to is None, "it gives the point up at once"
    second.now += 1.0
    (plan,) = only(second.tick(), fx.MakePlan)
    assert plan.basis.reason == "new requests on the way home", "it decides again (without 9: the planner's)"


def test_a_claim_that_does_not_settle_is_flown_after_the_bound() -> None:
    """A member never heard (late, or one whose key was stolen and that says nothing) delays a
    decision by ``fleet.settle_max_s`` at most; then it flies as decided, and says so."""
    run, up, _ = decided_on_the_way_home("uav2", 9)
    assert up is None
    run.now += SETTLE_S - 0.5
    assert not only(run.tick(), fx.Upload)
    run.now += 0.5
    out = run.tick()
    (up,) = only(out, fx.Upload)
    assert first_point_of(up) == 9
    assert only(out, fx.Unsettled) == [fx.Unsettled(up.plan_id, 9, SETTLE_S)], "the service warns, naming whom"


def test_a_lone_uav_flies_a_decision_at_once() -> None:
    run, world = on_the_way_home("uav2")  # settle_max_s 0: no fleet
    world.ask("c", 300.0, 300.0, 10, 9)
    (plan,) = only(run.feed(ins.RequestIn("c", 10)), fx.MakePlan)
    assert only(run.feed(ins.Planned(plan.basis, path(point(9, 300.0, 290.0, "c", 9)))), fx.Upload)


def first_point_of(up: fx.Upload) -> int | None:
    first = first_point(up)
    return None if first is None else first.hover_index


def test_a_hold_ends_once_the_next_points_claim_has_settled_and_a_next_point_lost_is_decided_again() -> None:
    """At a hold the decision's upload goes at once (it restarts the autopilot's hold timer)
    and the vehicle stays on the point it holds until the next point's claim has settled;
    another member claiming it first makes it decide again, still holding. Yielding the point
    held to another member does not wait."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    settling(run, world)
    run.feed(ins.FleetHeard(FleetView(settled=frozenset({3}))))
    out = run.tick(seq=2, xyz=(119.0, 200.5, 100.0), boot_s=12.0)  # arrived at 3, bound to a
    (plan,) = only(out, fx.MakePlan)
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    run.feed(ins.Uploaded(up))
    assert run.s.claims.flying_to == 9
    end = 12 + int(run.s.holds.binding.needed_s) + 2
    for t in range(13, end):
        run.tick(seq=2, xyz=(120.5, 199.5, 100.0), boot_s=float(t))
    assert run.s.holds.served_why() is not None, "the request is served"
    assert not only(run.effects, fx.Command)[1:], "the hold goes on: 9's claim has not settled"
    # another member claimed 9 first: decided again from the point held
    out = run.feed(ins.FleetHeard(FleetView(settled=frozenset({3}), blocked=frozenset({9}))))
    (plan,) = only(out, fx.MakePlan)
    assert plan.basis.reason == "point 9 claimed by another member, holding point 3"
    assert plan.basis.keep_through == 2 and plan.basis.at_point is not None
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(8, 300.0, 100.0, "b", 2)))), fx.Upload)
    run.feed(ins.Uploaded(up))
    assert run.s.claims.flying_to == 8
    assert not only(run.tick(seq=2, xyz=(120.5, 199.5, 100.0), boot_s=float(end)), fx.Command)
    out = run.feed(ins.FleetHeard(FleetView(settled=frozenset({3, 8}), blocked=frozenset({9}))))
    out += run.tick(seq=2, xyz=(120.5, 199.5, 100.0), boot_s=end + 1.0)
    (cmd,) = only(out, fx.Command)
    assert cmd.kind == "set_current" and cmd.seq == 3, cmd


def lost_in_flight(xyz: tuple[float, float, float] = (30.0, 50.0, 100.0),
                   battery_after_j: float = 20_000.0) -> tuple[Run, fx.MakePlan, fx.Upload]:
    """A member flying to point 3 (at ``xyz``) hears another claimed it first: its decision
    (point 9, the path leaving ``battery_after_j``) and the replacement's upload."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    settling(run, world)
    run.tick(seq=2, xyz=xyz, boot_s=9.0)
    (plan,) = only(run.feed(ins.FleetHeard(FleetView(blocked=frozenset({3})))), fx.MakePlan)
    assert plan.basis.reason == "point 3 claimed by another member" and not plan.basis.settles
    assert plan.basis.pauses and plan.basis.keep_through == 1
    decided = PlannedPath((point(9, 400.0, 300.0, "b", 2),), 20_000.0, battery_after_j, "the planned line ends")
    (up,) = only(run.feed(ins.Planned(plan.basis, decided)), fx.Upload)
    return run, plan, up


def test_a_member_flying_to_a_point_lost_holds_where_it_is_until_its_new_points_claim_has_settled() -> None:
    """Finding (20 UAVs over radios, 2026-12-07, in two runs of three): two members each
    replaced a point lost in flight with the same new point 2.0 s and 2.6 s apart, flew
    there at once (flying on to the lost point is what must end: an earlier run saw a member
    settle its new claim while flying on, and hold the lost point beside its keeper), and
    held it together before either heard the other. Now the replacement goes up at once,
    its first item a pause where the vehicle is, and the service ends the pause once the new
    point's claim has settled."""
    run, _, up = lost_in_flight()
    assert up.mission.is_pause(2) and not up.mission.is_pause(1) and up.current_seq == 2, "the pause is flown first"
    assert first_point_of(up) == 9 and up.mission.point_at(3) is not None and up.mission.point_at(2) is None
    assert up.items[2].param1 >= SETTLE_S, "the autopilot holds it as long as the claim may take to settle"
    assert "holds where it is until the claim of point 9 has settled" in " ".join(
        e.text for e in only(run.effects, fx.Log))
    run.feed(ins.Uploaded(up))
    assert run.s.claims.flying_to == 9, "the new point is claimed from the upload"
    assert not only(run.tick(seq=2, xyz=(31.0, 51.0, 100.0), boot_s=10.0), fx.Command), "not settled: paused"
    run.feed(ins.FleetHeard(FleetView(blocked=frozenset({3}), settled=frozenset({9}))))
    (cmd,) = only(run.tick(seq=2, xyz=(30.0, 50.0, 100.0), boot_s=11.0), fx.Command)
    assert cmd.kind == "set_current" and cmd.seq == 3 and "claim of point 9 has settled" in cmd.why
    assert not only(run.tick(seq=2, xyz=(30.0, 50.0, 100.0), boot_s=11.5), fx.Command), "asked once"
    run.feed(ins.CommandDone(cmd))
    assert not only(run.tick(seq=2, xyz=(30.0, 50.0, 100.0), boot_s=11.6), fx.Command), "its report comes later"


def test_a_pause_whose_point_is_lost_is_decided_again_and_one_never_settled_ends_after_the_bound() -> None:
    run, _, up = lost_in_flight()
    run.feed(ins.Uploaded(up))
    run.tick(seq=2, xyz=(30.0, 50.0, 100.0), boot_s=10.0)
    (plan,) = only(run.feed(ins.FleetHeard(FleetView(blocked=frozenset({3, 9})))), fx.MakePlan)
    assert plan.basis.reason == "point 9 claimed by another member" and plan.basis.keep_through == 1, \
        "the pause itself is replaced"
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(8, 300.0, 100.0, "b", 2)))), fx.Upload)
    assert up.mission.is_pause(2) and first_point_of(up) == 8
    run.feed(ins.Uploaded(up))
    claimed = run.now
    run.now = claimed + SETTLE_S - 0.5
    assert not only(run.tick(seq=2, xyz=(30.0, 50.0, 100.0), boot_s=11.0), fx.Command)
    run.now = claimed + SETTLE_S
    out = run.tick(seq=2, xyz=(30.0, 50.0, 100.0), boot_s=12.0)
    (cmd,) = only(out, fx.Command)
    assert cmd.seq == 3 and "point 8 flown unsettled" in cmd.why
    assert only(out, fx.Unsettled) == [fx.Unsettled(up.plan_id, 8, SETTLE_S)], "the service warns, naming whom"


def test_a_member_over_a_hovering_point_or_short_of_energy_flies_a_point_lost_s_replacement_at_once() -> None:
    """No pause where another member's vehicle may hold (within two hold radii of a hovering
    point: the SCENARIO's point 5 is at (120, 140)), nor where its hovering would cost a point."""
    for xyz, battery_after_j in (((118.0, 138.0, 100.0), 20_000.0), ((30.0, 50.0, 100.0), SCENARIO.energy_floor_j + 1000.0)):
        run, _, up = lost_in_flight(xyz, battery_after_j)
        assert not up.mission.is_pause(2) and first_point_of(up) == 9 and up.mission.point_at(2) is not None, xyz


def test_a_member_outbid_at_its_first_point_before_the_takeoff_plans_again_on_what_is_left() -> None:
    """Finding (the fleet on three SITL copters, 2026-12-07): all three decided at the tenth
    request (``planner.min_requests`` 10, ten users); uav2 lost its first point to uav1 or uav3
    three times, and then waited for ten requests no other member owned, which never came while
    they owned some: it stayed on the ground for 45 s, until uav3's service died. A member
    outbid decides again on the requests left to it, however few."""
    world = FakeWorld()
    for j, user in enumerate("abc"):
        world.ask(user, 100.0 + 100 * j, 200.0, 10, j + 1)
    run = settling(Run(world, rules(min_requests=3)), world)
    (plan,) = only(run.tick(), fx.MakePlan)
    assert plan.basis.reason == "requests before takeoff"
    assert not only(run.feed(ins.Planned(plan.basis, path(point(3, 100.0, 200.0, "a", 1)))), fx.Upload)
    assert run.s.schedule.busy == "settle"
    taken = FleetView(owners={"a": "uav1", "b": "uav3"}, blocked=frozenset({3}))
    out = run.feed(ins.FleetHeard(taken))
    assert "point 3 was claimed first by another member" in " ".join(e.text for e in only(out, fx.Log))
    (plan,) = only(out + run.tick(), fx.MakePlan)  # one request left to it, not three
    assert plan.basis.reason == "requests before takeoff"
    assert not only(run.feed(ins.Planned(plan.basis, path(point(5, 300.0, 200.0, "c", 3)))), fx.Upload)
    (up,) = only(run.feed(ins.FleetHeard(replace(taken, settled=frozenset({5})))), fx.Upload)
    assert first_point_of(up) == 5


def test_a_member_not_outbid_waits_for_its_minimum_of_requests_no_other_member_owns() -> None:
    world = FakeWorld()
    for j, user in enumerate("abc"):
        world.ask(user, 100.0 + 100 * j, 200.0, 10, j + 1)
    run = settling(Run(world, rules(min_requests=3)), world)
    run.s = replace(run.s, fleet=FleetView(owners={"a": "uav1"}))
    assert not only(run.tick(), fx.MakePlan), "two requests of its own, three wanted"
    world.ask("d", 400.0, 200.0, 10, 4)
    assert only(run.tick(), fx.MakePlan)


def served_and_left(run: Run) -> tuple[Binding, list[fx.Effect]]:
    """``run``'s member arrives at point 3, is bound to a, holds as long as a needs and leaves
    for item 3: its binding and the effects of the leaving."""
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    b = run.s.holds.binding
    assert b is not None and b.request_id is not None and b.user_id == "a"
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=21.0 + b.needed_s)
    return b, run.tick(seq=3, xyz=(200.0, 300.0, 100.0), boot_s=22.0 + b.needed_s)


def test_of_two_members_that_bound_one_user_within_a_hearing_delay_only_the_first_records_it() -> None:
    """Finding (20 UAVs over radios, 2026-12-07, the run after the pause): uav5 at point 4 and
    uav8 at point 5 bound user-5 (one task) 0.7 s apart, each hold 3.3-3.7 s, shorter than
    the hearing delay: both recorded it, neither had heard the other's binding, which went
    with the hold. Now a member records a hold's service once its binding has settled (every
    binding made before it is known), claiming the user meanwhile; the later binder hears the
    earlier one's binding (claimed until that one's record, too) and records nothing."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    settling(run, world)
    b, out = served_and_left(run)
    assert not only(out, fx.RecordService), "the binding has not settled"
    assert run.s.claims.bound == "a" and intents(run.effects)[-1].bound == "a", "a is still claimed as bound"
    assert "a" not in [r.user_id for r in run.logic._pending(run.s)], "nor planned again meanwhile"
    assert not only(run.tick(seq=3, xyz=(210.0, 300.0, 100.0), boot_s=30.0), fx.RecordService)
    out = run.feed(ins.FleetHeard(FleetView(owners={"a": "uav2"}, bound_settled="a")))
    out += run.tick(seq=3, xyz=(220.0, 300.0, 100.0), boot_s=31.0)
    assert not only(out, fx.RecordService)
    assert any("nothing recorded: uav2 serves a (owns it now)" in e.event.detail for e in only(out, fx.Emit))
    assert run.s.claims.bound is None and run.s.holds.judged_unrecorded is None
    # the first binder: its binding settles, nobody bound a before it: recorded
    first = settling(fly_to_first_point(FakeWorld())[0], world)
    served_and_left(first)
    first.feed(ins.FleetHeard(FleetView(bound_settled="a")))
    out = first.tick(seq=3, xyz=(220.0, 300.0, 100.0), boot_s=25.0 + b.needed_s)
    (svc,) = only(out, fx.RecordService)
    assert (svc.user_id, svc.tasks) == ("a", b.tasks)
    (served,) = [e.event for e in only(out, fx.Emit) if e.event.kind == "user_served"]
    assert "recorded 4.0 s after the hold" in served.detail, "the hold's end, for whoever reads when it was"


def test_a_binding_that_does_not_settle_is_recorded_after_the_bound_and_a_new_hold_records_the_last_at_once() -> None:
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    settling(run, world)
    served_and_left(run)
    run.tick(seq=3, xyz=(220.0, 300.0, 100.0), boot_s=31.0)  # its wait begins
    judged_at = run.now
    run.now = judged_at + SETTLE_S - 0.5
    assert not only(run.tick(seq=3, xyz=(230.0, 300.0, 100.0), boot_s=32.0), fx.RecordService)
    run.now = judged_at + SETTLE_S
    out = run.tick(seq=3, xyz=(240.0, 300.0, 100.0), boot_s=33.0)
    (svc,) = only(out, fx.RecordService)
    assert svc.user_id == "a" and "binding of a has not settled in 10 s" in " ".join(e.text for e in only(out, fx.Log))
    # the next hold binds before the last one's binding settled: the last is recorded then
    run2, _ = fly_to_first_point(FakeWorld())
    settling(run2, world)
    served_and_left(run2)
    (svc,) = only(run2.tick(seq=3, xyz=(320.0, 200.0, 100.0), boot_s=60.0), fx.RecordService)  # arrived at 7 (b)
    assert svc.user_id == "a" and run2.s.holds.binding.user_id == "b" and run2.s.claims.bound == "b"


def test_a_hold_recorded_at_the_next_arrival_is_not_bound_again_there() -> None:
    """The next arrival records the last hold at once and binds in the same step: the record
    is an effect, not yet in the journal, so the user just served counted as never served
    and its request as pending, and was bound again on it (``test_sortie_logic.py``'s
    replayed hold, the same in a fleet)."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    settling(run, world)
    served_and_left(run)
    del world.requests["b"]  # a, served, is the one user near point 7
    out = run.tick(seq=3, xyz=(320.0, 200.0, 100.0), boot_s=60.0)  # arrived at 7
    (svc,) = only(out, fx.RecordService)
    assert svc.user_id == "a"
    binding = run.s.holds.binding
    assert binding is not None and binding.request_id is None, binding
    assert any("nobody eligible near" in e.event.detail for e in only(out, fx.Emit)), out


def test_a_lone_uav_records_a_hold_at_once() -> None:
    run, _ = fly_to_first_point(FakeWorld())  # settle_max_s 0: no fleet
    _, out = served_and_left(run)
    assert only(out, fx.RecordService)


def test_a_member_reading_its_mission_back_keeps_what_it_claims() -> None:
    """Finding (20 UAVs over radios, 2026-12-07): while a member read its mission back (every
    30 s, and in every doubt: 44 read-backs in a run, up to 9 s each over the radios) it
    claimed nothing, so the others planned its points meanwhile; claimed again afterwards, by
    a later time, it lost them to those claims (8 of the 44 were followed within 8 s by the
    member losing its next point). Its vehicle flies on meanwhile: what it claimed stands."""
    world = FakeWorld()
    run, up = fly_to_first_point(world)
    settling(run, world)
    claimed = run.s.claims
    assert claimed.flying_to == 3
    out = run.feed(ins.Restored("AUTO"))  # the link came back: the mission is read back
    assert only(out, fx.ReadBack) and run.s.onboard.doubt is not None
    assert run.s.claims == claimed and not only(out, fx.Intend), "nothing given up"
    out = run.tick(seq=2, xyz=(60.0, 100.0, 100.0), boot_s=10.0)
    assert run.s.claims == claimed and not only(out, fx.Intend)
    out = run.feed(ins.ReadBackDone(up.items))
    assert run.s.onboard.doubt is None and run.s.claims == claimed and not only(out, fx.Intend)


def test_a_settled_plan_keeps_its_first_points_claim_through_its_upload() -> None:
    """Found with the read-backs' (the same run): a plan whose first point's claim had settled
    gave the claim up while its upload was in flight (the mission not yet on board), then
    claimed the point again once it was, by the time of the upload's end: its claim of 4 s
    before was lost, and the claims others made meanwhile came first."""
    run, up, _ = decided_on_the_way_home("uav2", 9)
    assert up is None and run.s.claims.flying_to == 9
    claimed, since = run.s.claims, len(run.effects)
    (up,) = only(run.feed(ins.FleetHeard(FleetView(settled=frozenset({9})))), fx.Upload)
    assert run.s.schedule.busy == "upload"
    assert run.s.claims == claimed, "claimed while the upload is in flight"
    run.feed(ins.Uploaded(up))
    assert run.s.claims.flying_to == 9
    assert all(c.flying_to == 9 for c in intents(run.effects[since:])), "never given up since it was first claimed"


def test_a_hold_whose_user_another_member_bound_first_ends_at_once() -> None:
    """Finding (20 UAVs over radios, 2026-12-07): 54 holds of 22-75 s recorded nothing, 23 of
    them because another member had bound the user first, heard during the hold: each held on
    for all the time its request needed, for nothing. Now such a hold ends as soon as the
    other's binding is heard (once the next point is decided and its claim settled, as any)."""
    world = FakeWorld()
    run, b = bound_to_a_user_uav2_owns(world)
    assert run.s.holds.binding.lost_to == "uav2"
    (plan,) = [e for e in run.effects if isinstance(e, fx.MakePlan)][-1:]
    (up,) = only(run.feed(ins.Planned(plan.basis, path(point(9, 400.0, 300.0, "b", 2)))), fx.Upload)
    run.feed(ins.Uploaded(up))
    (cmd,) = only(run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=21.0), fx.Command)
    assert cmd.kind == "set_current" and cmd.seq == 3 and "uav2 serves a (it bound the user first)" in cmd.why
    assert b.needed_s > 10.0, "long before the request's hold was flown"


def test_a_hold_that_carried_nothing_is_said_at_once_and_its_user_not_claimed_on() -> None:
    """Found with the deferred records (20 UAVs, the next run): a member whose hold was cut
    short kept its user claimed while its record waited, so two other members' holds of that
    user (59 and 73 s) recorded nothing, and it recorded nothing either."""
    world = FakeWorld()
    run, _ = fly_to_first_point(world)
    settling(run, world)
    run.tick(seq=2, xyz=(110.0, 195.0, 100.0), boot_s=19.9)  # reported just before the arrival
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=20.0)
    assert run.s.claims.bound == "a"
    out = run.tick(seq=3, xyz=(140.0, 210.0, 100.0), boot_s=21.0)  # left after a second
    assert run.s.holds.judged_unrecorded is None and run.s.claims.bound is None
    assert any("nothing served" in e.event.detail for e in only(out, fx.Emit))
