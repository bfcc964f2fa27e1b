"""Which telemetry each ground station gets, and how often: one table per peer.

ArduPilot keeps message rates per MAVLink channel and Copter's stream-rate parameters
(``MAVn_*``, ``SRn_*`` before 4.6) default to 0: a channel gets HEARTBEAT and nothing else
until it asks (checked on ArduCopter SITL V4.7.0-dev). It asks per message with
MAV_CMD_SET_MESSAGE_INTERVAL (``GCS_MAVLINK::set_message_interval`` in
``libraries/GCS_MAVLink/GCS_Common.cpp``: interval in microseconds, 0 = the default rate of
the message's stream group, -1 = off; a message ArduPilot cannot send is refused) or per
group with REQUEST_DATA_STREAM (the groups of ``ArduCopter/GCS_MAVLink_Copter.cpp``;
EXTENDED_SYS_STATE, HOME_POSITION and GPS_GLOBAL_ORIGIN are in none). The stub gives each
peer (a UDP address or a TCP connection) its own table, as ArduPilot does per channel.

PX4 streams a default set on a normal (ground station) link on its own
(``Mavlink::configure_streams_to_default`` in ``src/modules/mavlink/mavlink_main.cpp``,
MAVLINK_MODE_NORMAL) and honours SET_MESSAGE_INTERVAL; it ignores REQUEST_DATA_STREAM.

Rates are kept in wall-clock time, not simulated time, so that a speed-up of 160 does not
send 160 times as many messages; docs/VEHICLE.md says what that changes.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Mapping, Union

from pymavlink.dialects.v20 import common as mavlink

from protocol.autopilot import ARDUPILOT, PX4, Autopilot, autopilot_for

M = mavlink
DEFAULT_MAX_STREAM_HZ = 50.0
"""The most a streamed message is sent per wall second (``--max-stream-hz``): an autopilot's
rates are in its own clock, so a speed-up multiplies them; this keeps a stub at a speed-up of
160 from sending thousands of messages a second (PX4's fastest default is 50 Hz of its time)."""
MIN_INTERVAL_S = 1.0 / DEFAULT_MAX_STREAM_HZ
EKF_STATUS_REPORT_ID = 193
"""ArduPilot's EKF_STATUS_REPORT (ardupilotmega dialect, not in common)."""

# REQUEST_DATA_STREAM groups (MAV_DATA_STREAM ids), the messages of each that the stub can
# build (ArduCopter/GCS_MAVLink_Copter.cpp STREAM_*_msgs; the others are not simulated).
GROUPS: dict[int, tuple[int, ...]] = {
    M.MAV_DATA_STREAM_RAW_SENSORS: (),
    M.MAV_DATA_STREAM_EXTENDED_STATUS: (
        M.MAVLINK_MSG_ID_SYS_STATUS, M.MAVLINK_MSG_ID_MISSION_CURRENT, M.MAVLINK_MSG_ID_GPS_RAW_INT,
    ),
    M.MAV_DATA_STREAM_RC_CHANNELS: (),
    M.MAV_DATA_STREAM_POSITION: (M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    M.MAV_DATA_STREAM_EXTRA1: (M.MAVLINK_MSG_ID_ATTITUDE,),
    M.MAV_DATA_STREAM_EXTRA2: (M.MAVLINK_MSG_ID_VFR_HUD,),
    M.MAV_DATA_STREAM_EXTRA3: (
        M.MAVLINK_MSG_ID_SYSTEM_TIME, M.MAVLINK_MSG_ID_BATTERY_STATUS, EKF_STATUS_REPORT_ID,
    ),
}
GROUP_OF: dict[int, int] = {msg_id: group for group, ids in GROUPS.items() for msg_id in ids}

# PX4's onboard (API) link unasked, per simulated second, for the messages the stub builds:
# measured on PX4 SITL 1.18.0-dev at speed 5 and 10 (MAVLINK_MODE_ONBOARD, the link a
# companion computer and the service use; px4-rc.mavlink). GPS_RAW_INT follows the GPS
# (7.7 Hz measured); MISSION_CURRENT is the mission manager's 1 Hz.
PX4_DEFAULT_HZ: dict[int, float] = {
    M.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    M.MAVLINK_MSG_ID_ATTITUDE: 100.0,
    M.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    M.MAVLINK_MSG_ID_GPS_RAW_INT: 8.0,
    M.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    M.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    M.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
    M.MAVLINK_MSG_ID_SYSTEM_TIME: 1.0,
    M.MAVLINK_MSG_ID_VFR_HUD: 10.0,
    M.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
}
ARDUPILOT_STREAMABLE = frozenset(GROUP_OF) | {
    M.MAVLINK_MSG_ID_HEARTBEAT, M.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, M.MAVLINK_MSG_ID_HOME_POSITION,
    M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
}
PX4_STREAMABLE = frozenset(PX4_DEFAULT_HZ) | {M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, M.MAVLINK_MSG_ID_AUTOPILOT_VERSION}


@dataclass(frozen=True)
class StreamRules:
    """How one autopilot streams telemetry (the module's docstring has the sources)."""

    streamable: frozenset[int]
    """The messages it can send: SET_MESSAGE_INTERVAL and REQUEST_MESSAGE for others are refused."""
    default_hz: Mapping[int, float] | None
    """A new link's streams and what interval 0 means, message by message (PX4's
    MAVLINK_MODE_NORMAL); None: HEARTBEAT only, interval 0 the rate of the message's
    REQUEST_DATA_STREAM group (ArduPilot)."""
    fixed_heartbeat: bool
    """SET_MESSAGE_INTERVAL of HEARTBEAT is accepted and changes nothing (PX4's 1 Hz)."""
    data_streams: bool
    """REQUEST_DATA_STREAM is honoured (ArduPilot); PX4 has no handler for it."""
    simulated_time: bool
    """Rates and requested intervals are in the vehicle's own (simulated) clock, so a
    speed-up multiplies them, as PX4 SITL's do (measured: 5 times the messages at speed 5);
    False: wall time (the ArduPilot flavour, kept so; docs/VEHICLE.md)."""


STREAM_RULES: Mapping[str, StreamRules] = MappingProxyType({
    ARDUPILOT.name: StreamRules(ARDUPILOT_STREAMABLE, None, fixed_heartbeat=False, data_streams=True,
                                   simulated_time=False),
    PX4.name: StreamRules(PX4_STREAMABLE, MappingProxyType(PX4_DEFAULT_HZ), fixed_heartbeat=True,
                             data_streams=False, simulated_time=True),
})
"""The stream rules by the autopilot profile's name."""


@dataclass
class PeerStreams:
    """One peer's message intervals (wall seconds; absent or 0: not sent) and the times
    each is next due. ``speedup`` (simulated seconds per wall second) turns the vehicle's
    intervals into wall ones where the rules say they are simulated; ``max_hz`` caps every
    message's wall rate."""

    flavour: Union[str, Autopilot]
    speedup: float = 1.0
    max_hz: float = DEFAULT_MAX_STREAM_HZ
    intervals: dict[int, float] = field(default_factory=dict)
    group_hz: dict[int, float] = field(default_factory=dict)
    due: dict[int, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.rules = STREAM_RULES[autopilot_for(self.flavour).name]
        if not (self.speedup > 0 and self.max_hz > 0):
            raise ValueError(f"speedup and max_hz must be positive, got {self.speedup} and {self.max_hz}")
        if not self.intervals:
            if self.rules.default_hz is not None:
                self.intervals = {m: self._wall(1.0 / hz) for m, hz in self.rules.default_hz.items()}
            else:
                self.intervals = {M.MAVLINK_MSG_ID_HEARTBEAT: 1.0}

    def _wall(self, interval_s: float) -> float:
        """A vehicle interval as wall seconds (0 stays off), never under 1/max_hz."""
        if interval_s <= 0:
            return 0.0
        if self.rules.simulated_time:
            interval_s /= self.speedup
        return max(interval_s, 1.0 / self.max_hz)

    @property
    def streamable(self) -> frozenset[int]:
        return self.rules.streamable

    def default_interval(self, msg_id: int) -> float:
        """What interval 0 ("the default rate") means for ``msg_id``."""
        if msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            return self._wall(1.0)
        if self.rules.default_hz is not None:
            hz = self.rules.default_hz.get(msg_id, 0.0)
            return self._wall(1.0 / hz) if hz > 0 else 0.0
        hz = self.group_hz.get(GROUP_OF.get(msg_id, -1), 0.0)
        return 1.0 / hz if hz > 0 else 0.0

    def set_interval(self, msg_id: int, interval_us: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL; False for a message the vehicle cannot send."""
        if msg_id not in self.streamable:
            return False
        if self.rules.fixed_heartbeat and msg_id == M.MAVLINK_MSG_ID_HEARTBEAT:
            return True
        if interval_us == 0:
            interval = self.default_interval(msg_id)
        elif interval_us < 0:
            interval = 0.0
        else:
            interval = self._wall(min(interval_us / 1e6, 60.0))
        self._set(msg_id, interval)
        return True

    def request_data_stream(self, group: int, rate_hz: float, start: bool) -> None:
        """REQUEST_DATA_STREAM (ArduPilot): every message of ``group`` (all groups for
        MAV_DATA_STREAM_ALL) at ``rate_hz``, or off."""
        if not self.rules.data_streams:
            return
        hz = rate_hz if start and rate_hz > 0 else 0.0
        groups = list(GROUPS) if group == M.MAV_DATA_STREAM_ALL else [group]
        for g in groups:
            if g not in GROUPS:
                continue
            self.group_hz[g] = hz
            for msg_id in GROUPS[g]:
                self._set(msg_id, 1.0 / hz if hz > 0 else 0.0)

    def enabled(self, msg_id: int) -> bool:
        return self.intervals.get(msg_id, 0.0) > 0

    def due_now(self, now: float) -> list[int]:
        """The messages due at ``now`` (their next time is moved on)."""
        out = []
        for msg_id, interval in self.intervals.items():
            if interval <= 0 or now < self.due.get(msg_id, 0.0):
                continue
            self.due[msg_id] = now + interval
            out.append(msg_id)
        return out

    def _set(self, msg_id: int, interval: float) -> None:
        self.intervals[msg_id] = interval
        self.due.pop(msg_id, None)
