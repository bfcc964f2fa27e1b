"""The demo's world planned offline: the scenario the demo's service flies, as the model
plans it (``run_sortie``, no I/O), so that a flown sortie can be compared with the same one
planned (the demo's summary, ``bench --flight``)."""

from __future__ import annotations

import contextlib
import io
from typing import Any, Callable

from ..policy import PolicySpec
from ..service.config import build_config
from ..sortie import run_sortie

USERS_ARRIVAL_PERIOD_S = 55.0
"""``sim_bridge users``' default ``--interval``: a draw of the model's arrivals every so many
simulated seconds (the service's process boundary: not imported from it; a test checks)."""


def offline_scenario(users: int) -> Any:
    """The scenario the demo's service flies, as the model plans it offline."""
    return build_config({}, {}).scenario().replace(num_users=users, task_model="backlog")


def plan_offline(algo: str, seed: int, users: int, budget_ms: float, echo: Callable[[str], None],
                 scenario: Any = None, timed: bool = False, iterations: int | None = None) -> dict[str, Any]:
    """The sortie planned offline on ``scenario`` (default: the demo's, ``offline_scenario``);
    ``timed``: in the world whose tasks arrive as the users draw them (``bench --flight``'s
    ``timed``), not by the scenario's law. MCTS decides
    on ``budget_ms``, as in flight, or on ``iterations`` (the same decisions every run)."""
    scenario = offline_scenario(users) if scenario is None else scenario.replace(num_users=users)
    options = {"arrivals_every_s": USERS_ARRIVAL_PERIOD_S} if timed else None
    spec = PolicySpec(iterations=None, budget_ms=budget_ms) if iterations is None else PolicySpec(iterations)
    with contextlib.redirect_stdout(io.StringIO()):
        summary = run_sortie(scenario, algo, seed, spec, options)
    echo(f"  {'timed' if timed else 'offline':7s} {algo:7s} seed {seed}: {summary['intervals']} intervals, "
         f"{summary['throughput_tasks_per_interval']:.1f} tasks/interval, reward {summary['average_reward']:.3f}")
    return summary


__all__ = ["USERS_ARRIVAL_PERIOD_S", "offline_scenario", "plan_offline"]
