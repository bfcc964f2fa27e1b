"""What the service knows of the mission on board the vehicle: the one it holds, whether
that is known or in doubt, an upload whose outcome is unknown, and the reports kept until
the doubt is resolved. Pure.

Its fields change together: an upload accepted, a read-back or a doubt sets ``held``,
``known``, ``unconfirmed`` and ``doubt`` in one step."""

from __future__ import annotations

from dataclasses import dataclass

from .hold import Sample
from .mission import HeldMission


@dataclass(frozen=True)
class OnBoard:
    """The mission on board, as far as the service knows."""

    held: HeldMission | None = None
    known: bool = False
    """The vehicle is known to hold ``held`` (an upload accepted, a read-back); False while
    in doubt or before it is known."""
    unconfirmed: HeldMission | None = None
    """An upload whose outcome is unknown: the vehicle may hold it."""
    doubt: str | None = None
    """Why the vehicle may hold another mission than ``held``: read it back first."""
    must_upload: bool = False
    """The vehicle lost its mission in the air: upload whatever the plan."""
    resume_pending: bool = False
    """A mission re-planned in the air is to be resumed (or the operator told it waits)."""
    restarted: bool = False
    """The vehicle restarted since the last read-back: the holds it flew were cut."""
    doubted: tuple[Sample, ...] = ()
    """The vehicle's reports while in doubt or an upload is in flight (``_replay``), at most
    ``MAX_DOUBTED``."""
