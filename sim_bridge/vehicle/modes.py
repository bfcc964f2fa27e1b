"""Flight modes and their numbers on the wire, per autopilot flavour.

ArduPilot Copter sends its mode number in HEARTBEAT.custom_mode. PX4 packs a main mode
and a sub mode: ``custom_mode = main << 16 | sub << 24`` (px4_custom_mode.h), and
DO_SET_MODE carries them in param2 and param3.
"""

from __future__ import annotations

import enum

from pymavlink.dialects.v20 import common as mavlink


class Mode(enum.Enum):
    """What the simulated aircraft does; each flavour names these its own way."""

    MANUAL = "MANUAL"
    """On the ground: nothing; in the air: hold position (no pilot is simulated)."""
    HOLD = "HOLD"
    """Loiter at the current position."""
    GUIDED = "GUIDED"
    """Accepts takeoff commands; otherwise holds."""
    TAKEOFF = "TAKEOFF"
    """Climb to the takeoff altitude, then hold (PX4 AUTO.TAKEOFF)."""
    AUTO = "AUTO"
    """Fly the mission."""
    RTL = "RTL"
    """Return to launch and land."""
    LAND = "LAND"
    """Land where it is."""


# ArduPilot Copter mode numbers (ArduCopter/mode.h).
ARDUPILOT_MODES: dict[int, Mode] = {
    0: Mode.MANUAL,  # STABILIZE
    2: Mode.MANUAL,  # ALT_HOLD
    3: Mode.AUTO,
    4: Mode.GUIDED,
    5: Mode.HOLD,  # LOITER
    6: Mode.RTL,
    9: Mode.LAND,
    16: Mode.HOLD,  # POSHOLD
    17: Mode.HOLD,  # BRAKE
}
ARDUPILOT_NAMES: dict[int, str] = {
    0: "STABILIZE", 2: "ALT_HOLD", 3: "AUTO", 4: "GUIDED", 5: "LOITER", 6: "RTL", 9: "LAND", 16: "POSHOLD",
    17: "BRAKE",
}
"""Copter's mode names (Mode::name()), as its STATUSTEXTs spell them."""
ARDUPILOT_NUMBERS: dict[Mode, int] = {
    Mode.MANUAL: 0, Mode.HOLD: 5, Mode.GUIDED: 4, Mode.TAKEOFF: 4, Mode.AUTO: 3,
    Mode.RTL: 6, Mode.LAND: 9,
}

# PX4 main modes and AUTO sub modes (px4_custom_mode.h).
PX4_MAIN_MANUAL, PX4_MAIN_ALTCTL, PX4_MAIN_POSCTL, PX4_MAIN_AUTO = 1, 2, 3, 4
PX4_MAIN_ACRO, PX4_MAIN_OFFBOARD, PX4_MAIN_STABILIZED = 5, 6, 7
PX4_AUTO_READY, PX4_AUTO_TAKEOFF, PX4_AUTO_LOITER, PX4_AUTO_MISSION = 1, 2, 3, 4
PX4_AUTO_RTL, PX4_AUTO_LAND = 5, 6

PX4_MODES: dict[tuple[int, int], Mode] = {
    (PX4_MAIN_AUTO, PX4_AUTO_READY): Mode.HOLD,
    (PX4_MAIN_AUTO, PX4_AUTO_TAKEOFF): Mode.TAKEOFF,
    (PX4_MAIN_AUTO, PX4_AUTO_LOITER): Mode.HOLD,
    (PX4_MAIN_AUTO, PX4_AUTO_MISSION): Mode.AUTO,
    (PX4_MAIN_AUTO, PX4_AUTO_RTL): Mode.RTL,
    (PX4_MAIN_AUTO, PX4_AUTO_LAND): Mode.LAND,
    (PX4_MAIN_OFFBOARD, 0): Mode.GUIDED,
}
PX4_MAIN_ONLY: dict[int, Mode] = {
    PX4_MAIN_MANUAL: Mode.MANUAL, PX4_MAIN_ALTCTL: Mode.MANUAL, PX4_MAIN_POSCTL: Mode.MANUAL,
    PX4_MAIN_ACRO: Mode.MANUAL, PX4_MAIN_STABILIZED: Mode.MANUAL, PX4_MAIN_OFFBOARD: Mode.GUIDED,
}
PX4_NUMBERS: dict[Mode, tuple[int, int]] = {
    Mode.MANUAL: (PX4_MAIN_POSCTL, 0),
    Mode.HOLD: (PX4_MAIN_AUTO, PX4_AUTO_LOITER),
    Mode.GUIDED: (PX4_MAIN_OFFBOARD, 0),
    Mode.TAKEOFF: (PX4_MAIN_AUTO, PX4_AUTO_TAKEOFF),
    Mode.AUTO: (PX4_MAIN_AUTO, PX4_AUTO_MISSION),
    Mode.RTL: (PX4_MAIN_AUTO, PX4_AUTO_RTL),
    Mode.LAND: (PX4_MAIN_AUTO, PX4_AUTO_LAND),
}

AUTOPILOT = {"ardupilot": mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, "px4": mavlink.MAV_AUTOPILOT_PX4}


def custom_mode(flavour: str, mode: Mode) -> int:
    """HEARTBEAT.custom_mode of ``mode``."""
    if flavour == "px4":
        main, sub = PX4_NUMBERS[mode]
        return (main << 16) | (sub << 24)
    return ARDUPILOT_NUMBERS[mode]


def mode_from_custom(flavour: str, custom: int) -> Mode | None:
    """The mode a HEARTBEAT-style custom_mode (or SET_MODE) names; None if unknown."""
    if flavour == "px4":
        return mode_from_px4(((custom >> 16) & 0xFF), ((custom >> 24) & 0xFF))
    return ARDUPILOT_MODES.get(int(custom))


def mode_from_px4(main: int, sub: int) -> Mode | None:
    """A PX4 main/sub mode pair (DO_SET_MODE param2/param3) as a mode; None if unknown."""
    if (main, sub) in PX4_MODES:
        return PX4_MODES[(main, sub)]
    if main == PX4_MAIN_AUTO and sub == 0:
        return Mode.HOLD
    return PX4_MAIN_ONLY.get(main) if main != PX4_MAIN_AUTO else None


def mode_from_command(flavour: str, param2: float, param3: float) -> Mode | None:
    """The mode requested by MAV_CMD_DO_SET_MODE's custom mode parameters."""
    if flavour == "px4":
        return mode_from_px4(int(param2), int(param3))
    return ARDUPILOT_MODES.get(int(param2))


def mode_name(flavour: str, mode: Mode) -> str:
    """The name a ground station shows for ``mode`` in this flavour."""
    if flavour == "px4":
        return {
            Mode.MANUAL: "POSCTL", Mode.HOLD: "AUTO.LOITER", Mode.GUIDED: "OFFBOARD",
            Mode.TAKEOFF: "AUTO.TAKEOFF", Mode.AUTO: "AUTO.MISSION", Mode.RTL: "AUTO.RTL",
            Mode.LAND: "AUTO.LAND",
        }[mode]
    return {
        Mode.MANUAL: "STABILIZE", Mode.HOLD: "LOITER", Mode.GUIDED: "GUIDED", Mode.TAKEOFF: "GUIDED",
        Mode.AUTO: "AUTO", Mode.RTL: "RTL", Mode.LAND: "LAND",
    }[mode]
