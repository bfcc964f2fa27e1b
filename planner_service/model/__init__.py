"""The paper's system model: pure, seeded, shared by planners, learners and the stub."""

from ._jit import HAVE_NUMBA
from .env import Snapshot, SortieEnv
from .errors import ScenarioError
from .interval import AT_BASE, NO_USER, evaluate_actions, service_outcome
from .layouts import base_position, hover_points, user_rows
from .params import pack
from .presets import PRESETS, field, fleet, paper, paper_3d, preset
from .scenario import Scenario
from .state import SortieState
from .world import NO_MOVES, NO_NEWS, Outcome, Scene, World, draw_chance, scene_of, step

__all__ = [
    "AT_BASE", "HAVE_NUMBA", "NO_MOVES", "NO_NEWS", "NO_USER", "Outcome", "PRESETS", "Scenario", "ScenarioError",
    "Scene", "Snapshot", "SortieEnv", "SortieState", "World", "base_position", "draw_chance", "evaluate_actions",
    "field", "fleet", "hover_points", "pack", "paper", "paper_3d", "preset", "scene_of", "service_outcome", "step",
    "user_rows",
]
