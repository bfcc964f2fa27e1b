"""A fleet's planners and its simulated sortie: N UAVs, each planned by a single-UAV planner
on a view of its own (``FleetEnv.view``), coordinated or not by what the others intend.

Built: ``independent`` (the baseline: each UAV blind to the others) and ``claims`` (each
UAV leaves out what the others have committed to). Not built yet, and refused by name
until they are: ``dec-mcts`` (each UAV samples the others' published distributions over
their plans in its playouts) and ``joint`` (one search over the joint action, the reference
where it is tractable): issue 26's second half; ``LATER`` names them.
"""

from .policies import (FLEET_PLANNERS, LATER, ClaimsFleet, IndependentFleet, MessageLink, fleet_algorithms,
                       make_fleet_policy, takes_link)
from .sortie import fleet_streams, message_figures, run_fleet_sortie

__all__ = ["FLEET_PLANNERS", "LATER", "ClaimsFleet", "IndependentFleet", "MessageLink", "fleet_algorithms",
           "fleet_streams", "make_fleet_policy", "message_figures", "run_fleet_sortie", "takes_link"]
