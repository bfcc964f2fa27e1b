"""Flight modes by the names ground stations show, from a HEARTBEAT's custom_mode."""

from __future__ import annotations

# ArduPilot Copter custom modes and PX4 (main, sub) modes.
ARDUPILOT_MODES = {0: "STABILIZE", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL",
                   9: "LAND", 16: "POSHOLD", 17: "BRAKE"}
PX4_MODES = {(1, 0): "MANUAL", (2, 0): "ALTCTL", (3, 0): "POSCTL", (4, 1): "AUTO.READY",
             (4, 2): "AUTO.TAKEOFF", (4, 3): "AUTO.LOITER", (4, 4): "AUTO.MISSION", (4, 5): "AUTO.RTL",
             (4, 6): "AUTO.LAND", (5, 0): "ACRO", (6, 0): "OFFBOARD", (7, 0): "STABILIZED"}
RETURNING_MODES = frozenset({"RTL", "LAND", "AUTO.RTL", "AUTO.LAND", "RETURN_TO_LAUNCH"})
MISSION_MODES = frozenset({"AUTO", "AUTO.MISSION", "MISSION"})
HOLDING_MODES = frozenset({"LOITER", "POSHOLD", "BRAKE", "AUTO.LOITER", "HOLD"})
"""Modes in which an airborne vehicle waits where it is (what a restarted autopilot does)."""


def mode_name(flavour: str, custom_mode: int) -> str:
    """The mode a HEARTBEAT's custom_mode names, as a ground station shows it."""
    if flavour == "px4":
        main, sub = (custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF
        return PX4_MODES.get((main, sub), PX4_MODES.get((main, 0), f"PX4 {main}/{sub}"))
    return ARDUPILOT_MODES.get(custom_mode, f"MODE {custom_mode}")


def mode_number(flavour: str, name: str) -> tuple[int, int]:
    """MAV_CMD_DO_SET_MODE's (custom main mode, custom sub mode) for ``name``."""
    if flavour == "px4":
        for (main, sub), known in PX4_MODES.items():
            if known == name:
                return main, sub
    else:
        for number, known in ARDUPILOT_MODES.items():
            if known == name:
                return number, 0
    raise ValueError(f"no {flavour} mode named {name!r}")
