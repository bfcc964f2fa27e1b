"""The paper's system model: pure, seeded, shared by planners, learners and the stub."""

from ._jit import HAVE_NUMBA
from .env import Snapshot, SortieEnv
from .errors import ScenarioError
from .interval import AT_BASE, NO_USER, evaluate_actions, service_outcome
from .layouts import base_position, hover_points, user_rows
from .params import pack
from .presets import PRESETS, field, paper, paper_3d, preset
from .scenario import Scenario
from .state import SortieState

__all__ = [
    "AT_BASE", "HAVE_NUMBA", "NO_USER", "PRESETS", "Scenario", "ScenarioError", "Snapshot",
    "SortieEnv", "SortieState", "base_position", "evaluate_actions", "field", "hover_points",
    "pack", "paper", "paper_3d", "preset", "service_outcome", "user_rows",
]
