"""Flight modes and their numbers on the wire, per autopilot flavour.

ArduPilot Copter sends its mode number in HEARTBEAT.custom_mode. PX4 packs a main mode
and a sub mode: ``custom_mode = main << 16 | sub << 24`` (px4_custom_mode.h), and
DO_SET_MODE carries them in param2 and param3.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Callable, Mapping

from protocol.autopilot import ARDUPILOT, PX4, Autopilot, autopilot_for


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
ARDUPILOT_NAMES: dict[int, str] = {main: name for (main, _), name in ARDUPILOT.modes.items()}
"""Copter's mode names (Mode::name()), as its STATUSTEXTs spell them (the profile's table)."""
ARDUPILOT_NUMBERS: dict[Mode, tuple[int, int]] = {
    Mode.MANUAL: (0, 0), Mode.HOLD: (5, 0), Mode.GUIDED: (4, 0), Mode.TAKEOFF: (4, 0), Mode.AUTO: (3, 0),
    Mode.RTL: (6, 0), Mode.LAND: (9, 0),
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



def _ardupilot_mode(main: int, sub: int) -> Mode | None:
    return ARDUPILOT_MODES.get(main)


@dataclass(frozen=True)
class ModeTable:
    """What the stub does in each of an autopilot's modes, and how it numbers them (the
    names and the packing into custom_mode are the profile's, ``protocol.autopilot``)."""

    autopilot: Autopilot
    numbers: Mapping[Mode, tuple[int, int]]
    """Mode -> (custom main mode, custom sub mode) the vehicle reports it as."""
    decode: Callable[[int, int], "Mode | None"]
    """(main, sub) -> the mode they ask for; None if unknown."""


TABLES: dict[str, ModeTable] = {
    ARDUPILOT.name: ModeTable(ARDUPILOT, ARDUPILOT_NUMBERS, _ardupilot_mode),
    PX4.name: ModeTable(PX4, PX4_NUMBERS, lambda main, sub: mode_from_px4(main, sub)),
}


def _table(flavour: str | Autopilot) -> ModeTable:
    return TABLES[autopilot_for(flavour).name]


def custom_mode(flavour: str | Autopilot, mode: Mode) -> int:
    """HEARTBEAT.custom_mode of ``mode``."""
    table = _table(flavour)
    return table.autopilot.custom_mode(*table.numbers[mode])


def mode_from_custom(flavour: str | Autopilot, custom: int) -> Mode | None:
    """The mode a HEARTBEAT-style custom_mode (or SET_MODE) names; None if unknown."""
    table = _table(flavour)
    a = table.autopilot
    sub = (int(custom) >> a.sub_shift) & 0xFF if a.sub_shift is not None else 0
    return table.decode((int(custom) >> a.main_shift) & a.main_mask, sub)


def mode_from_px4(main: int, sub: int) -> Mode | None:
    """A PX4 main/sub mode pair (DO_SET_MODE param2/param3) as a mode; None if unknown."""
    if (main, sub) in PX4_MODES:
        return PX4_MODES[(main, sub)]
    if main == PX4_MAIN_AUTO and sub == 0:
        return Mode.HOLD
    return PX4_MAIN_ONLY.get(main) if main != PX4_MAIN_AUTO else None


def mode_from_command(flavour: str | Autopilot, param2: float, param3: float) -> Mode | None:
    """The mode requested by MAV_CMD_DO_SET_MODE's custom mode parameters."""
    return _table(flavour).decode(int(param2), int(param3))


def mode_name(flavour: str | Autopilot, mode: Mode) -> str:
    """The name a ground station shows for ``mode`` in this autopilot."""
    return autopilot_for(flavour).mode_name(custom_mode(flavour, mode))


def requested_name(flavour: str | Autopilot, main: int, mode: Mode, sub: int = 0) -> str:
    """The name of the mode a request asked for by number, as the autopilot's refusal spells
    it (``Mode change to LOITER failed``): ``mode``'s own name if the number has none."""
    a = autopilot_for(flavour)
    return a.modes.get((main, sub if a.sub_shift is not None else 0), mode.value)
