"""The command lines, run as a user runs them."""

from __future__ import annotations

import json
import subprocess


def run(python, env, *args, check=True):
    return subprocess.run([python, *args], env=env, capture_output=True, text=True, timeout=120, check=check)


def test_help_lists_the_commands(python, python_env):
    out = run(python, python_env, "-m", "planner_service", "--help").stdout
    for name in ("serve", "demo", "plan", "experiment", "bench", "submit", "keygen", "export", "warm"):
        assert name in out
    out = run(python, python_env, "-m", "sim_bridge", "--help").stdout
    for name in ("vehicle", "users", "lossy-proxy", "router"):
        assert name in out


def test_plan_json_summary(python, python_env):
    out = run(python, python_env, "-m", "planner_service", "plan", "--preset", "paper",
              "--algo", "greedy", "--seed", "4", "--json").stdout
    summary = json.loads(out)
    for key in ("algo", "preset", "seed", "iterations", "intervals", "throughput_tasks_per_interval",
                "throughput_bits_per_interval", "average_reward", "energy_used_j", "energy_budget_j",
                "served", "hover_points", "fairness_violations", "energy_violation", "wall_s",
                "scenario", "trace"):
        assert key in summary, key
    assert summary["scenario"]["speed_mps"] == 20.0
    assert summary["intervals"] == len(summary["trace"]) == len(summary["served"])
    tasks = [r["tasks"] for r in summary["trace"]]
    assert summary["throughput_tasks_per_interval"] == sum(tasks) / len(tasks)
    assert summary["throughput_bits_per_interval"] == 1e5 * sum(tasks) / len(tasks)
    assert summary["fairness_violations"] == 0 and summary["energy_violation"] is False


def test_plan_a_fleet(python, python_env):
    out = run(python, python_env, "-m", "planner_service", "plan", "--preset", "fleet", "--uavs", "3", "--algo",
              "claims", "--iterations", "100", "--seed", "2", "--json").stdout
    summary = json.loads(out)
    assert (summary["algo"], summary["base"], summary["uavs"], summary["preset"]) == ("claims", "mcts", 3, "fleet")
    per_uav, fleet = summary["per_uav"], summary["fleet"]
    assert [u["uav"] for u in per_uav] == [0, 1, 2]
    assert fleet["throughput_tasks_per_interval"] == sum(u["throughput_tasks_per_interval"] for u in per_uav)
    assert fleet["total_tasks"] == sum(u["total_tasks"] for u in per_uav)
    assert fleet["double_services"] == fleet["double_holds"] == fleet["fairness_violations"] == 0
    assert [u["scenario"]["altitude_m"] for u in per_uav] == [100.0, 110.0, 120.0]
    text = run(python, python_env, "-m", "planner_service", "plan", "--preset", "fleet", "--uavs", "2",
               "--iterations", "50").stdout
    assert "independent (mcts per UAV) on fleet, 2 UAVs" in text and "double services   0, double holds 0" in text


def test_plan_override_and_bad_override(python, python_env):
    out = run(python, python_env, "-m", "planner_service", "plan", "--algo", "random", "--seed", "1",
              "--set", "speed_mps=10", "--json").stdout
    assert json.loads(out)["scenario"]["speed_mps"] == 10.0
    bad = run(python, python_env, "-m", "planner_service", "plan", "--set", "sped_mps=10", check=False)
    assert bad.returncode == 2 and "sped_mps" in bad.stderr


def test_same_result_without_numba(python, python_env):
    args = ("-m", "planner_service", "plan", "--algo", "greedy", "--seed", "8", "--json")
    with_numba = json.loads(run(python, python_env, *args).stdout)
    python_env["UAV_PLANNER_NO_NUMBA"] = "1"
    without = json.loads(run(python, python_env, *args).stdout)
    assert with_numba["trace"] == without["trace"]


def test_plan_with_a_clock_budget_only(python, python_env):
    out = run(python, python_env, "-m", "planner_service", "plan", "--algo", "mcts", "--budget-ms", "15",
              "--seed", "2", "--json").stdout
    summary = json.loads(out)
    assert summary["iterations"] is None and summary["budget_ms"] == 15.0
    assert summary["intervals"] >= 1 and summary["fairness_violations"] == 0
    bad = run(python, python_env, "-m", "planner_service", "plan", "--algo", "mcts-paper", "--budget-ms", "15", check=False)
    assert bad.returncode == 2 and "iterations" in bad.stderr


def test_warm_leaves_the_planners_kernels_in_numbas_cache(python, python_env):
    from pathlib import Path

    out = run(python, python_env, "-m", "planner_service", "warm").stdout
    assert out.startswith("planner kernels compiled or loaded in "), out
    cache = Path(__file__).resolve().parent.parent / "planner_service" / "mcts" / "__pycache__"
    assert any(cache.glob("*.nbi")), "no kernel in numba's cache beside the search's sources"
