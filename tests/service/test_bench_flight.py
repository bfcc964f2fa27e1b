"""``bench --flight``'s seed-by-seed comparison (the flights themselves take minutes: the
bench is a command, not a test)."""

from __future__ import annotations

from planner_service.bench.flight import paired_line


def _row(algo: str, tasks: list[float], reward: list[float]) -> dict:
    return {"algo": algo, "flown_per_seed": {"throughput_tasks_per_interval": tasks, "average_reward": reward}}


def test_the_paired_line_counts_the_seeds_each_leads_and_the_median_difference() -> None:
    a = _row("mcts", [14.0, 13.0, 12.0, 15.5], [0.30, 0.20, 0.25, 0.40])
    b = _row("greedy", [13.0, 13.0, 13.0, 15.0], [0.10, 0.25, 0.25, 0.20])
    line = paired_line(a, b)
    # differences 1, 0, -1, 0.5 (median 0.25); 0.2, -0.05, 0, 0.2 (median 0.1)
    assert line == ("flown mcts - greedy, per seed: tasks/interval +0.25 (ahead on 2, behind on 1 of 4); "
                    "reward +0.100 (ahead on 2, behind on 1 of 4)")
