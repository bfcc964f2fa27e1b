"""What the link asked the autopilot for (a mode, an arming), to tell the heartbeat that
shows it from somebody else's doing.

A change shown while the command is in flight, or within ``COMMANDED_WINDOW_S`` wall
seconds of its answer, was commanded by us. The window counts from the answer, not from
the asking: on a loaded machine MAVSDK sent a service's arming (through its executor) more
than five seconds after it was asked for, and the arming was taken as somebody else's (the
authority revoked at the service's own start). A refusal ends the expectation at once (the
autopilot did not do it, so a change that follows is somebody else's); a command that got
no answer may have been carried out, so its window stays."""
from __future__ import annotations

import math
from typing import Generic, TypeVar

COMMANDED_WINDOW_S = 5.0
"""A mode (an arming, a disarming) reported within this many wall seconds of the answer to
our asking for it was commanded by us."""

T = TypeVar("T")


class Asked(Generic[T]):
    """One kind of change asked for (a mode, an arming): the value last asked and until when
    a change to it counts as ours."""

    def __init__(self) -> None:
        self._value: T | None = None
        self._until = -math.inf

    def ask(self, value: T) -> None:
        """The command for ``value`` is being sent: until it is answered a change to it is ours."""
        self._value, self._until = value, math.inf

    def answered(self, now: float, *, refused: bool) -> None:
        self._until = -math.inf if refused else now + COMMANDED_WINDOW_S

    def shows(self, value: T, now: float) -> bool:
        """Is ``value``, reported now, what we asked for?"""
        return self._value == value and now <= self._until
