"""Monte Carlo Tree Search planners (Algorithm 1, TS-MCTS, the sound online planner)."""

PLANNERS: dict = {}

__all__ = ["PLANNERS"]
