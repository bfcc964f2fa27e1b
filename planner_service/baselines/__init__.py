"""Baselines the paper's MCTS is compared with: greedy, random, Q-learning and DQN."""

from .dqn import DQNConfig, DQNPolicy, dqn
from .qlearning import QLearningConfig, QLearningPolicy, q_learning
from .simple import GreedyPolicy, RandomPolicy, greedy, uniform_random

BASELINES = {"greedy": greedy, "random": uniform_random, "ql": q_learning, "dqn": dqn}

__all__ = [
    "BASELINES", "DQNConfig", "DQNPolicy", "GreedyPolicy", "QLearningConfig", "QLearningPolicy", "RandomPolicy",
]
