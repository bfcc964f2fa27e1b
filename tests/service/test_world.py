"""The sortie logic over a real journal whose file fails mid-sortie (the degraded state): a
service the journal refuses is still counted, so the request it served is not bound and
announced ``user_served`` a second time at the next point near its user (issue 23)."""

from __future__ import annotations

from pathlib import Path

import pytest

from planner_service.service.errors import JournalError
from planner_service.service.journal import Journal
from planner_service.service.sortie import effects as fx
from planner_service.service.sortie import inputs as ins
from planner_service.service.world import FleetWorld, JournalWorld
from tests.service.test_sortie_logic import Run, only, path, point

T0 = 1_800_000_000.0


def served_events(effects: list[fx.Effect]) -> list[int | None]:
    return [e.event.request_id for e in only(effects, fx.Emit) if e.event.kind == "user_served"]


def carry(world: JournalWorld, effects: list[fx.Effect]) -> list[str]:
    """What app.py does with the logic's records: each service to the journal, through the view."""
    refused = []
    for e in only(effects, fx.RecordService):
        try:
            world.record_service(e.request_id, e.user_id, e.tasks, e.hover_index, e.xyz, e.bits, e.reward, 1e5,
                                 T0, e.bound_tasks)
        except JournalError as err:
            refused.append(str(err))
    return refused


def hold(run: Run, world: JournalWorld, seq: int, xyz: tuple[float, float, float], start_s: float) -> list[str]:
    """Fly to item ``seq`` at ``xyz``, hold there as long as the binding needs, leave."""
    refused = []
    before = len(run.effects)
    run.tick(seq=seq, xyz=xyz, boot_s=start_s)
    needed = run.s.holds.binding.needed_s if run.s.holds.binding is not None else 0.0
    for t in range(1, int(needed) + 2):
        run.tick(seq=seq, xyz=xyz, boot_s=start_s + t)
    run.tick(seq=seq + 1, xyz=(xyz[0] + 60.0, xyz[1], xyz[2]), boot_s=start_s + needed + 3)
    refused += carry(world, run.effects[before:])
    return refused


@pytest.mark.parametrize("fails", [False, True])
def test_a_service_the_journal_refuses_is_served_and_announced_once(tmp_path: Path, fails: bool) -> None:
    journal = Journal(tmp_path / "journal.sqlite", synchronous="OFF", now_s=T0)
    world = JournalWorld(journal)
    a, _ = journal.accept("a", 120.0, 200.0, 0.0, 10, None, T0)
    b, _ = journal.accept("b", 480.0, 480.0, 0.0, 12, None, T0)
    run = Run(world)  # type: ignore[arg-type]
    (plan,) = only(run.tick(), fx.MakePlan)
    # two points near a: the second finds a served, or finds nobody
    out = run.feed(ins.Planned(plan.basis, path(point(3, 120.0, 200.0, "a", a), point(4, 125.0, 205.0, "a", a))))
    (up,) = only(out, fx.Upload)
    run.feed(ins.Uploaded(up))
    run.feed(ins.CommandDone(fx.Command("start")), armed=True, mode="AUTO")
    run.tick(airborne=True, seq=1, xyz=(0.0, 0.0, 50.0), boot_s=5.0)
    if fails:
        (tmp_path / "journal.sqlite").unlink()  # the journal fails at its next write
    refused = hold(run, world, 2, (120.0, 200.0, 100.0), 10.0)
    if fails:
        assert refused and "deleted" in refused[0], refused
        run.feed(ins.PartFailed(journal.failed or ""))
        assert world.services_of("a") == 1 and world.request_for("a") is None
        assert [r.user_id for r in world.pending()] == ["b"] and world.pending_count() == 1
    else:
        assert not refused
    refused += hold(run, world, 3, (125.0, 205.0, 100.0), 60.0)
    # at the second point the model's rule serves b (a is served): a's request once, b's once
    assert served_events(run.effects) == [a, b], "a's request announced once"
    services = only(run.effects, fx.RecordService)
    assert [(s.request_id, s.tasks) for s in services] == [(a, 10), (b, 12)]
    assert len(refused) == (2 if fails else 0), "b's service is refused too (the journal failed), and kept"
    if fails:
        assert world.pending() == [] and world.services_of("b") == 1
    journal.close()


def test_a_fleet_members_view_counts_the_others_services(tmp_path: Path) -> None:
    """``FleetWorld``: another member's service takes its tasks off the user's request in
    force here and counts toward the fairness rule (who owns a user is the sortie logic's
    to judge: ``tests/service/test_fleet_logic.py``)."""
    journal = Journal(tmp_path / "journal.sqlite", now_s=T0)
    world = FleetWorld(journal)
    try:
        a, _ = journal.accept("a", 100.0, 100.0, 0.0, 10, None, T0)
        journal.accept("b", 300.0, 300.0, 0.0, 8, None, T0)
        assert [r.user_id for r in world.pending()] == ["a", "b"] and world.served_elsewhere("a") is None
        assert world.count_remote("a", 4)  # uav2 served 4 of a's 10 tasks
        row = world.request_for("a")
        assert row is not None and row.request_id == a and row.backlog == 6 and world.services_of("a") == 1
        assert world.served_elsewhere("a") is None  # tasks left: a hold here still serves them
        assert world.count_remote("a", 6)
        assert world.request_for("a") is None and world.services_of("a") == 2
        assert world.served_elsewhere("a") == "another member served a's request meanwhile"
        assert not world.count_remote("nobody", 3) and world.services_of("nobody") == 1
    finally:
        journal.close()
