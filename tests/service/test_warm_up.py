"""After the warm-up, the first real decision of each algorithm compiles nothing.

Each case runs in a fresh interpreter (compiled kernels live per process): it warms the
service's planner up, records how many compiled signatures every numba function of the
planner has, makes a first real decision with its path and its planning battery on a state
assembled as the service assembles it, and counts again. A cold run (no warm-up) shows the
check can fail."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from planner_service.model import HAVE_NUMBA
from planner_service.service.planning import FLIGHT_ALGOS

SCRIPT = r"""
import json, sys
from numba.core.registry import CPUDispatcher
from planner_service.mcts import MctsConfig
from planner_service.service.config import build_config
from planner_service.service.rows import RequestRow, ServiceRow, UserRow
from planner_service.service.planning import Planner, VehicleFix, assemble, planning_battery_j

def signatures():
    out = {}
    for name, module in list(sys.modules.items()):
        if name.startswith("planner_service.") and module is not None:
            for attr, obj in vars(module).items():
                if isinstance(obj, CPUDispatcher):
                    out[f"{name}.{attr}"] = len(obj.signatures)
    return out

algo, warm = sys.argv[1], sys.argv[2] == "warm"
scenario = build_config({}, {}).scenario()  # the scenario the service flies
planner = Planner(scenario, MctsConfig(iterations=None, budget_ms=60.0), 3, 8, algo)
if warm:
    planner.warm_up()
before = signatures()
users = [UserRow(user_id=f"u{i}", x_m=60.0 * i + 20.0, y_m=400.0 - 45.0 * i, z_m=0.0, services=int(i < 2))
         for i in range(7)]
pending = [RequestRow(request_id=10 + i, user_id=u.user_id, x_m=u.x_m + 3.0, y_m=u.y_m, z_m=0.0,
                      tasks=[17, 19, 6, 12, 9, 14, 11][i], client_ref=None, accepted_at_s=1.0, status="pending",
                      reason="") for i, u in enumerate(users)]
services = [ServiceRow(service_id=1 + i, request_id=1 + i, user_id=f"u{i}", tasks=10, bits=1e6, hover_index=3 + i,
                       x_m=0.0, y_m=0.0, z_m=100.0, reward=0.3, battery_j=90_000.0, time_s=1.0) for i in range(2)]
fix = VehicleFix(120.0, 80.0, 100.0, 80_000.0, True)
battery = planning_battery_j(scenario, fix.battery_j, 2.0, 1000.0)
assembled = assemble(scenario, users, pending, services, VehicleFix(fix.x_m, fix.y_m, fix.z_m, battery, True), 4)
decision, path = planner.decide(assembled)
grown = {k: v - before.get(k, 0) for k, v in signatures().items() if v != before.get(k, 0)}
print(json.dumps({"action": None if decision is None else decision.action, "points": len(path.points),
                  "grown": grown}))
"""


def first_decision(algo: str, warm: bool) -> dict:
    out = subprocess.run([sys.executable, "-c", SCRIPT, algo, "warm" if warm else "cold"], capture_output=True,
                         text=True, timeout=600, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not HAVE_NUMBA, reason="without numba nothing is compiled")
@pytest.mark.parametrize("algo", FLIGHT_ALGOS)
def test_first_decision_compiles_nothing_after_the_warm_up(algo: str) -> None:
    result = first_decision(algo, warm=True)
    assert result["action"] is not None and result["points"] >= 1
    assert result["grown"] == {}


@pytest.mark.skipif(not HAVE_NUMBA, reason="without numba nothing is compiled")
def test_without_the_warm_up_the_first_decision_compiles() -> None:
    result = first_decision("mcts", warm=False)
    assert result["action"] is not None
    assert any(name.startswith("planner_service.mcts.open_loop.search") for name in result["grown"])
