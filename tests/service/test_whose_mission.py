"""Whose mission the vehicle flies, from every signal the autopilot gives (issue 23, item 2):
MISSION_CURRENT's ``mission_id`` against the id the autopilot gave our upload, the item
flown against our mission's items and order, and a periodic read-back compared item by
item. Each disagreement reads the mission back; a mission that is not ours ends the
authority. Pure logic, in milliseconds."""

from __future__ import annotations

from dataclasses import replace

from planner_service.service.sortie import effects as fx
from planner_service.service.sortie import inputs as ins
from tests.service.test_sortie_logic import FakeWorld, fly_to_first_point, only

OURS, THEIRS = 0x7D59A53B, 0x1234ABCD


def moved(items: tuple, dlat: int = 5000) -> tuple:
    """The same number of items, each navigation item 55 m further north: another
    station's mission of the same length."""
    return tuple(replace(i, x=i.x + dlat) if i.x else i for i in items)


def test_a_mission_id_not_ours_reads_back_and_a_same_length_mission_ends_the_authority() -> None:
    run, up = fly_to_first_point(FakeWorld())
    run.feed(ins.Uploaded(up, mission_id=OURS))  # the same plan again, now with the id PX4 gave it
    assert not only(run.tick(seq=2, mission_total=len(up.items), mission_id=OURS, boot_s=9.0), fx.ReadBack)
    (rb,) = only(run.tick(seq=2, mission_total=len(up.items), mission_id=THEIRS, boot_s=10.0), fx.ReadBack)
    assert "0x1234abcd" in rb.why and "0x7d59a53b" in rb.why, rb.why
    run.feed(ins.ReadBackDone(moved(up.items), mission_id=THEIRS))
    assert run.s.authority.state == "revoked" and "not ours" in run.s.authority.detail
    assert run.s.onboard.held is None and not only(run.tick(boot_s=11.0), fx.MakePlan), "theirs is not replaced"


def test_an_id_the_link_did_not_learn_is_read_back_once_then_known() -> None:
    run, up = fly_to_first_point(FakeWorld())  # uploaded with id 0: the link saw no opaque_id
    (rb,) = only(run.tick(seq=2, mission_id=OURS, boot_s=9.0), fx.ReadBack)
    assert "not said" in rb.why
    run.feed(ins.ReadBackDone(up.items))
    assert run.s.authority.granted and run.s.evidence.id_explained == OURS
    assert not only(run.tick(seq=2, mission_id=OURS, boot_s=10.0), fx.ReadBack)
    assert only(run.tick(seq=2, mission_id=THEIRS, boot_s=11.0), fx.ReadBack), "a new id is news again"


def test_the_read_backs_own_id_names_the_mission_held() -> None:
    run, up = fly_to_first_point(FakeWorld())
    run.tick(seq=2, mission_id=THEIRS, boot_s=9.0)  # stale, say
    run.feed(ins.ReadBackDone(up.items, mission_id=OURS))  # MISSION_COUNT's opaque_id: ours
    assert run.s.evidence.mission_id == OURS and run.s.authority.granted
    assert only(run.tick(seq=2, mission_id=THEIRS, boot_s=10.0), fx.ReadBack)


def test_an_item_flown_that_our_mission_lacks_or_a_step_back_reads_back() -> None:
    run, up = fly_to_first_point(FakeWorld())
    assert not only(run.tick(seq=3, boot_s=9.0), fx.ReadBack), "forward is the mission's own order"
    (rb,) = only(run.tick(seq=2, boot_s=10.0), fx.ReadBack)
    assert "went back from item 3 to 2" in rb.why, rb.why
    run.feed(ins.ReadBackDone(up.items))  # ours after all: flown on
    assert run.s.authority.granted and not only(run.tick(seq=2, boot_s=11.0), fx.ReadBack)
    (rb,) = only(run.tick(seq=len(up.items), boot_s=12.0), fx.ReadBack)
    assert f"flies item {len(up.items)}" in rb.why, rb.why


