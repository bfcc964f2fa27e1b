"""The search tree as preallocated arrays indexed by node id.

After mctx's ``Tree``: one row per node, the children of node n in ``children[n, a]``
(``UNVISITED`` where action a has no child yet), so the compiled search touches only flat
arrays. Node 0 is the root. Shapes: N = capacity, K = number of actions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

ROOT_INDEX = 0
NO_PARENT = -1
UNVISITED = -1


class TreeArrays(NamedTuple):
    """A ``Tree``'s arrays as one record for the compiled search (same shapes)."""

    parent: np.ndarray
    action: np.ndarray
    children: np.ndarray
    visits: np.ndarray
    value_sum: np.ndarray


@dataclass
class Tree:
    """Statistics of a search tree; arrays grow by doubling when full.

    ``parent`` (N,) int64, ``action`` (N,) int64 (the action that led to the node),
    ``children`` (N, K) int64, ``visits`` (N,) float64 (float so old statistics can be
    decayed on reuse), ``value_sum`` (N,) float64 (sum of returns backed up into the node).
    """

    parent: np.ndarray
    action: np.ndarray
    children: np.ndarray
    visits: np.ndarray
    value_sum: np.ndarray
    num_nodes: int

    @classmethod
    def empty(cls, num_actions: int, capacity: int) -> "Tree":
        capacity = max(capacity, 1)
        tree = cls(
            parent=np.full(capacity, NO_PARENT, dtype=np.int64),
            action=np.full(capacity, -1, dtype=np.int64),
            children=np.full((capacity, num_actions), UNVISITED, dtype=np.int64),
            visits=np.zeros(capacity),
            value_sum=np.zeros(capacity),
            num_nodes=1,
        )
        return tree

    def arrays(self) -> TreeArrays:
        """The arrays as the compiled search takes them."""
        return TreeArrays(self.parent, self.action, self.children, self.visits, self.value_sum)

    @property
    def capacity(self) -> int:
        return len(self.parent)

    @property
    def num_actions(self) -> int:
        return self.children.shape[1]

    def reserve(self, extra: int) -> None:
        """Make room for ``extra`` more nodes."""
        need = self.num_nodes + extra
        if need <= self.capacity:
            return
        size = max(need, 2 * self.capacity)
        grow = size - self.capacity
        self.parent = np.concatenate([self.parent, np.full(grow, NO_PARENT, dtype=np.int64)])
        self.action = np.concatenate([self.action, np.full(grow, -1, dtype=np.int64)])
        self.children = np.vstack(
            [self.children, np.full((grow, self.num_actions), UNVISITED, dtype=np.int64)]
        )
        self.visits = np.concatenate([self.visits, np.zeros(grow)])
        self.value_sum = np.concatenate([self.value_sum, np.zeros(grow)])

    def mean_value(self, node: int) -> float:
        n = self.visits[node]
        return float(self.value_sum[node] / n) if n > 0 else 0.0

    def best_child(self, node: int, allowed: np.ndarray | None = None) -> int:
        """The most visited child (ties: the higher mean); ``UNVISITED`` if none.

        ``allowed`` (K,) bool restricts the choice to actions possible now."""
        kids = self.children[node]
        best, best_key = UNVISITED, (-1.0, -np.inf)
        for a in range(self.num_actions):
            child = kids[a]
            if child == UNVISITED or (allowed is not None and not allowed[a]):
                continue
            key = (self.visits[child], self.mean_value(child))
            if key > best_key:
                best, best_key = int(child), key
        return best

    def principal_line(self, node: int = ROOT_INDEX, max_depth: int = 64) -> list[int]:
        """Actions along the most visited children from ``node`` down."""
        line: list[int] = []
        while len(line) < max_depth:
            child = self.best_child(node)
            if child == UNVISITED or self.visits[child] <= 0:
                break
            line.append(int(self.action[child]))
            node = child
        return line

    def lines_below(self, action: int, k: int, depth: int) -> tuple[list[list[int]], np.ndarray, float]:
        """What the root's child for ``action`` expects next: its k most visited children
        (ties: the higher mean), each with the principal line below it, cut to ``depth``
        actions; their mean values (k,); and the child's visits. Empty if it was never tried."""
        child = self.children[ROOT_INDEX, action]
        if child == UNVISITED:
            return [], np.zeros(0), 0.0
        kids = [int(c) for c in self.children[child] if c != UNVISITED and self.visits[c] > 0]
        kids = sorted(kids, key=lambda c: (-self.visits[c], -self.mean_value(c)))[:k]
        lines = [[int(self.action[c]), *self.principal_line(c, depth - 1)] for c in kids]
        return lines, np.array([self.mean_value(c) for c in kids]), float(self.visits[child])

    def subtree(self, new_root: int, decay: float = 1.0) -> "Tree":
        """A compact copy of the subtree under ``new_root``, which becomes node 0.

        Statistics are multiplied by ``decay`` (1 keeps them, 0 forgets them)."""
        order = [new_root]
        frontier = np.array([new_root])
        while len(frontier):
            kids = self.children[frontier].ravel()
            frontier = kids[kids != UNVISITED]
            order.extend(frontier.tolist())
        old = np.array(order, dtype=np.int64)
        remap = np.full(self.capacity, UNVISITED, dtype=np.int64)
        remap[old] = np.arange(len(old))
        kids = self.children[old]
        children = np.where(kids == UNVISITED, UNVISITED, remap[np.maximum(kids, 0)])
        parent = np.where(self.parent[old] == NO_PARENT, NO_PARENT, remap[np.maximum(self.parent[old], 0)])
        parent[0] = NO_PARENT
        action = self.action[old].copy()
        action[0] = -1
        return Tree(
            parent=parent,
            action=action,
            children=children,
            visits=self.visits[old] * decay,
            value_sum=self.value_sum[old] * decay,
            num_nodes=len(old),
        )
