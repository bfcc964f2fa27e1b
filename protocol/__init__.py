"""The wire contracts: zenoh keys, JSON messages, the MAVLink mission encoding, mission files."""

from .area import Area
from .errors import MissionError, ProtocolError, SigningError
from .geodesy import GeoOrigin, global_to_local, local_to_global
from .keys import DEFAULT_PREFIX, Keys
from .messages import (
    MAX_PAYLOAD_BYTES, SCHEMA_VERSION, ErrorReply, Event, Plan, PlanPoint, PendingRequest, State,
    Status, TaskAck, TaskRequest, decode, decode_reply, decode_request, encode,
)
from .mission import (
    FLAVOURS, Flavour, HoverPoint, MissionItem, MissionPlan, decode_path, encode_path, mission_digest,
    replacement_items, same_items, same_mission, stored_item, validate_mission,
)
from .mission_files import read_plan, read_wpl, write_plan, write_wpl

__all__ = [
    "Area", "DEFAULT_PREFIX", "ErrorReply", "Event", "FLAVOURS", "Flavour", "GeoOrigin",
    "HoverPoint", "Keys", "MAX_PAYLOAD_BYTES", "MissionError", "MissionItem", "MissionPlan",
    "PendingRequest", "Plan", "PlanPoint", "ProtocolError", "SCHEMA_VERSION", "SigningError", "State", "Status",
    "TaskAck", "TaskRequest", "decode", "decode_path", "decode_reply", "decode_request", "encode",
    "encode_path", "global_to_local", "local_to_global", "mission_digest", "read_plan", "read_wpl",
    "replacement_items", "same_items", "same_mission", "stored_item", "validate_mission", "write_plan", "write_wpl",
]
