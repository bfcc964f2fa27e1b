"""The wire contracts: zenoh keys, JSON messages, the MAVLink mission encoding, mission files."""

from .area import Area
from .errors import MissionError, ProtocolError, SigningError
from .geodesy import GeoOrigin, global_to_local, local_to_global
from .keys import DEFAULT_PREFIX, FleetKeys, Keys, check_user_id
from .messages import (
    MAX_PAYLOAD_BYTES, SCHEMA_VERSION, ErrorReply, Event, Plan, PlanPoint, PendingRequest, State,
    Status, TaskAck, TaskRequest, UserPlace, decode, decode_reply, decode_request, encode,
)
from .messages import (
    OPERATOR_SCHEMA_VERSION, STATUS_SCHEMA_VERSION, OperatorCommand, OperatorReply, decode_operator_command,
    decode_operator_reply,
)
from .autopilot import ARDUPILOT, FLAVOURS, PROFILES, PX4, Autopilot, Flavour, autopilot_for
from .mission import (
    HoverPoint, MissionItem, MissionPlan, decode_path, encode_path, mission_digest,
    replacement_items, same_items, same_mission, stored_item, validate_mission,
)
from .mission_files import read_plan, read_wpl, write_plan, write_wpl
from .text import printable

__all__ = [
    "ARDUPILOT", "Autopilot", "PROFILES", "PX4", "autopilot_for", "Area", "DEFAULT_PREFIX", "ErrorReply", "Event", "FLAVOURS", "Flavour", "GeoOrigin",
    "FleetKeys", "HoverPoint", "Keys", "MAX_PAYLOAD_BYTES", "MissionError", "MissionItem", "MissionPlan",
    "PendingRequest", "Plan", "PlanPoint", "ProtocolError", "SCHEMA_VERSION", "SigningError", "State", "Status",
    "TaskAck", "TaskRequest", "UserPlace", "check_user_id", "decode", "decode_path", "decode_reply", "decode_request", "encode",
    "encode_path", "global_to_local", "local_to_global", "mission_digest", "read_plan", "read_wpl",
    "replacement_items", "same_items", "same_mission", "stored_item", "validate_mission", "write_plan", "write_wpl",
    "OPERATOR_SCHEMA_VERSION", "STATUS_SCHEMA_VERSION", "OperatorCommand", "OperatorReply",
    "decode_operator_command", "decode_operator_reply", "printable",
]
