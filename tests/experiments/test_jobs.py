"""Jobs, the trajectory replay, the registry's job lists and the process-pool runner."""

from __future__ import annotations

import numpy as np
import pytest

from planner_service.experiments import EXPERIMENTS, Job, RunConfig, replay_users, run_job, run_jobs, three_d
from planner_service.model import preset, user_rows
from planner_service.policy import PolicySpec
from planner_service.sortie import run_sortie


def test_three_d_of_the_paper_preset_is_the_paper_3d_preset():
    assert three_d(preset("paper")) == preset("paper-3d")
    assert three_d(preset("field")).dimensions == 3 and three_d(preset("field")).bandwidth_hz == 2000.0


def test_replay_reproduces_the_users_of_a_sortie():
    s = preset("paper")
    summary = run_sortie(s, "greedy", 3, PolicySpec())
    users = replay_users(s, 3, summary["trace"])
    assert users.shape == (len(summary["trace"]) + 1, s.num_users, 3)
    assert np.array_equal(users[0], user_rows(s.num_users, s.area_side_m))
    for t, rec in enumerate(summary["trace"]):
        assert users[t][rec["user"]].tolist() == rec["user_xyz"]
    assert not np.array_equal(users[0], users[-1])  # they moved


def test_a_path_job_records_the_trace_and_users():
    rec = run_job(Job(preset("paper"), "greedy", None, 2, record_paths=True))
    assert len(rec["trace"]) == rec["intervals"] and len(rec["users_xyz"]) == rec["intervals"] + 1


def test_jobs_per_experiment_and_shared_jobs():
    cfg = RunConfig(base=preset("paper"), episodes=(10, 30), seeds=(0, 1))
    # 2 speeds x (5 trained x 2 episodes + 2 static) x 2 seeds
    assert len(EXPERIMENTS["reward-vs-episodes"].jobs(cfg)) == 2 * 12 * 2
    # the 20 m/s setting of Fig. 3 is the setting of Fig. 4 and the timesaving experiment
    fig3 = {j for _, j in EXPERIMENTS["reward-vs-episodes"].jobs(cfg)}
    assert {j for _, j in EXPERIMENTS["throughput-vs-episodes"].jobs(cfg)} <= fig3
    # the timesaving experiment times its MCTS sorties apart (best of three), shares the rest
    ts = [j for _, j in EXPERIMENTS["timesaving"].jobs(cfg)]
    assert {j.repeats for j in ts if j.algo in ("mcts-paper", "ts-mcts", "mcts")} == {3}
    assert {j for j in ts if j.repeats == 1} <= fig3 and len([j for j in ts if j.repeats == 1]) == 2 * 2 * 2 + 2 * 2
    # the trajectory flies only the largest n, and records the first seed's sorties
    traj = [j for _, j in EXPERIMENTS["trajectory"].jobs(cfg)]
    assert {j.episodes for j in traj} == {30, None}
    assert sum(j.record_paths for j in traj) == 7 and all(j.seed == 0 for j in traj if j.record_paths)


def test_pool_gives_the_same_sorties_as_this_process():
    jobs = [Job(preset("paper"), algo, n, seed) for algo, n in (("mcts-paper", 5), ("ql", 3), ("greedy", None))
            for seed in (0, 1)]
    pooled = run_jobs(jobs, workers=2)
    assert set(pooled) == set(jobs)
    for job in jobs:
        here = run_job(job)
        for key in ("average_reward", "throughput_tasks_per_interval", "intervals", "energy_used_j"):
            assert pooled[job][key] == pytest.approx(here[key], rel=0, abs=0), (job, key)


def test_repeats_keep_the_same_sortie():
    job = Job(preset("paper"), "ts-mcts", 20, 4)
    once, thrice = run_job(job), run_job(Job(preset("paper"), "ts-mcts", 20, 4, repeats=3))
    for key in ("average_reward", "throughput_tasks_per_interval", "intervals", "energy_used_j"):
        assert once[key] == thrice[key]
    assert thrice["wall_s"] > 0
