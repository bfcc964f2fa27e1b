"""The ground-station side of the MAVLink mission upload and download, as state machines
with no I/O: each is given a ``send`` callable, fed the autopilot's messages and told when
a wait ran out. Silence repeats the last message; an operation gives up after ``retries``
repeats in a row *and* ``patience_s`` of silence (``Silence``).

Upload: MISSION_COUNT -> (MISSION_REQUEST_INT or legacy MISSION_REQUEST ->
MISSION_ITEM_INT)* -> MISSION_ACK. ArduPilot asks with the legacy MISSION_REQUEST and
accepts MISSION_ITEM_INT in reply, so both requests are answered with MISSION_ITEM_INT.
An upload given up after its last item was sent may have been committed (only the ACK was
lost): ``UploadDone.maybe_committed`` says so, and the caller must find out.

Download: MISSION_REQUEST_LIST -> MISSION_COUNT -> (MISSION_REQUEST_INT -> MISSION_ITEM_INT)*
-> MISSION_ACK (ours).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from pymavlink.dialects.v20 import common as mavlink

from protocol import MissionItem

MISSION_TYPE = mavlink.MAV_MISSION_TYPE_MISSION
RESULT_NAMES = {v.name: k for k, v in mavlink.enums["MAV_MISSION_RESULT"].items()}


def result_name(code: int) -> str:
    entry = mavlink.enums["MAV_MISSION_RESULT"].get(code)
    return entry.name if entry is not None else f"MAV_MISSION_RESULT {code}"


class Silence:
    """Waits in a row that ran out with no answer. The link's wait before a repeat follows
    the measured round trip (rtt.py) and may be as short as 0.1 s, but the vehicle's own
    repeats do not speed up with it: PX4 asks again for a lost item every 0.25 s and drops
    an item it did not ask for without a word, ArduPilot asks again every second. So a
    short wait shortens the repeats, never the patience: giving up needs ``retries``
    repeats and ``patience_s`` of silence both (the link gives ``retries`` times its
    longest wait, ``mavlink.item_timeout_s``)."""

    def __init__(self, retries: int, patience_s: float = 0.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.retries = retries
        self.patience_s = patience_s
        self.clock = clock
        self.repeats = 0
        self.since = clock()

    def answered(self) -> None:
        self.repeats, self.since = 0, self.clock()

    def ran_out(self) -> bool:
        """One more wait ran out: True when it is time to give up, else repeat."""
        self.repeats += 1
        return self.repeats > self.retries and self.clock() - self.since >= self.patience_s

    def over(self) -> str:
        """How long the silence was, for a NO_ANSWER: ' in 5.0 s'."""
        return f" in {self.clock() - self.since:.1f} s"


@dataclass(frozen=True)
class UploadDone:
    """How an upload ended: ``accepted``, or why not (``result``: a MAV_MISSION_RESULT
    name, or ``NO_ANSWER`` / ``BAD_REQUEST``)."""

    accepted: bool
    result: str
    messages_sent: int
    maybe_committed: bool = False
    """Given up for silence after the last item was sent: the autopilot may hold it."""


class MissionUpload:
    def __init__(self, items: Sequence[MissionItem], send: Callable[[Any], None], target: tuple[int, int],
                 retries: int, patience_s: float = 0.0) -> None:
        if not items:
            raise ValueError("a mission upload needs at least one item")
        self.items = list(items)
        self.send = send
        self.target = target
        self.silence = Silence(retries, patience_s)
        self.last_sent: int | None = None
        self.sent_last = False
        """The last item went out at least once: only then can an ACCEPTED be this upload's."""
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
            if msg.type == mavlink.MAV_MISSION_ACCEPTED and not self.sent_last:
                # An autopilot accepts an upload once it has every item: before the last went
                # out, an ACCEPTED answers an earlier operation (a late or duplicated datagram
                # of the upload before, on a lossy link), not this one.
                return None
            if msg.type == mavlink.MAV_MISSION_INVALID_SEQUENCE:
                # A repeated or reordered item: ArduPilot answers it so and goes on waiting
                # for the item it asked for, asking again every second (MissionItemProtocol.cpp);
                # so does this upload. The vehicle answered: it is not silent.
                self.silence.answered()
                return None
            if msg.type == mavlink.MAV_MISSION_ERROR and self.sent_last:
                # Both autopilots answer ERROR to an item that comes after the upload ended:
                # our repeat of the last item crossed its ACCEPTED, which was lost, or a late
                # duplicate of an earlier request had an earlier item sent again (PX4 SITL
                # through the lossy proxy: "IGN MISSION_ITEM: No transfer"). Committed most
                # likely, not certainly: the caller reads the mission back.
                self.done = UploadDone(False, result_name(msg.type), self.sent, maybe_committed=True)
                return self.done
            self.done = UploadDone(msg.type == mavlink.MAV_MISSION_ACCEPTED, result_name(msg.type), self.sent)
            return self.done
        if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            if not 0 <= msg.seq < len(self.items):
                self.done = UploadDone(False, f"BAD_REQUEST (item {msg.seq} of {len(self.items)})", self.sent)
                return self.done
            self.silence.answered()
            self.last_sent = msg.seq
            self.sent_last |= msg.seq == len(self.items) - 1
            self._send(self.items[msg.seq].to_message(*self.target))
        return None

    def on_timeout(self) -> UploadDone | None:
        """The wait for the autopilot ran out: repeat the last message, or give up."""
        if self.done is not None:
            return self.done
        if self.silence.ran_out():
            where = "MISSION_COUNT" if self.last_sent is None else f"item {self.last_sent}"
            result = f"NO_ANSWER after {self.silence.repeats - 1} repeats of {where}{self.silence.over()}"
            self.done = UploadDone(False, result, self.sent, maybe_committed=self.sent_last)
            return self.done
        if self.last_sent is None:
            self._send(self._count())
        else:
            self._send(self.items[self.last_sent].to_message(*self.target))
        return None


