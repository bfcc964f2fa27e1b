"""Tasks that arrive in time (the environment's ``arrivals_every_s``): a draw of the model's
arrivals once every period of flight and hold, each user at its phase; the rest of the
world as the model's."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner_service.model import ScenarioError, SortieEnv, field, pack
from planner_service.model.arrivals import TimedArrivals
from planner_service.model.mobility import draw_arrivals
from planner_service.service.planning import hold_time_s

BACKLOG = field().replace(task_model="backlog", num_users=10)


def test_each_user_draws_once_a_period_at_its_phase_capped_at_u_max() -> None:
    p = pack(BACKLOG.replace(task_arrival_mean=6.0))
    law = TimedArrivals(10.0, np.array([3.0, 7.0]), 0.0, np.random.default_rng(5))
    tasks = np.array([0, BACKLOG.task_max - 1], dtype=np.int64)
    law.run(p, tasks, 4.0)  # user 0's draw at 3 s is due, user 1's at 7 s is not
    assert law.due_s.tolist() == [13.0, 7.0] and law.clock_s == 4.0
    law.run(p, tasks, 20.0)  # by 24 s: user 0 at 13 and 23 s, user 1 at 7 and 17 s
    assert law.due_s.tolist() == [33.0, 27.0]
    replay, one = np.random.default_rng(5), np.zeros(1, dtype=np.int64)
    draws = []
    for _ in range(5):
        draw_arrivals(p, one, replay)
        draws.append(int(one[0]))
    assert tasks[0] == min(sum(draws[:3]), BACKLOG.task_max) and tasks[1] == BACKLOG.task_max


def _greedy_actions(env: SortieEnv, seed: int, options: dict | None = None) -> list[int]:
    env.reset(seed=seed, options=options)
    actions = []
    while not env.done:
        actions.append(int(np.argmax(env.action_values())))
        env.step(actions[-1])
    return actions


def test_only_the_tasks_change_and_the_clock_is_the_flights_and_the_holds() -> None:
    model, timed = SortieEnv(BACKLOG), SortieEnv(BACKLOG)
    actions = _greedy_actions(SortieEnv(BACKLOG), 3)
    model.reset(seed=3)
    timed.reset(seed=3, options={"arrivals_every_s": 55.0})
    assert timed.state.tasks.tolist() == model.state.tasks.tolist()  # the first backlogs
    p, clock, differed = timed.params, 0.0, False
    for a in actions:
        if timed.done or not timed.action_mask()[a]:
            break
        start = timed.state.uav_xyz.copy()
        *_, m = model.step(a)
        *_, t = timed.step(a)
        # the users walk alike (the world's generator is not drawn from by the timed law)
        assert timed.state.users.tolist() == model.state.users.tolist()
        hold = hold_time_s(p, np.array(t["uav_xyz"]), np.array(t["user_xyz"]), t["bits"])
        clock += math.dist(start, t["uav_xyz"]) / BACKLOG.speed_mps + hold
        assert timed.arrivals.clock_s == pytest.approx(clock, rel=1e-9)
        differed |= timed.state.tasks.tolist() != model.state.tasks.tolist()
    assert differed and clock > 2 * 55.0


def test_a_long_interval_brings_more_tasks_than_a_short_one() -> None:
    near, far = SortieEnv(BACKLOG), SortieEnv(BACKLOG)
    for env in (near, far):
        env.reset(seed=8, options={"arrivals_every_s": 30.0})
    start = near.state.uav_xyz
    order = np.argsort(np.linalg.norm(near.hover_points - start, axis=1))
    allowed = [int(k) for k in order if near.action_mask()[k]]
    near.step(allowed[0])
    far.step(allowed[-1])
    assert far.arrivals.clock_s > near.arrivals.clock_s
    drawn = [int(((env.arrivals.due_s - 30.0) // 30.0 + 1).sum()) for env in (near, far)]
    assert drawn[1] > drawn[0]  # draws made by each: every draw moved its user's due time on


def test_snapshot_restore_continues_identically() -> None:
    env = SortieEnv(BACKLOG)
    env.reset(seed=2, options={"arrivals_every_s": 40.0})
    env.step(int(np.argmax(env.action_values())))
    snap = env.snapshot()
    a = _continue(env)
    env.restore(snap)
    assert _continue(env) == a


def _continue(env: SortieEnv) -> list[list[int]]:
    seen = []
    while not env.done:
        env.step(int(np.argmax(env.action_values())))
        seen.append(env.state.tasks.tolist())
    return seen


@pytest.mark.parametrize("period", [0.0, -5.0, math.nan, math.inf, "soon"])
def test_a_period_that_is_not_a_positive_number_of_seconds_is_refused(period: object) -> None:
    with pytest.raises(ScenarioError) as err:
        SortieEnv(BACKLOG).reset(seed=0, options={"arrivals_every_s": period})
    assert err.value.field == "arrivals_every_s"


def test_timed_arrivals_need_tasks_that_wait_and_no_task_table() -> None:
    with pytest.raises(ScenarioError, match="backlog") as err:
        SortieEnv(field()).reset(seed=0, options={"arrivals_every_s": 55.0})
    assert err.value.field == "arrivals_every_s"
    table = np.ones((2, BACKLOG.num_users), dtype=np.int64)
    with pytest.raises(ScenarioError, match="task_table") as err:
        SortieEnv(BACKLOG).reset(seed=0, options={"arrivals_every_s": 55.0, "task_table": table})
    assert err.value.field == "arrivals_every_s"
