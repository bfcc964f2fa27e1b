"""``bench --flight``'s seed-by-seed comparison (the flights themselves take minutes: the
bench is a command, not a test)."""

from __future__ import annotations

from planner_service.bench.flight import USERS_ARRIVAL_PERIOD_S, format_flight, paired_line, run_flight_bench
from sim_bridge.users import TaskParams


def _row(algo: str, tasks: list[float], reward: list[float]) -> dict:
    return {"algo": algo, "per_seed": {"flown": {"throughput_tasks_per_interval": tasks, "average_reward": reward}}}


def test_the_paired_line_counts_the_seeds_each_leads_and_the_median_difference() -> None:
    a = _row("mcts", [14.0, 13.0, 12.0, 15.5], [0.30, 0.20, 0.25, 0.40])
    b = _row("greedy", [13.0, 13.0, 13.0, 15.0], [0.10, 0.25, 0.25, 0.20])
    line = paired_line(a, b)
    # differences 1, 0, -1, 0.5: median 0.25, mean 0.125, s.d. 0.854 (s.e. 0.427);
    # 0.2, -0.05, 0, 0.2: median 0.1, mean 0.0875, s.d. 0.1315 (s.e. 0.0657)
    assert line == ("flown mcts - greedy, per seed: tasks/interval median +0.25, mean +0.12 +- 0.43 (ahead on 2, "
                    "behind on 1 of 4); reward median +0.100, mean +0.087 +- 0.066 (ahead on 2, behind on 1 of 4)")


def test_the_timed_world_is_the_simulated_users_arrival_period() -> None:
    assert USERS_ARRIVAL_PERIOD_S == TaskParams().interval_s


def test_offline_only_plans_both_offline_worlds_and_compares_them_seed_by_seed() -> None:
    r = run_flight_bench([1, 2], ["greedy", "random"], budget_ms=5.0, fly_too=False)
    greedy, random = r["rows"]
    assert set(greedy["per_seed"]) == {"offline", "timed"} and not r["flown"]
    for row in r["rows"]:
        for world in ("offline", "timed"):
            assert all(n > 0 for n in row["per_seed"][world]["total_tasks"])
    # greedy's choices do not depend on how the tasks arrive until the backlogs differ: the
    # two worlds give the same first world but not the same sortie
    assert greedy["per_seed"]["offline"] != greedy["per_seed"]["timed"]
    text = format_flight(r)
    assert "timed greedy - random, per seed" in text and "offline greedy - random, per seed" in text
    assert "flown" not in text.split("\n", 1)[1]
