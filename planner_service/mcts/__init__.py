"""Monte Carlo Tree Search planners (Algorithm 1, TS-MCTS, the sound online planner)."""

from .planner import MctsConfig, MctsPlanner
from .paper import PaperMctsPlanner
from .policies import PlannerPolicy, paper_mcts, sound_mcts, timesaving_mcts
from .tree import NO_PARENT, ROOT_INDEX, UNVISITED, Tree
from .warm import warm_up

PLANNERS = {"mcts": sound_mcts, "mcts-paper": paper_mcts, "ts-mcts": timesaving_mcts}

__all__ = ["MctsConfig", "MctsPlanner", "PaperMctsPlanner", "NO_PARENT", "PLANNERS", "PlannerPolicy", "ROOT_INDEX", "Tree",
           "UNVISITED", "warm_up"]
