"""N UAVs over shared users: the fleet's parameters, state, joint rules and environment.

Every UAV steps the single-UAV model's own kernels (``model.world``, ``model.interval``)
with its own parameter vector (its speed, battery, base and altitude layer) and its own
hovering points (its layer); the users, their tasks and their service counts are shared.
``docs/MODEL.md``, "A fleet", has the rules.
"""

from .env import FleetEnv, FleetSnapshot
from .rules import FleetError, check_joint
from .setup import Fleet, uav_scenarios
from .state import FleetState

__all__ = ["Fleet", "FleetEnv", "FleetError", "FleetSnapshot", "FleetState", "check_joint", "uav_scenarios"]