def test_a_step_back_the_service_commanded_is_its_own() -> None:
    run, _ = fly_to_first_point(FakeWorld())
    run.tick(seq=3, boot_s=9.0)
    run.feed(ins.CommandDone(fx.Command("set_current", 2)))
    assert not only(run.tick(seq=2, boot_s=10.0), fx.ReadBack)


def test_the_mission_is_read_back_periodically_under_authority_and_a_changed_one_ends_it() -> None:
    run, up = fly_to_first_point(FakeWorld())
    interval = run.logic.rules.readback_interval_s
    assert interval > 0
    assert not only(run.tick(seq=2, boot_s=9.0), fx.ReadBack), "just uploaded"
    run.now += interval
    (rb,) = only(run.tick(seq=2, boot_s=10.0), fx.ReadBack)
    assert "periodic" in rb.why
    run.feed(ins.ReadBackDone(up.items))
    assert run.s.authority.granted and run.s.onboard.held is not None
    assert not only(run.tick(seq=2, boot_s=11.0), fx.ReadBack), "checked just now"
    run.now += interval
    assert only(run.tick(seq=2, boot_s=12.0), fx.ReadBack)
    run.feed(ins.ReadBackDone(moved(up.items, 1)))  # one step of 1e-7 deg: not ours
    assert run.s.authority.state == "revoked" and "not ours" in run.s.authority.detail


def test_no_periodic_read_back_during_an_upload_or_without_authority() -> None:
    run, up = fly_to_first_point(FakeWorld())
    run.s = replace(run.s, schedule=replace(run.s.schedule, busy="upload"))
    run.now += 10 * run.logic.rules.readback_interval_s
    assert not only(run.tick(seq=2, boot_s=9.0), fx.ReadBack), "an upload in flight is not disturbed"
    run.s = replace(run.s, authority=run.s.authority.release("the operator's hold"),
                    schedule=replace(run.s.schedule, busy=""))
    assert not only(run.tick(seq=2, boot_s=10.0), fx.ReadBack)


def test_a_vehicle_off_the_leg_it_flies_reads_the_mission_back() -> None:
    # Another station's mission of the same length: the same item numbers, other places.
    # The vehicle began item 2 at (30, 50) for our point at (120, 200); theirs lies east.
    run, up = fly_to_first_point(FakeWorld())
    for k, t in enumerate((9.0, 10.0, 11.0, 12.0)):  # on our leg (a few metres off at most)
        f = (k + 1) / 5
        assert not only(run.tick(seq=2, xyz=(30.0 + 90.0 * f + 3.0, 50.0 + 150.0 * f, 100.0), boot_s=t), fx.ReadBack)
    run.tick(seq=2, xyz=(120.0, 200.0, 100.0), boot_s=13.0)  # at the point, holding: on the leg's end
    assert run.s.evidence.leg is not None and run.s.evidence.off_leg == 0
    run2, _ = fly_to_first_point(FakeWorld())
    out = []
    for k, t in enumerate((9.0, 10.0, 11.0)):
        assert not only(out, fx.ReadBack), "one or two reports off are no evidence"
        out = run2.tick(seq=2, xyz=(30.0 + 40.0 * (k + 1), 50.0 - 5.0 * (k + 1), 100.0), boot_s=t)
    (rb,) = only(out, fx.ReadBack)
    assert "m off its leg to point" in rb.why and "item 2" in rb.why, rb.why
    run2.feed(ins.ReadBackDone(moved(up.items)))
    assert run2.s.authority.state == "revoked" and "not ours" in run2.s.authority.detail


def test_the_same_report_seen_by_several_ticks_counts_once_off_the_leg() -> None:
    run, _ = fly_to_first_point(FakeWorld())
    for _ in range(5):  # ticks come faster than position reports
        out = run.tick(seq=2, xyz=(150.0, 20.0, 100.0), boot_s=9.0)
    assert not only(out, fx.ReadBack) and run.s.evidence.off_leg == 1
