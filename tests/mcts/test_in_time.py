"""Tasks that arrive in time (``task_arrival_period_s`` > 0): an interval's arrivals follow
how long it lasted, in the world and in the planner's playouts, which then draw their
futures afresh and confirm a departure from greedy on paired fresh futures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner_service.mcts import MctsConfig, MctsPlanner
from planner_service.mcts.futures import root_values_of
from planner_service.model import SortieEnv, field, pack, scene_of
from planner_service.model.interval import interval_duration_s
from planner_service.model.mobility import poisson_quantile
from planner_service.policy import PolicySpec
from planner_service.sortie import run_sortie

IN_TIME = field().replace(task_model="backlog", task_arrival_period_s=55.0)


@pytest.mark.parametrize("mean", [0.3, 1.0, 2.7])
def test_the_quantile_of_a_uniform_is_a_poisson_draw(mean: float) -> None:
    zero = math.exp(-mean)  # P(N = 0): below it 0, above it at least 1
    assert poisson_quantile(mean, zero * (1 - 1e-9)) == 0 and poisson_quantile(mean, zero * (1 + 1e-9)) == 1
    draws = np.array([poisson_quantile(mean, u) for u in np.random.default_rng(1).random(200_000)])
    assert draws.mean() == pytest.approx(mean, rel=0.02) and draws.var() == pytest.approx(mean, rel=0.03)
    assert poisson_quantile(0.0, 0.99) == 0


def test_an_interval_brings_arrivals_in_proportion_to_its_duration() -> None:
    s = IN_TIME.replace(num_users=2000, task_max=10_000, task_arrival_mean=2.0, user_move_range_m=0.0,
                        task_arrival_period_s=110.0)
    env = SortieEnv(s)
    env.reset(seed=1)
    before, start = env.state.tasks.copy(), env.state.uav_xyz.copy()
    *_, info = env.step(int(np.argmax(env.action_values())))
    duration = interval_duration_s(env.params, start, np.array(info["uav_xyz"]), np.array(info["user_xyz"]),
                                   info["bits"])
    mean = 2.0 * duration / 110.0
    arrivals = np.delete(env.state.tasks - before, info["user"])
    assert abs(mean - 2.0) > 0.5  # tells the scaled mean from the per-interval one
    assert arrivals.mean() == pytest.approx(mean, rel=0.08) and arrivals.var() == pytest.approx(mean, rel=0.15)


def _planner_at_start(seed: int) -> tuple[MctsPlanner, SortieEnv]:
    env = SortieEnv(IN_TIME)
    env.reset(seed=seed)
    env.step(int(np.argmax(env.action_values())))  # in the air: the flight's time counts
    return MctsPlanner(IN_TIME, env.hover_points, MctsConfig(iterations=64), np.random.default_rng(seed)), env


def test_the_paired_playouts_play_both_actions_on_the_same_futures() -> None:
    planner, env = _planner_at_start(4)
    scene = scene_of(pack(IN_TIME), env.hover_points, env.state.task_table)
    root = env.state.world()
    values = root_values_of(scene, root, planner.tables)
    allowed = np.flatnonzero(np.isfinite(values.q))
    settings = planner._settings(env.state)
    same = planner._paired_fresh(scene, root, values, settings, int(allowed[0]), int(allowed[0]))
    assert same.shape == (planner.config.confirm_futures, 2) and (same[:, 0] == same[:, 1]).all()
    assert len(set(same[:, 0])) > 1  # and the futures differ from one another
    other = planner._paired_fresh(scene, root, values, settings, int(allowed[0]), int(allowed[-1]))
    assert (other[:, 0] != other[:, 1]).any()


def test_the_planner_flies_whole_sorties_and_repeats_itself() -> None:
    for seed in (2, 3):
        a, b = (run_sortie(IN_TIME, "mcts", seed, PolicySpec(200)) for _ in range(2))
        assert a["intervals"] >= 5 and a["fairness_violations"] == 0 and not a["energy_violation"]
        assert a["hover_points"] == b["hover_points"]


@pytest.mark.slow
def test_in_the_world_in_time_the_planner_that_knows_it_beats_greedy() -> None:
    """The world as flown (``arrivals_every_s``: each user's draw every 55 s, as ``sim_bridge
    users``) over 100 seeds, paired: ``mcts`` planning with arrivals in time ahead of greedy
    by two standard errors in tasks per interval and in reward, and ahead of ``mcts``
    planning with arrivals per interval in tasks per interval (docs/MODEL.md, "Task
    models", prints the table's rows). About a minute."""
    world = {"arrivals_every_s": 55.0}
    per_interval = IN_TIME.replace(task_arrival_period_s=0.0)
    seeds = range(1, 101)
    runs = {name: [run_sortie(scenario, algo, seed, PolicySpec(1000), options) for seed in seeds]
            for name, algo, scenario, options in (
                ("in time", "mcts", IN_TIME, world), ("per interval", "mcts", per_interval, world),
                ("greedy", "greedy", per_interval, world),
                # the per-interval planner in the world it assumes, for the table's last row
                ("per interval, own world", "mcts", per_interval, None), ("greedy, own world", "greedy", per_interval,
                                                                          None))}

    def paired(a: str, b: str, figure: str) -> tuple[float, float]:
        diff = np.array([x[figure] - y[figure] for x, y in zip(runs[a], runs[b])])
        return diff.mean(), diff.std(ddof=1) / np.sqrt(len(diff))

    for name, other in (("per interval", "greedy"), ("in time", "greedy"),
                        ("per interval, own world", "greedy, own world")):
        reward = [x["average_reward"] - y["average_reward"] for x, y in zip(runs[name], runs[other])]
        print(f"mcts planning {name} - greedy: " + "; ".join(
            "{} {:+.3f} +- {:.3f}".format(figure, *paired(name, other, figure))
            for figure in ("throughput_tasks_per_interval", "average_reward"))
            + f"; reward ahead on {sum(d > 0 for d in reward)}, behind on {sum(d < 0 for d in reward)}")
    for figure in ("throughput_tasks_per_interval", "average_reward"):
        mean, se = paired("in time", "greedy", figure)
        assert mean > 2 * se, figure
    mean, se = paired("in time", "per interval", "throughput_tasks_per_interval")
    assert mean > 2 * se
