"""The fleet experiment: its numbers by hand, its jobs over the fleet registry (planners
added to it appear, a message link only for those that take one), and its --quick path
end to end through the command line."""

from __future__ import annotations

import csv
import json
import math
import subprocess

import numpy as np
import pytest

from planner_service.experiments.fleet import FleetConfig, fleet_jobs, jain_index, mean_se, verdict
from planner_service.fleet import MessageLink, make_fleet_policy, policies, takes_link
from planner_service.model import preset
from planner_service.policy import PolicySpec


def test_mean_se_and_verdict_by_hand():
    d = mean_se([1.0, 2.0, 3.0, 6.0])  # mean 3, s = sqrt(14/3), se = s / 2
    assert d["mean"] == 3.0 and d["n"] == 4 and d["se"] == pytest.approx(math.sqrt(14 / 3) / 2)
    assert verdict({"mean": 0.5, "se": 0.2}) == "ahead"
    assert verdict({"mean": -0.5, "se": 0.2}) == "behind"
    assert verdict({"mean": 0.39, "se": 0.2}) == "within noise"  # 1.95 SE: not two
    assert verdict(mean_se([4.0])) == "one seed"


def test_jain_index_by_hand():
    assert jain_index([5, 5, 5, 5]) == 1.0
    assert jain_index([8, 0, 0, 0]) == 0.25
    assert jain_index([1, 3]) == pytest.approx(16 / (2 * 10))
    assert jain_index([0, 0]) == 0.0


class _Talker:
    """A stand-in for a message-passing planner: its factory takes ``link``."""

    def __init__(self, base, spec, rngs, link=None):
        self.link = link


def test_jobs_follow_the_registry(monkeypatch: pytest.MonkeyPatch) -> None:
    cfg = FleetConfig(preset("fleet"), uavs=(1, 2, 3, 4), seeds=(0, 1), iterations=5, joint_max_uavs=2)
    assert cfg.planners() == ["independent", "claims", "dec-mcts", "joint"]
    assert takes_link("dec-mcts") and not takes_link("claims") and not takes_link("joint")
    assert cfg.links() == [(0.0, 0), (0.2, 0), (0.5, 0), (0.0, 1), (0.0, 2), (0.0, 3)]
    jobs = fleet_jobs(cfg)
    plain = [j for j in jobs if j.link is None and not j.record_paths]
    assert sorted({j.uavs for j in plain if j.algo == "joint"}) == [1, 2]  # joint only up to joint_max_uavs
    assert len(plain) == 2 * (4 * 3 + 2)
    linked = [j for j in jobs if j.link is not None]
    assert {j.algo for j in linked} == {"dec-mcts"} and {j.uavs for j in linked} == {3}
    assert len(linked) == 6 * 2
    # paths at N = 3, where joint (N <= 2 here) does not fly
    assert [j.algo for j in jobs if j.record_paths] == ["independent", "claims", "dec-mcts"]
    # the default joint_max_uavs (3) on the fleet preset: 40^3 joint actions do not fit (joint
    # refuses them; flying it stopped the whole experiment)
    default = FleetConfig(preset("fleet"), uavs=(1, 2, 3), seeds=(0,), iterations=5)
    assert sorted({j.uavs for j in fleet_jobs(default) if j.algo == "joint"}) == [1, 2]

    rngs = [np.random.default_rng(k) for k in range(2)]
    # dec-mcts takes the link as its own settings (drop, age)
    config = make_fleet_policy("dec-mcts", "mcts", PolicySpec(iterations=5), rngs, MessageLink(0.2, 1)).config
    assert (config.drop, config.age) == (0.2, 1)
    # a planner whose factory takes the link itself gets it as it is
    monkeypatch.setitem(policies.FLEET_PLANNERS, "talker", _Talker)
    assert takes_link("talker")
    assert make_fleet_policy("talker", "mcts", None, rngs, MessageLink(0.2, 1)).link == MessageLink(0.2, 1)
    with pytest.raises(ValueError, match="sends no messages"):
        make_fleet_policy("claims", "mcts", None, rngs, MessageLink(0.2))


