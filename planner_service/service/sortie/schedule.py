"""The sortie's schedule: what the service has in flight (a plan, an upload, a read-back, a
command), when the next may go, and what the decisions are counted by. Pure.

Its fields change together: a plan or an upload sent, returned or failed moves ``busy``,
``failures`` and ``retry_at`` in one step, whatever the mission on board."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

Busy = Literal["", "plan", "upload", "readback"]


@dataclass(frozen=True)
class Schedule:
    """What is in flight and when the next plan, read-back or command may go."""

    plan_id: int = 0
    """The last plan id given (a plan uploaded, or refused before its upload)."""
    version: int = 0
    """Bumped when a plan being searched is stale (doubt, restart, sortie over)."""
    busy: Busy = ""
    commanding: str = ""
    """The command sent and not yet answered ('' for none)."""
    failures: int = 0
    retry_at: float = 0.0
    readback_at: float = 0.0
    """The next read-back, apart from ``retry_at``: a doubt is resolved at once, whatever
    the plans' back-off (holds flown meanwhile are not judged), and only a failed read-back
    waits."""
    dirty: bool = True
    """Requests came in since the last plan."""
    last_plan_at: float = -math.inf
    decided_at: int | None = None
    """The seq from whose hold the last decision was made (one decision per interval)."""
    last_hover_index: int = -1
    """The hover point the vehicle last arrived at (where the way home's decisions start)."""
