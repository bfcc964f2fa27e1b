"""What a search backs up into a node: the objective of ``mcts`` (and Algorithm 1's R).

``mcts`` maximises the **sortie's average reward**, the number the project reports:

    J = (sum of q over the intervals already flown + sum of q over this iteration's steps)
        / (intervals already flown + this iteration's steps)

with q the reward (11) of each interval. Every node on the iteration's path gets the same
J (``RETURN_SORTIE``, the default). The steps before a node are the same actions for all
its siblings, so J ranks siblings as the return from their own step onward would, and the
sortie's length (which the battery decides) is part of what is optimised: an interval that
earns less than the average so far lowers J.

Two other returns are kept for comparison (``MctsConfig.return_kind``): ``RETURN_MEAN``,
the mean of q from the node's own step to the end of the iteration (the paper's R, which
``mcts-paper`` and ``ts-mcts`` back up from the newly expanded node), and ``RETURN_SUM``,
their sum. docs/PLANNER.md has what each costs.
"""

from __future__ import annotations

from ..model._jit import jit_borrow

RETURN_MEAN = 0
"""A node's return: the mean of q from its own step to the end (the paper's R)."""
RETURN_SUM = 1
"""A node's return: the sum of q from its own step to the end."""
RETURN_SORTIE = 2
"""Every node's return: the whole sortie's average q, the past intervals included (the
reported average reward): the objective of ``mcts``."""


@jit_borrow
def node_return(
    kind: int, own_sum: float, own_steps: int, whole_sum: float, whole_steps: int, past_sum: float, past_count: int
) -> float:
    """What a node backs up: ``own_*`` are the sum and count of q from the node's own step
    to the end of the iteration, ``whole_*`` those of every step of the iteration, and
    ``past_*`` those of the intervals flown before the search's root."""
    if kind == RETURN_SUM:
        return own_sum
    if kind == RETURN_SORTIE:
        count = past_count + whole_steps
        return (past_sum + whole_sum) / count if count > 0 else 0.0
    return own_sum / own_steps if own_steps > 0 else 0.0


__all__ = ["RETURN_MEAN", "RETURN_SORTIE", "RETURN_SUM", "node_return"]
