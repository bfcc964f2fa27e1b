"""Baselines the paper's MCTS is compared with: greedy, random (and Q-learning, DQN)."""

from .simple import GreedyPolicy, RandomPolicy, greedy, uniform_random

BASELINES = {"greedy": greedy, "random": uniform_random}

__all__ = ["BASELINES", "GreedyPolicy", "RandomPolicy"]
