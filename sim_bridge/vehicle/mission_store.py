"""The vehicle side of the MAVLink mission protocol, as a state machine without sockets.

Given a ``send(message, peer)`` callable and a clock it handles upload (MISSION_COUNT ->
MISSION_REQUEST_INT -> MISSION_ITEM_INT -> MISSION_ACK, with re-requests on timeout),
download (answering MISSION_REQUEST_INT with MISSION_ITEM_INT and the legacy
MISSION_REQUEST with MISSION_ITEM), clear and set-current
(https://mavlink.io/en/services/mission.html).

A failed upload never touches the mission held: items are collected aside and committed
only when the last one arrived and the whole mission passed ``check``.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable

from pymavlink.dialects.v20 import common as mavlink

from protocol.mission import MissionItem

log = logging.getLogger(__name__)

MISSION = mavlink.MAV_MISSION_TYPE_MISSION
SendFn = Callable[[Any, Hashable], None]
"""send(message, peer): the peer is whatever the link uses to address a ground station."""
CheckFn = Callable[[list[MissionItem]], "tuple[int, str] | None"]
"""check(items) -> None when acceptable, else (MAV_MISSION_RESULT, reason)."""


@dataclass
class _Upload:
    peer: Hashable
    target: tuple[int, int]
    count: int
    items: list[MissionItem] = field(default_factory=list)
    deadline: float = 0.0
    retries: int = 0


@dataclass
class _Done:
    """The last upload that completed, to repeat its ACK when the ground station, having
    missed it, sends the last item again."""

    peer: Hashable
    target: tuple[int, int]
    count: int
    result: int
    until: float


class MissionStore:
    """Holds the vehicle's mission and speaks the protocol for it."""

    def __init__(
        self,
        send: SendFn,
        clock: Callable[[], float],
        *,
        check: CheckFn | None = None,
        on_commit: Callable[[list[MissionItem]], list[MissionItem] | None] | None = None,
        on_set_current: Callable[[int], bool] | None = None,
        capacity: int = 512,
        item_timeout_s: float = 1.0,
        max_retries: int = 5,
    ) -> None:
        self._send = send
        self._clock = clock
        self._check = check or (lambda items: None)
        # on_commit may return the items as the vehicle keeps them (ArduPilot's home).
        self._on_commit = on_commit or (lambda items: None)
        self._on_set_current = on_set_current or (lambda seq: 0 <= seq < len(self.items))
        self.capacity = capacity
        self.item_timeout_s = item_timeout_s
        self.max_retries = max_retries
        self.items: list[MissionItem] = []
        self._upload: _Upload | None = None
        self._done: _Done | None = None
        self.uploads_accepted = 0
        self.uploads_failed = 0

    @property
    def uploading(self) -> bool:
        return self._upload is not None

    # --- dispatch -------------------------------------------------------------------------
    def handle(self, msg: Any, peer: Hashable) -> bool:
        """Handle one received message; False if it is not part of the mission protocol."""
        kind = msg.get_type()
        handler = {
            "MISSION_COUNT": self._on_count,
            "MISSION_ITEM_INT": self._on_item,
            "MISSION_ITEM": self._on_item,
            "MISSION_REQUEST_LIST": self._on_request_list,
            "MISSION_REQUEST_INT": self._on_request,
            "MISSION_REQUEST": self._on_request,
            "MISSION_ACK": self._on_ack,
            "MISSION_CLEAR_ALL": self._on_clear,
            "MISSION_SET_CURRENT": self._on_set_current_msg,
        }.get(kind)
        if handler is None:
            return False
        handler(msg, peer, (msg.get_srcSystem(), msg.get_srcComponent()))
        return True

    def tick(self) -> None:
        """Re-request the awaited item on timeout; give up after ``max_retries``."""
        up = self._upload
        if up is None or self._clock() < up.deadline:
            return
        if up.retries >= self.max_retries:
            log.warning("mission upload timed out waiting for item %d of %d", len(up.items), up.count)
            self._fail(up, mavlink.MAV_MISSION_OPERATION_CANCELLED)
            return
        up.retries += 1
        self._request_next(up)

    # --- upload ---------------------------------------------------------------------------
    def _on_count(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if mission_type != MISSION:
            self._ack(peer, src, mavlink.MAV_MISSION_UNSUPPORTED, mission_type)
            return
        up = self._upload
        if up is not None and up.peer == peer and up.target == src and up.count == msg.count:
            # A repeated COUNT (our request was lost, or the link duplicated it): carry on.
            self._request_next(up)
            return
        if msg.count == 0:
            self._upload = None
            self._commit([], peer, src, 0)
            return
        if msg.count > self.capacity:
            self._ack(peer, src, mavlink.MAV_MISSION_NO_SPACE, MISSION)
            return
        if up is not None:
            log.info("mission upload restarted by a new MISSION_COUNT")
        self._done = None
        self._upload = _Upload(peer=peer, target=src, count=int(msg.count))
        self._request_next(self._upload)

    def _on_item(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        if getattr(msg, "mission_type", MISSION) != MISSION:
            return
        up = self._upload
        if up is None:
            done = self._done
            if done and done.peer == peer and msg.seq == done.count - 1 and self._clock() < done.until:
                self._ack(peer, src, done.result, MISSION)
            return
        if peer != up.peer or src != up.target:
            return
        expected = len(up.items)
        if msg.seq != expected:
            # An old item again means our request for the next one was lost; anything
            # else is out of order. Either way ask again for the one we need.
            if msg.seq == expected - 1 or msg.seq > expected:
                self._request_next(up)
            return
        try:
            item = MissionItem.from_message(msg)
        except ValueError:
            self._fail(up, mavlink.MAV_MISSION_INVALID)
            return
        problem = _item_problem(item)
        if problem is not None:
            log.warning("mission item %d refused: %s", item.seq, problem[1])
            self._fail(up, problem[0])
            return
        up.items.append(item)
        up.retries = 0
        if len(up.items) < up.count:
            self._request_next(up)
            return
        self._upload = None
        problem = self._check(up.items)
        if problem is not None:
            log.warning("mission refused: %s", problem[1])
            self._finish(up, problem[0])
            return
        self._commit(up.items, peer, src, up.count)

    def _request_next(self, up: _Upload) -> None:
        up.deadline = self._clock() + self.item_timeout_s
        msg = mavlink.MAVLink_mission_request_int_message(up.target[0], up.target[1], len(up.items), MISSION)
        self._send(msg, up.peer)

    def _commit(self, items: list[MissionItem], peer: Hashable, src: tuple[int, int], count: int) -> None:
        kept = self._on_commit(list(items))
        self.items = list(items) if kept is None else kept
        self.uploads_accepted += 1
        self._done = _Done(peer, src, count, mavlink.MAV_MISSION_ACCEPTED, self._clock() + 10 * self.item_timeout_s)
        self._ack(peer, src, mavlink.MAV_MISSION_ACCEPTED, MISSION)

    def _fail(self, up: _Upload, result: int) -> None:
        self._upload = None
        self._finish(up, result)

    def _finish(self, up: _Upload, result: int) -> None:
        self.uploads_failed += 1
        self._done = _Done(up.peer, up.target, up.count, result, self._clock() + 10 * self.item_timeout_s)
        self._ack(up.peer, up.target, result, MISSION)

    def _ack(self, peer: Hashable, target: tuple[int, int], result: int, mission_type: int) -> None:
        self._send(mavlink.MAVLink_mission_ack_message(target[0], target[1], result, mission_type), peer)

    # --- download, clear, set current --------------------------------------------------------
    def _on_request_list(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        # Fences and rally points are not kept: report none rather than leave a ground
        # station (QGroundControl asks for all three) waiting.
        count = len(self.items) if mission_type == MISSION else 0
        self._send(mavlink.MAVLink_mission_count_message(src[0], src[1], count, mission_type), peer)

    def _on_request(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if mission_type != MISSION:
            self._ack(peer, src, mavlink.MAV_MISSION_INVALID_SEQUENCE, mission_type)
            return
        if self._upload is not None and self._upload.peer == peer and self._upload.target == src:
            # Not a download: our own upload partner cannot be asking.
            return
        if not 0 <= msg.seq < len(self.items):
            self._ack(peer, src, mavlink.MAV_MISSION_INVALID_SEQUENCE, MISSION)
            return
        item = self.items[msg.seq]
        if msg.get_type() == "MISSION_REQUEST":
            self._send(item.to_legacy_message(src[0], src[1]), peer)
        else:
            self._send(item.to_message(src[0], src[1]), peer)

    def _on_ack(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        up = self._upload
        if up is not None and up.peer == peer and up.target == src and msg.type != mavlink.MAV_MISSION_ACCEPTED:
            log.info("ground station cancelled the upload (result %d)", msg.type)
            self._upload = None
            self.uploads_failed += 1

    def _on_clear(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if mission_type not in (MISSION, mavlink.MAV_MISSION_TYPE_ALL):
            self._ack(peer, src, mavlink.MAV_MISSION_ACCEPTED, mission_type)
            return
        self._upload = None
        self._commit([], peer, src, 0)

    def _on_set_current_msg(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        if not self._on_set_current(int(msg.seq)):
            log.info("MISSION_SET_CURRENT %d refused (mission has %d items)", msg.seq, len(self.items))


_SUPPORTED_FRAMES = frozenset({
    mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mavlink.MAV_FRAME_MISSION,
})
_FLOWN = frozenset({
    mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME, mavlink.MAV_CMD_NAV_TAKEOFF,
    mavlink.MAV_CMD_NAV_LAND, mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_NAV_DELAY,
})
# Accepted and completed at once: they change a camera, gimbal or speed, not the path.
_NO_OPS = frozenset({
    mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_CMD_DO_SET_ROI_NONE, mavlink.MAV_CMD_DO_SET_ROI_LOCATION,
    mavlink.MAV_CMD_DO_MOUNT_CONTROL, mavlink.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
    mavlink.MAV_CMD_IMAGE_START_CAPTURE, mavlink.MAV_CMD_IMAGE_STOP_CAPTURE,
    mavlink.MAV_CMD_VIDEO_START_CAPTURE, mavlink.MAV_CMD_VIDEO_STOP_CAPTURE,
    mavlink.MAV_CMD_DO_SET_CAM_TRIGG_DIST, mavlink.MAV_CMD_DO_SET_CAM_TRIGG_INTERVAL,
})
SUPPORTED_COMMANDS = _FLOWN | _NO_OPS


def _item_problem(item: MissionItem) -> tuple[int, str] | None:
    """Per-item checks with the MAV_MISSION_RESULT a real autopilot would answer."""
    if item.command not in SUPPORTED_COMMANDS:
        return mavlink.MAV_MISSION_UNSUPPORTED, f"command {item.command} is not supported"
    if item.frame not in _SUPPORTED_FRAMES:
        return mavlink.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {item.frame} is not supported"
    results = (
        mavlink.MAV_MISSION_INVALID_PARAM1, mavlink.MAV_MISSION_INVALID_PARAM2,
        mavlink.MAV_MISSION_INVALID_PARAM3,
    )
    for result, value, name in zip(results, (item.param1, item.param2, item.param3), ("param1", "param2", "param3")):
        # NaN is a documented "use the default" in many commands; infinity never is.
        if math.isinf(value):
            return result, f"{name} is infinite"
    positional = item.command in _FLOWN - {mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH, mavlink.MAV_CMD_NAV_DELAY}
    if math.isinf(item.z) or (positional and math.isnan(item.z)):
        return mavlink.MAV_MISSION_INVALID_PARAM7, "z is not finite"
    if item.frame != mavlink.MAV_FRAME_MISSION:
        if not -900_000_000 <= item.x <= 900_000_000:
            return mavlink.MAV_MISSION_INVALID_PARAM5_X, "latitude out of range"
        if not -1_800_000_000 <= item.y <= 1_800_000_000:
            return mavlink.MAV_MISSION_INVALID_PARAM6_Y, "longitude out of range"
    if item.command in (mavlink.MAV_CMD_NAV_WAYPOINT, mavlink.MAV_CMD_NAV_LOITER_TIME) and item.param1 < 0:
        return mavlink.MAV_MISSION_INVALID_PARAM1, "hold time is negative"
    return None
