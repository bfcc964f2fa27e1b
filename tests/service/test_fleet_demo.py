"""``demo --uavs N`` end to end (two routers, a stub and a service per UAV, the users submitting
to the fleet), small and fast: its summary is read from each UAV's own journal and holds the
fleet's rules, and the live map it prints shows the UAVs; and the options that fly one UAV are refused with --uavs."""

from __future__ import annotations

import http.cookiejar
import json
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

from planner_service.harness.fleet_demo import run_fleet_demo
from planner_service.harness.processes import REPO


class LivePage:
    """The demo's output; once it printed the live map's address, the vehicles the map shows
    (logged in with the printed token) while the sortie goes on."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.url: str | None = None
        self.seen: set[str] = set()
        self.opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))

    def echo(self, line: str) -> None:
        print(line)
        self.lines.append(line)
        if line.startswith("live map: http://127.0.0.1:"):
            self.url = line.split()[2]
            self.opener.open(self.url, timeout=5).read()  # the login: a session cookie
        elif self.url is not None and line.startswith("["):  # the sortie's progress
            with self.opener.open(self.url.split("login?")[0] + "api/picture", timeout=5) as answer:
                self.seen |= {v["id"] for v in json.load(answer)["vehicles"] if v["x_m"] is not None}


@pytest.mark.timeout(240)
def test_a_fleet_of_two_flies_one_sortie_and_sums_it_up(tmp_path: Path) -> None:
    page = LivePage()
    summary = run_fleet_demo(tmp_path, uavs=2, users=6, speedup=40.0, budget_ms=50.0, seed=2, echo=page.echo)
    assert page.seen >= {"uav1", "uav2"}, f"the live map the demo printed showed {page.seen}: {page.lines}"
    fleet, per_uav = summary["fleet"], summary["per_uav"]
    assert set(per_uav) == {"uav1", "uav2"}
    assert fleet["intervals"] == sum(s["intervals"] for s in per_uav.values()) > 0
    assert fleet["fairness_violations"] == 0 and fleet["energy_violations"] == 0
    # every request held by every member: each journal accepted every user's
    assert all(s["requests"]["accepted"] >= 6 for s in per_uav.values()), fleet["requests_accepted"]
    flew = [v for v, s in per_uav.items() if s["intervals"]]
    assert all(summary["traffic_bytes_per_s"][v]["fleet_keys"] > 0 for v in flew)
    assert summary["offline"]["throughput_tasks_per_interval"] > 0 and summary["flown_to_offline"] > 0
    assert (tmp_path / "paths.png").stat().st_size > 0 and (tmp_path / "summary.json").exists()
    print(f"flown / offline {summary['flown_to_offline']:.2f}, by two UAVs {fleet['users_served_by_two_uavs']}")


def test_options_of_one_uav_are_refused_with_uavs(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-m", "planner_service", "demo", "--uavs", "3", "--mavlink",
                           "tcp:127.0.0.1:5760", "--out", str(tmp_path)], cwd=REPO, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2
    assert "error: --mavlink fly one UAV; --uavs 3 flies the stubs with the defaults" in done.stderr
