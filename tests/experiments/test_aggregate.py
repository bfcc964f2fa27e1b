"""Aggregation over seeds, paired differences, and the CSV / JSON files, on records made by hand."""

from __future__ import annotations

import csv
import json
import math

import pytest

from planner_service.experiments import METRICS, Results, Setting, write_csv, write_json
from planner_service.model import preset


def record(algo, episodes, seed, reward, throughput):
    r = {m: 0.0 for m in METRICS}
    r.update(algo=algo, episodes=episodes, seed=seed, average_reward=reward, throughput_tasks_per_interval=throughput)
    return r


@pytest.fixture
def results():
    res = Results([Setting("v=20 m/s", preset("paper"))], ("mcts", "greedy"), (10, 100), (0, 1, 2))
    # mcts at n=10: rewards 0.1, 0.2, 0.3; at n=100: 0.2, 0.4, 0.3; greedy: 0.15, 0.25, 0.2
    for seed, (a, b, g) in enumerate([(0.1, 0.2, 0.15), (0.2, 0.4, 0.25), (0.3, 0.3, 0.2)]):
        res.add("v=20 m/s", record("mcts", 10, seed, a, 10 + seed))
        res.add("v=20 m/s", record("mcts", 100, seed, b, 12 + seed))
        res.add("v=20 m/s", record("greedy", None, seed, g, 15.0))
    return res


T2 = 4.302652730  # t(2)


def test_point_is_the_mean_and_t_interval_over_seeds(results):
    iv = results.point("v=20 m/s", "mcts", 10, "average_reward")
    # mean 0.2, s = 0.1, se = 0.1 / sqrt(3)
    assert iv.n == 3 and iv.mean == pytest.approx(0.2)
    assert iv.hi - iv.mean == pytest.approx(T2 * 0.1 / math.sqrt(3))


def test_paired_difference_is_taken_seed_by_seed(results):
    # differences mcts(n=100) - greedy: 0.05, 0.15, 0.1 -> mean 0.1, s = 0.05
    d = results.paired(results.key("v=20 m/s", "mcts", 100), results.key("v=20 m/s", "greedy", 100), "average_reward")
    assert d.mean == pytest.approx(0.1)
    assert d.hi - d.mean == pytest.approx(T2 * 0.05 / math.sqrt(3))
    # the static algorithm's key ignores the episodes
    assert results.key("v=20 m/s", "greedy", 100) == ("v=20 m/s", "greedy", None)


def test_rows_have_one_point_per_algorithm_and_episodes(results):
    rows = results.rows("demo", "paper")
    assert [(r["algo"], r["episodes"]) for r in rows] == [("mcts", 10), ("mcts", 100), ("greedy", "")]
    mcts100 = rows[1]
    assert mcts100["seeds"] == 3
    assert mcts100["throughput_tasks_per_interval_mean"] == pytest.approx(13.0)
    assert mcts100["average_reward_mean"] == pytest.approx(0.3)
    assert rows[2]["throughput_tasks_per_interval_lo"] == rows[2]["throughput_tasks_per_interval_hi"] == 15.0


def test_csv_round_trip(results, tmp_path):
    path = write_csv(results.rows("demo", "paper"), tmp_path / "demo.csv")
    with open(path) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 3
    assert rows[0]["experiment"] == "demo" and rows[0]["setting"] == "v=20 m/s"
    assert float(rows[0]["average_reward_mean"]) == pytest.approx(0.2)
    assert float(rows[0]["average_reward_lo"]) == pytest.approx(0.2 - T2 * 0.1 / math.sqrt(3))
    assert rows[2]["episodes"] == ""
    for m in METRICS:
        assert {f"{m}_mean", f"{m}_lo", f"{m}_hi"} <= set(rows[0])


def test_csv_writes_an_undefined_bound_as_an_empty_cell(tmp_path):
    path = write_csv([{"a": 1.0, "b": math.nan}], tmp_path / "x.csv")
    assert path.read_text().splitlines() == ["a,b", "1.0,"]


def test_json_has_no_nan(tmp_path):
    path = write_json({"x": math.nan, "y": (1, 2.5), "z": {"w": math.inf}}, tmp_path / "x.json")
    assert json.loads(path.read_text()) == {"x": None, "y": [1, 2.5], "z": {"w": None}}
