"""One quick experiment end to end through the command line, as a user runs it."""

from __future__ import annotations

import csv
import json
import subprocess

import pytest

from planner_service.experiments.report import claims_markdown

ALGOS = {"mcts-paper", "ts-mcts", "mcts", "ql", "dqn", "greedy", "random"}


def run(python, env, *args):
    return subprocess.run([python, "-m", "planner_service", "experiment", *args], env=env,
                          capture_output=True, text=True, timeout=120)


def test_hover_layout_quick_writes_csv_png_and_json(python, python_env, tmp_path):
    out = tmp_path / "out"
    proc = run(python, python_env, "hover-layout", "--quick", "--workers", "2", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "100%" in proc.stderr  # the progress bar
    for suffix in ("csv", "png", "json"):
        assert (out / f"hover-layout.{suffix}").stat().st_size > 1000
    assert (out / "hover-layout.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    with open(out / "hover-layout.csv") as f:
        rows = list(csv.DictReader(f))
    # the quick form: 2 layouts x (5 trained algorithms x 3 episodes + 2 static), 3 seeds
    assert len(rows) == 2 * (5 * 3 + 2)
    assert {r["setting"] for r in rows} == {"original layout", "uniform layout"}
    assert {r["algo"] for r in rows} == ALGOS
    assert {r["episodes"] for r in rows if r["algo"] == "dqn"} == {"10", "30", "100"}
    for r in rows:
        assert r["preset"] == "paper" and r["seeds"] == "3"
        mean, lo, hi = (float(r[f"throughput_tasks_per_interval_{k}"]) for k in ("mean", "lo", "hi"))
        assert 0 < mean <= 20 and lo <= mean <= hi
        assert 1 <= float(r["intervals_mean"]) <= 10
        assert -1 <= float(r["average_reward_mean"]) <= 1
        assert float(r["throughput_bits_per_interval_mean"]) == pytest.approx(1e5 * mean)
        assert float(r["fairness_violations_mean"]) == 0 and float(r["energy_violation_mean"]) == 0

    summary = json.loads((out / "hover-layout.json").read_text())
    assert summary["experiment"] == "hover-layout" and summary["preset"] == "paper"
    assert summary["episodes"] == [10, 30, 100] and summary["seeds"] == [0, 1, 2] and summary["quick"]
    assert summary["settings"][1]["changes"] == {"hover_layout": "uniform"}
    assert len(summary["points"]) == len(rows)
    claims = {c["id"]: c for c in summary["claims"]}
    assert {"appA-similar", "appA-mcts-best"} <= set(claims)
    assert len(claims["appA-similar"]["checks"]) == len(ALGOS)
    assert summary["run"]["commit"] and summary["run"]["sorties_cpu_s"] > 0

    table = claims_markdown(out)  # the docs' tables are made from these files
    assert table.startswith("### hover-layout (Appendix A, preset paper, 3 seeds")
    assert f"**appA-similar** (Appendix A): {claims['appA-similar']['claim']}" in table
    assert table.count("| mcts-paper, n=100 | throughput(uniform) - throughput(original) |") == 1


def test_bad_arguments_are_refused(python, python_env, tmp_path):
    bad_name = run(python, python_env, "fig-99", "--out", str(tmp_path))
    assert bad_name.returncode == 2 and "fig-99" in bad_name.stderr
    bad_episodes = run(python, python_env, "3d", "--episodes", "10,x", "--out", str(tmp_path))
    assert bad_episodes.returncode == 2 and "--episodes" in bad_episodes.stderr
    bad_override = run(python, python_env, "3d", "--set", "sped_mps=3", "--out", str(tmp_path))
    assert bad_override.returncode == 2 and "sped_mps" in bad_override.stderr
