"""A few parameters, readable as an autopilot's are (PARAM_REQUEST_LIST, PARAM_REQUEST_READ).

ArduPilot answers PARAM_REQUEST_READ by name with param_index 65535 and by index with the
index (``libraries/GCS_MAVLink/GCS_Param.cpp``, seen on SITL: ``WPNAV_SPEED`` came back with
index 65535), and does not answer a name it does not have. Values are sent as floats (C cast).
PX4 sends integer parameters bytewise (the int32's bytes in the float field,
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE). The stub's parameters describe the vehicle as
it is simulated; they are read-only (a PARAM_SET is answered with the value kept). The
encoding is the behaviour's (``Behaviour.params_bytewise``, ``param_index_by_name``), the
names the table ``PARAMS`` keyed by the autopilot's profile.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any, Callable, Union

from pymavlink.dialects.v20 import common as mavlink

from protocol.autopilot import ARDUPILOT, PX4, Autopilot

from .behaviour import Behaviour, behaviour_for

M = mavlink


@dataclass(frozen=True)
class Param:
    name: str
    kind: int
    """MAV_PARAM_TYPE."""
    value: Callable[[], float]


def _encode(behaviour: Behaviour, param: Param) -> float:
    value = float(param.value())
    if behaviour.params_bytewise and param.kind in (M.MAV_PARAM_TYPE_INT32, M.MAV_PARAM_TYPE_INT8, M.MAV_PARAM_TYPE_INT16):
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return value


class ParamTable:
    """The vehicle's parameters in a fixed order (the index)."""

    def __init__(self, flavour: Union[str, Autopilot, Behaviour], params: list[Param]) -> None:
        self.behaviour = behaviour_for(flavour)
        self.params = params
        self._by_name = {p.name: i for i, p in enumerate(params)}

    def __len__(self) -> int:
        return len(self.params)

    def message(self, index: int, by_name: bool = False) -> Any:
        param = self.params[index]
        by_name_index = self.behaviour.param_index_by_name
        shown = by_name_index if by_name and by_name_index is not None else index
        return M.MAVLink_param_value_message(param.name.encode("ascii"), _encode(self.behaviour, param), param.kind,
                                             len(self.params), shown)

    def read(self, name: str, index: int) -> Any | None:
        """PARAM_REQUEST_READ: by index when ``index`` >= 0, else by name; None if unknown."""
        if index >= 0:
            return self.message(index) if index < len(self.params) else None
        i = self._by_name.get(name)
        return None if i is None else self.message(i, by_name=True)

    def all(self) -> list[Any]:
        return [self.message(i) for i in range(len(self.params))]

    def index_of(self, name: str) -> int | None:
        return self._by_name.get(name)


def _const(v: float) -> Callable[[], float]:
    return lambda: v


def _px4_params(system_id: int, speed_mps: Callable[[], float], climb_mps: float, rtl_alt_m: float,
                disarm_delay_s: float, mission_total: Callable[[], int]) -> list[Param]:
    const = _const
    return [
        Param("MAV_SYS_ID", M.MAV_PARAM_TYPE_INT32, const(system_id)),
        Param("MPC_XY_CRUISE", M.MAV_PARAM_TYPE_REAL32, speed_mps),
        Param("MPC_Z_VEL_MAX_UP", M.MAV_PARAM_TYPE_REAL32, const(climb_mps)),
        Param("MIS_TAKEOFF_ALT", M.MAV_PARAM_TYPE_REAL32, const(2.5)),
        Param("RTL_RETURN_ALT", M.MAV_PARAM_TYPE_REAL32, const(rtl_alt_m)),
        Param("COM_DISARM_PRFLT", M.MAV_PARAM_TYPE_REAL32, const(disarm_delay_s)),
        Param("GF_ACTION", M.MAV_PARAM_TYPE_INT32, const(0)),
    ]


def _ardupilot_params(system_id: int, speed_mps: Callable[[], float], climb_mps: float, rtl_alt_m: float,
                      disarm_delay_s: float, mission_total: Callable[[], int]) -> list[Param]:
    const = _const
    return [
        Param("SYSID_THISMAV", M.MAV_PARAM_TYPE_INT16, const(system_id)),
        Param("WPNAV_SPEED", M.MAV_PARAM_TYPE_REAL32, lambda: speed_mps() * 100.0),
        Param("WPNAV_SPEED_UP", M.MAV_PARAM_TYPE_REAL32, const(climb_mps * 100.0)),
        Param("WPNAV_SPEED_DN", M.MAV_PARAM_TYPE_REAL32, const(climb_mps * 100.0)),
        Param("RTL_ALT", M.MAV_PARAM_TYPE_INT32, const(rtl_alt_m * 100.0)),
        Param("DISARM_DELAY", M.MAV_PARAM_TYPE_INT8, const(disarm_delay_s)),
        Param("FENCE_ENABLE", M.MAV_PARAM_TYPE_INT8, const(0)),
        Param("MIS_TOTAL", M.MAV_PARAM_TYPE_INT16, lambda: float(mission_total())),
        Param("MIS_RESTART", M.MAV_PARAM_TYPE_INT8, const(0)),
    ]


PARAMS: dict[str, Callable[..., list[Param]]] = {ARDUPILOT.name: _ardupilot_params, PX4.name: _px4_params}
"""The parameters each autopilot has for what the stub simulates, by the profile's name."""


def vehicle_params(flavour: Union[str, Autopilot, Behaviour], system_id: int, speed_mps: Callable[[], float],
                   climb_mps: float, rtl_alt_m: float, disarm_delay_s: float,
                   mission_total: Callable[[], int]) -> ParamTable:
    """The parameters of the simulated vehicle, named as each autopilot names them."""
    behaviour = behaviour_for(flavour)
    build = PARAMS[behaviour.autopilot.name]
    return ParamTable(behaviour, build(system_id, speed_mps, climb_mps, rtl_alt_m, disarm_delay_s, mission_total))