def test_message_link_refuses_bad_values():
    with pytest.raises(ValueError, match="loss"):
        MessageLink(1.0)
    with pytest.raises(ValueError, match="late_intervals"):
        MessageLink(0.0, -1)


def run(python, env, *args):
    return subprocess.run([python, "-m", "planner_service", "experiment", "fleet", *args], env=env,
                          capture_output=True, text=True, timeout=600)


def test_fleet_quick_writes_csv_png_and_json(python, python_env, tmp_path):
    out = tmp_path / "out"
    proc = run(python, python_env, "--quick", "--uavs", "1,2", "--seeds", "2", "--iterations", "20",
               "--workers", "1", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    for name in ("fleet.png", "fleet-paths.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with open(out / "fleet.csv") as f:
        rows = list(csv.DictReader(f))
    planners = ["claims", "dec-mcts", "independent", "joint"]
    assert sorted({(r["uavs"], r["planner"]) for r in rows}) == [(n, p) for n in ("1", "2") for p in planners]
    one = [r for r in rows if r["uavs"] == "1" and r["planner"] in ("claims", "independent")]
    assert one[0]["throughput_tasks_per_interval"] == one[1]["throughput_tasks_per_interval"]  # a fleet of one
    for r in rows:
        assert r["seeds"] == "2" and len(r["per_uav_throughput"].split(";")) == int(r["uavs"])
        assert (0 < int(r["message_bytes_max"]) < 2048) if r["planner"] == "dec-mcts" else r["message_bytes_max"] == "0"
        assert 0 < float(r["jain_index"]) <= 1 and float(r["throughput_tasks_per_interval"]) > 0
    two = {r["planner"]: float(r["throughput_tasks_per_interval"]) for r in rows
           if r["uavs"] == "2" and r["planner"] in ("claims", "independent")}
    assert all(v > 1.5 * float(one[0]["throughput_tasks_per_interval"]) for v in two.values())

    summary = json.loads((out / "fleet.json").read_text())
    assert summary["preset"] == "fleet" and summary["uavs"] == [1, 2] and summary["seeds"] == [0, 1]
    assert summary["planners"] == ["independent", "claims", "dec-mcts", "joint"] and summary["quick"]
    d = summary["against_independent"]["claims"]["N=1"]["throughput_tasks_per_interval"]
    assert d["mean"] == 0 and d["n"] == 2 and d["verdict"] == "within noise"
    assert summary["violations"] == {"double_services": 0, "double_holds": 0, "fairness_violations": 0}
    assert any("joint" in n for n in summary["notes"])
    assert all(len(summary["paths"][p]["paths"]) == 2 for p in planners)  # N = 2 (3 not flown): a path per UAV
    # 2 seeds x 2 fleet sizes x 4 planners, dec-mcts's 6 message links at N = 2, a paths sortie per planner
    assert summary["run"]["commit"] and summary["run"]["sorties"] == 2 * 2 * 4 + 6 * 2 + 4


@pytest.mark.parametrize("args, needle", [
    (("--uavs", "0,2"), "--uavs"),
    (("--uavs", "1,x"), "--uavs"),
    (("--episodes", "10"), "--episodes"),
    (("--iterations", "0"), "--iterations"),
])
def test_fleet_bad_arguments_are_refused(python, python_env, tmp_path, args, needle):
    proc = run(python, python_env, *args, "--out", str(tmp_path))
    assert proc.returncode == 2 and needle in proc.stderr


def test_fleet_options_are_refused_for_the_papers_figures(python, python_env, tmp_path):
    proc = subprocess.run([python, "-m", "planner_service", "experiment", "3d", "--uavs", "3", "--out", str(tmp_path)],
                          env=python_env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "--uavs" in proc.stderr and "fleet" in proc.stderr
