"""The holds of the mission held: the one watched, the request bound to it, the points
already judged, the hold the service ended early. Pure.

Its fields change together: a hold judged clears the watch and the binding and adds its
seq to ``judged`` in one step."""

from __future__ import annotations

from dataclasses import dataclass

from .hold import HoldWatch


@dataclass(frozen=True)
class Binding:
    """The request a hold serves, bound when the vehicle arrives at the point."""

    seq: int
    user_id: str
    request_id: int | None
    """None: nothing to serve there (``why_not``)."""
    tasks: int = 0
    needed_s: float = 0.0
    """The hold the bound tasks need from this point (upload time)."""
    planned: bool = False
    """The request bound is the one the plan was made for."""
    why_not: str = ""
    done: bool = False
    """The user said its upload is done (a newer request with no tasks)."""


@dataclass(frozen=True)
class Holds:
    """The watch over the point flown and what was judged of the points before it."""

    watch: HoldWatch | None = None
    binding: Binding | None = None
    judged: frozenset[int] = frozenset()
    """Seqs of the mission held's points already judged (served or not)."""
    early_end: int | None = None
    """The seq whose hold the service ended early."""
