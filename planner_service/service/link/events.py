"""What a link reports, one frozen dataclass per event (``LinkEvent`` is their union), so a
consumer dispatches with ``match`` and a typo is a type error, not a silent no-op.

``mission`` on ``Reached`` and ``Current`` says which mission the report is about: the
link's ``generation`` when the vehicle sent it. The generation grows when an upload is
accepted, when a download shows what the vehicle holds and when the vehicle restarts, so a
report sent before one of those (delayed or reordered on the link) is never read against
the mission that followed.

Text from the wire (STATUSTEXT, mode names of unknown modes) is escaped of control
characters before it goes into an event (``protocol.text.printable``): it reaches logs and
terminals.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Union

MAX_TEXT = 256
"""Longest text kept from the wire (STATUSTEXT carries 50 characters a chunk)."""


@dataclass(frozen=True)
class Connected:
    """The autopilot's first heartbeat: ``mode`` it is in, ``system``/``component`` it
    speaks from (only these count from now on)."""

    mode: str
    system: int
    component: int


@dataclass(frozen=True)
class Lost:
    """Nothing heard from the autopilot for ``link_timeout_s`` (or the connection broke)."""

    detail: str


@dataclass(frozen=True)
class Restored:
    """The autopilot is heard again after ``Lost``; ``mode`` it is in."""

    mode: str


@dataclass(frozen=True)
class Restarted:
    """The autopilot rebooted (its clock went back, in reports over half a second): its mission and home are
    stale until read back; telemetry rates were requested again."""

    detail: str


@dataclass(frozen=True)
class Reached:
    """Mission item ``seq`` was completed (MISSION_ITEM_REACHED, or the current item moving
    past it); ``mission``: the generation it is about."""

    seq: int
    mission: int


@dataclass(frozen=True)
class Current:
    """The vehicle flies item ``seq`` (-1: the report names none) of ``total`` (0: it holds
    no mission, -1: it does not say); ``mission``: the generation it is about."""

    seq: int
    total: int
    mission: int


@dataclass(frozen=True)
class ModeChanged:
    """The autopilot is now in ``mode``; ``commanded``: this link asked for that mode in the
    last few seconds (False: a pilot, a failsafe or another ground station changed it)."""

    mode: str
    commanded: bool


@dataclass(frozen=True)
class ArmedChanged:
    """The autopilot is now ``armed`` (or disarmed); ``commanded``: this link asked for it in
    the last few seconds (False: a pilot, the ground crew, a failsafe, the autopilot's own
    disarming after a landing, another ground station)."""

    armed: bool
    commanded: bool


@dataclass(frozen=True)
class OnGround:
    """The vehicle was airborne and is now on the ground (``source``: EXTENDED_SYS_STATE or
    how it was derived)."""

    source: str


@dataclass(frozen=True)
class StatusText:
    """A STATUSTEXT from the autopilot, ``text`` escaped; ``severity`` as MAV_SEVERITY
    (0 emergency .. 7 debug)."""

    text: str
    severity: int


@dataclass(frozen=True)
class TelemetryMissing:
    """Messages the link asked for and does not receive (empty: all arrive again)."""

    missing: tuple[str, ...]


@dataclass(frozen=True)
class PositionChanged:
    """The autopilot has a position now (``ok``) or lost it; ``waiting_for`` says what is
    missing when not."""

    ok: bool
    waiting_for: str


LinkEvent = Union[Connected, Lost, Restored, Restarted, Reached, Current, ModeChanged, ArmedChanged, OnGround,
                  StatusText, TelemetryMissing, PositionChanged]
"""Every event a link reports."""
