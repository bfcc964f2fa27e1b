"""``python -m planner_service export``: a mission from the journal or a plan summary as a WPL
file or a QGroundControl .plan, run as a user runs it."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from planner_service.service.journal import Journal
from planner_service.service.sortie import item_dict
from protocol import GeoOrigin, HoverPoint, encode_path, read_plan, read_wpl, same_items

ORIGIN = GeoOrigin()


def export(python: str, env: dict[str, str], *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([python, "-m", "planner_service", "export", *args], env=env, capture_output=True,
                          text=True, timeout=120)


def journal_with_missions(path: Path) -> list:
    journal = Journal(path, now_s=0.0)
    first = encode_path([HoverPoint(10.0, 20.0, 30.0, 5.0)], ORIGIN)
    second = encode_path([HoverPoint(40.0, 50.0, 60.0, 7.0), HoverPoint(70.0, 80.0, 60.0, 0.0)], ORIGIN)
    journal.record_mission(1, [item_dict(i) for i in first], [], "accepted", 1.0)
    journal.record_mission(2, [item_dict(i) for i in second], [], "refused: NO_SPACE", 2.0)
    journal.record_mission(2, [item_dict(i) for i in second], [], "accepted", 3.0)
    journal.record_mission(3, [item_dict(i) for i in first], [], "refused: DENIED", 4.0)
    journal.close()
    return [first, second]


def test_export_from_the_journal(python, python_env, tmp_path: Path) -> None:
    db = tmp_path / "journal.sqlite"
    first, second = journal_with_missions(db)
    before = db.read_bytes()
    out = tmp_path / "m.waypoints"
    done = export(python, python_env, "--journal", str(db), "--plan-id", "2", "--out", str(out))
    assert done.returncode == 0, done.stderr
    items, home = read_wpl(out.read_text(), "ardupilot")
    assert same_items(items, second) and home == ORIGIN
    lines = out.read_text().splitlines()[1:]
    assert [line.split("\t")[1] for line in lines].count("1") == 1
    # Default: the last accepted mission; as a .plan.
    plan = tmp_path / "m.plan"
    assert export(python, python_env, "--journal", str(db), "--format", "plan", "--out", str(plan)).returncode == 0
    assert same_items(read_plan(plan.read_text(), "ardupilot")[0], second)
    assert db.read_bytes() == before, "the journal is only read"
    missing = export(python, python_env, "--journal", str(db), "--plan-id", "9", "--out", str(out))
    assert missing.returncode == 2 and "no mission with plan id 9" in missing.stderr
    nothing = export(python, python_env, "--journal", str(tmp_path / "nope.sqlite"), "--out", str(out))
    assert nothing.returncode == 2 and "does not exist" in nothing.stderr


def test_export_from_a_plan_summary(python, python_env, tmp_path: Path) -> None:
    summary = subprocess.run([python, "-m", "planner_service", "plan", "--preset", "field", "--algo", "greedy",
                              "--seed", "3", "--json"], env=python_env, capture_output=True, text=True, timeout=120,
                             check=True).stdout
    src = tmp_path / "summary.json"
    src.write_text(summary)
    out = tmp_path / "m.plan"
    done = export(python, python_env, "--plan-json", str(src), "--format", "plan", "--flavour", "px4",
                  "--out", str(out))
    assert done.returncode == 0, done.stderr
    items, _ = read_plan(out.read_text(), "px4")
    trace = json.loads(summary)["trace"]
    waypoints = [i for i in items if i.command == 16]
    assert len(waypoints) == len(trace) and items[-1].command == 20
    assert all(w.param1 >= 0 for w in waypoints) and any(w.param1 > 0 for w in waypoints)
    bad = export(python, python_env, "--plan-json", str(tmp_path / "missing.json"), "--out", "-")
    assert bad.returncode == 2 and "export:" in bad.stderr
