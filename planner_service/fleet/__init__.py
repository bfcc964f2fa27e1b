"""A fleet's planners and its simulated sortie: N UAVs, each planned by a single-UAV planner
on a view of its own (``FleetEnv.view``), coordinated or not by what the others intend.

Built: ``independent`` (the baseline: each UAV blind to the others), ``claims`` (each
UAV leaves out what the others have committed to), ``dec-mcts`` (each UAV samples the
others' published distributions over their plans in its futures: ``dec_mcts.py``, its
messages ``messages.py``) and ``joint`` (one search over the whole fleet's plan, the
reference where K^N is small: ``joint.py``).
"""

from .dec_mcts import DecMctsConfig, DecMctsFleet
from .joint import MAX_JOINT_ACTIONS, JointFleet, joint_fits
from .messages import MessageError, PlanMessage, decode
from .policies import (FLEET_PLANNERS, LATER, MESSAGE_PLANNERS, ClaimsFleet, IndependentFleet, MessageLink,
                       fleet_algorithms, make_fleet_policy, takes_link)
from .sortie import fleet_streams, message_figures, run_fleet_sortie

__all__ = ["FLEET_PLANNERS", "LATER", "MAX_JOINT_ACTIONS", "MESSAGE_PLANNERS", "ClaimsFleet", "DecMctsConfig",
           "DecMctsFleet", "IndependentFleet", "JointFleet", "MessageError", "MessageLink", "PlanMessage", "decode",
           "fleet_algorithms", "fleet_streams", "joint_fits", "make_fleet_policy", "message_figures",
           "run_fleet_sortie", "takes_link"]
