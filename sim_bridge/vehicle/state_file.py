"""The vehicle's state file (``--state-file``): the flight saved a few times a second so that
a vehicle killed mid-flight can be started again where it was, as after a reboot.

The file is JSON, written to a temporary name beside it and renamed over it, so a reader
(or a restart after SIGKILL) sees the previous state or the new one, never half of one. It
is not fsync'd: it survives the process being killed, not the machine losing power.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import MISSING, asdict, fields
from pathlib import Path
from typing import Any

from protocol.autopilot import PROFILES

from .errors import VehicleError
from .flight import FlightSnapshot
from .modes import Mode

STATE_VERSION = 1
SAVE_INTERVAL_S = 0.2
"""Wall seconds between saves: a restart loses at most this much of the flight (times the
speed-up in simulated time)."""


def save_state(path: Path, snap: FlightSnapshot) -> None:
    """Write ``snap`` to ``path`` atomically (temporary file, then rename)."""
    data = {"version": STATE_VERSION, **asdict(snap)}
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data))
    os.replace(tmp, path)


def load_state(path: Path) -> FlightSnapshot | None:
    """The snapshot saved at ``path``, or None if there is no file. A file that cannot be
    read as a snapshot is refused with ``VehicleError`` naming the file and the field:
    flying on a guessed state would be worse than not starting."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    except OSError as err:
        raise VehicleError("state_file", f"cannot read {path}: {err.strerror or err}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise VehicleError("state_file", f"{path} is not JSON: {err}") from None
    return parse_state(data, str(path))


def parse_state(data: Any, where: str = "state") -> FlightSnapshot:
    """A snapshot from its JSON form, every field checked."""
    if not isinstance(data, dict):
        raise VehicleError("state_file", f"{where}: expected an object")
    if data.get("version") != STATE_VERSION:
        raise VehicleError("state_file", f"{where}: version {data.get('version')!r}, expected {STATE_VERSION}")
    values: dict[str, Any] = {}
    for f in fields(FlightSnapshot):
        if f.name not in data:
            if f.default is not MISSING:  # an optional field
                continue
            raise VehicleError("state_file", f"{where}: missing {f.name!r}")
        values[f.name] = _field(f.name, data[f.name], where)
    return FlightSnapshot(**values)


def _field(name: str, value: Any, where: str) -> Any:
    def bad(expected: str) -> VehicleError:
        return VehicleError("state_file", f"{where}: {name} = {value!r} is not {expected}")

    if name in ("pos", "home"):
        if not (isinstance(value, list) and len(value) == 3 and all(_finite(v) for v in value)):
            raise bad("three finite numbers")
        return (float(value[0]), float(value[1]), float(value[2]))
    if name in ("armed", "landed"):
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if name == "flavour":
        if value not in PROFILES:
            raise bad(f"one of {tuple(PROFILES)}")
        return value
    if name == "mode":
        if value not in {m.value for m in Mode}:
            raise bad(f"one of {sorted(m.value for m in Mode)}")
        return value
    if not _finite(value) or value < 0 or (name == "speed_mps" and value == 0):
        raise bad("a finite non-negative number" if name != "speed_mps" else "a positive number")
    return float(value)


def _finite(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
