"""``bench --fleet``: decision times per UAV and message sizes, over the fleet registry."""

from __future__ import annotations

import json
import subprocess

from planner_service.bench.fleet import run_fleet_bench, time_fleet_decisions
from planner_service.bench.run import scenario_of
from planner_service.fleet import policies


class _Talker(policies.IndependentFleet):
    """A stand-in for a message-passing planner: 40 bytes for every decision, to each other UAV."""

    def __init__(self, base, spec, rngs):
        super().__init__(base, spec, rngs)
        self.message_bytes: list[int] = []

    def decide(self, env):
        self.message_bytes += [40] * (env.num_uavs - 1)
        return super().decide(env)


def test_messages_are_counted_and_joint_is_skipped_beyond_its_size(monkeypatch):
    monkeypatch.setitem(policies.FLEET_PLANNERS, "talker", _Talker)
    monkeypatch.setitem(policies.FLEET_PLANNERS, "joint", policies.IndependentFleet)
    row = time_fleet_decisions(scenario_of(20, 10), 3, "talker", 5, 7)
    assert row["decisions"] == 7 and row["messages_sent"] == 7 * 2 and row["message_bytes_max"] == 40
    assert 0 < row["median_ms"] <= row["p95_ms"]
    res = run_fleet_bench(2, 5, sizes=((20, 10),), uavs=(3, 5))
    got = {(r["algo"], r["N"]) for r in res["rows"]}
    assert got == {(a, n) for a in ("claims", "dec-mcts", "independent", "talker") for n in (3, 5)} | {("joint", 3)}
    assert res["skipped"] == ["joint at N=5, K=20: beyond JOINT_MAX_UAVS=3"]
    assert all(r["message_bytes_max"] == 0 for r in res["rows"] if r["algo"] not in ("talker", "dec-mcts"))
    assert all(0 < r["message_bytes_max"] < 2048 for r in res["rows"] if r["algo"] == "dec-mcts")


def test_joint_is_skipped_where_its_search_does_not_fit():
    # K = 40 at N = 3: 64 000 joint actions; joint refuses them (it stopped the whole bench)
    res = run_fleet_bench(2, 5, sizes=((40, 10),), uavs=(3,))
    assert "joint" not in {r["algo"] for r in res["rows"]} and {r["algo"] for r in res["rows"]}
    assert res["skipped"] == ["joint at N=3, K=40: K^N = 64000 joint actions, beyond 10000"]


def test_bench_fleet_quick_json(python, python_env):
    proc = subprocess.run([python, "-m", "planner_service", "bench", "--fleet", "--quick", "--json",
                           "--decisions", "3", "--iterations", "20"],
                          env=python_env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    res = json.loads(proc.stdout)
    assert res["iterations"] == 20 and res["target_ms"] == 150.0 and res["target_message_bytes"] == 2048
    assert [(r["algo"], r["N"], r["K"], r["I"]) for r in res["rows"]] == [  # the paper's size only
        ("claims", 3, 20, 10), ("dec-mcts", 3, 20, 10), ("independent", 3, 20, 10), ("joint", 3, 20, 10),
        ("claims", 5, 20, 10), ("dec-mcts", 5, 20, 10), ("independent", 5, 20, 10)]
    for r in res["rows"]:
        assert r["decisions"] == 3 and 0 < r["median_ms"] <= r["p95_ms"]
        assert (0 < r["message_bytes_max"] < 2048) if r["algo"] == "dec-mcts" else r["message_bytes_max"] == 0
