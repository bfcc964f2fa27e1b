"""The ground-station side of the MAVLink mission upload, as a state machine with no I/O:
it is given a ``send`` callable, fed the autopilot's messages and told when a wait ran
out. MISSION_COUNT -> (MISSION_REQUEST_INT or legacy MISSION_REQUEST -> MISSION_ITEM_INT)*
-> MISSION_ACK. Silence repeats the last message, up to ``retries`` times in a row.

ArduPilot asks with the legacy MISSION_REQUEST and accepts MISSION_ITEM_INT in reply, so
both requests are answered with MISSION_ITEM_INT.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

from pymavlink.dialects.v20 import common as mavlink

from protocol import MissionItem

MISSION_TYPE = mavlink.MAV_MISSION_TYPE_MISSION
RESULT_NAMES = {v.name: k for k, v in mavlink.enums["MAV_MISSION_RESULT"].items()}


def result_name(code: int) -> str:
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(code)
    return entry.name if entry is not None else f"MAV_MISSION_RESULT {code}"


@dataclass(frozen=True)
class UploadDone:
    """How an upload ended: ``accepted``, or why not (``result``: a MAV_MISSION_RESULT
    name, or ``NO_ANSWER`` / ``BAD_REQUEST``)."""

    accepted: bool
    result: str
    messages_sent: int


class MissionUpload:
    def __init__(self, items: Sequence[MissionItem], send: Callable[[Any], None], target: tuple[int, int],
                 retries: int) -> None:
        if not items:
            raise ValueError("a mission upload needs at least one item")
        self.items = list(items)
        self.send = send
        self.target = target
        self.retries = retries
        self.last_sent: int | None = None
        self.silent = 0
        self.sent = 0
        self.done: UploadDone | None = None

    def _send(self, msg: Any) -> None:
        self.sent += 1
        self.send(msg)

    def _count(self) -> Any:
        return mavlink.MAVLink_mission_count_message(self.target[0], self.target[1], len(self.items), MISSION_TYPE)

    def begin(self) -> None:
        self._send(self._count())

    def on_message(self, msg: Any) -> UploadDone | None:
        """Feed a MISSION_REQUEST(_INT) or MISSION_ACK; the outcome once there is one."""
        if self.done is not None:
            return self.done
        kind = msg.get_type()
        if getattr(msg, "mission_type", MISSION_TYPE) != MISSION_TYPE:
            return None
        if kind == "MISSION_ACK":
            if self.last_sent is None and msg.type == mavlink.MAV_MISSION_ACCEPTED:
                return None  # a stale ACK of an earlier operation
            self.done = UploadDone(msg.type == mavlink.MAV_MISSION_ACCEPTED, result_name(msg.type), self.sent)
            return self.done
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            if not 0 <= msg.seq < len(self.items):
                self.done = UploadDone(False, f"BAD_REQUEST (item {msg.seq} of {len(self.items)})", self.sent)
                return self.done
            self.silent = 0
            self.last_sent = msg.seq
            self._send(self.items[msg.seq].to_message(*self.target))
        return None

    def on_timeout(self) -> UploadDone | None:
        """The wait for the autopilot ran out: repeat the last message, or give up."""
        if self.done is not None:
            return self.done
        self.silent += 1
        if self.silent > self.retries:
            where = "MISSION_COUNT" if self.last_sent is None else f"item {self.last_sent}"
            self.done = UploadDone(False, f"NO_ANSWER after {self.retries} repeats of {where}", self.sent)
            return self.done
        if self.last_sent is None:
            self._send(self._count())
        else:
            self._send(self.items[self.last_sent].to_message(*self.target))
        return None