def cancel_message(target: tuple[int, int]) -> Any:
    """MISSION_ACK CANCELLED: tells the autopilot to drop an upload we gave up, so that a
    later upload of the same length is never taken for its continuation."""
    return mavlink.MAVLink_mission_ack_message(target[0], target[1], mavlink.MAV_MISSION_OPERATION_CANCELLED,
                                               MISSION_TYPE)


@dataclass(frozen=True)
class DownloadDone:
    """How a download ended: ``ok`` with the ``items``, or why not (``result``)."""

    ok: bool
    result: str
    items: tuple[MissionItem, ...] = ()


class MissionDownload:
    def __init__(self, send: Callable[[Any], None], target: tuple[int, int], retries: int,
                 patience_s: float = 0.0) -> None:
        self.send = send
        self.target = target
        self.silence = Silence(retries, patience_s)
        self.count: int | None = None
        self.items: list[MissionItem] = []
        self.sent = 0
        self.done: DownloadDone | None = None

    def _send(self, msg: Any) -> None:
        self.sent += 1
        self.send(msg)

    def _ask(self) -> None:
        if self.count is None:
            self._send(mavlink.MAVLink_mission_request_list_message(*self.target, MISSION_TYPE))
        else:
            self._send(mavlink.MAVLink_mission_request_int_message(*self.target, len(self.items), MISSION_TYPE))

    def _finish(self) -> DownloadDone:
        self._send(mavlink.MAVLink_mission_ack_message(*self.target, mavlink.MAV_MISSION_ACCEPTED, MISSION_TYPE))
        self.done = DownloadDone(True, "MAV_MISSION_ACCEPTED", tuple(self.items))
        return self.done

    def begin(self) -> None:
        self._ask()

    def on_message(self, msg: Any) -> DownloadDone | None:
        """Feed a MISSION_COUNT, MISSION_ITEM_INT or MISSION_ACK; the outcome once there is one."""
        if self.done is not None:
            return self.done
        if getattr(msg, "mission_type", MISSION_TYPE) != MISSION_TYPE:
            return None
        kind = msg.get_type()
        if kind == "MISSION_COUNT" and self.count is None:
            self.count = int(msg.count)
            self.silence.answered()
            if self.count == 0:
                return self._finish()
            self._ask()
        elif kind == "MISSION_ITEM_INT" and self.count is not None and msg.seq == len(self.items):
            self.items.append(MissionItem.from_message(msg))
            self.silence.answered()
            if len(self.items) == self.count:
                return self._finish()
            self._ask()
        elif kind == "MISSION_ACK" and self.count is not None and msg.type != mavlink.MAV_MISSION_ACCEPTED:
            self.done = DownloadDone(False, result_name(msg.type))
        return self.done

    def on_timeout(self) -> DownloadDone | None:
        """The wait ran out: ask again, or give up."""
        if self.done is not None:
            return self.done
        if self.silence.ran_out():
            where = "MISSION_COUNT" if self.count is None else f"item {len(self.items)} of {self.count}"
            result = f"NO_ANSWER after {self.silence.repeats - 1} requests for {where}{self.silence.over()}"
            self.done = DownloadDone(False, result)
            return self.done
        self._ask()
        return None
