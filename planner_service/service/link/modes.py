"""Flight modes by the names ground stations show, from a HEARTBEAT's custom_mode (the
tables are each autopilot's profile, ``protocol.autopilot``)."""

from __future__ import annotations

from protocol.autopilot import Autopilot, autopilot_for
RETURNING_MODES = frozenset({"RTL", "LAND", "AUTO.RTL", "AUTO.LAND", "RETURN_TO_LAUNCH"})
MISSION_MODES = frozenset({"AUTO", "AUTO.MISSION", "MISSION"})
HOLDING_MODES = frozenset({"LOITER", "POSHOLD", "BRAKE", "AUTO.LOITER", "HOLD"})
"""Modes in which an airborne vehicle waits where it is (what a restarted autopilot does)."""


def mode_name(autopilot: str | Autopilot, custom_mode: int) -> str:
    """The mode a HEARTBEAT's custom_mode names, as a ground station shows it."""
    return autopilot_for(autopilot).mode_name(custom_mode)


def mode_number(autopilot: str | Autopilot, name: str) -> tuple[int, int]:
    """MAV_CMD_DO_SET_MODE's (custom main mode, custom sub mode) for ``name``."""
    return autopilot_for(autopilot).mode_number(name)
