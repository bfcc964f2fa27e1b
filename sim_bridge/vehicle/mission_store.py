"""The vehicle side of the MAVLink mission protocol, as a state machine without sockets.

Given a ``send(message, peer)`` callable and a clock it handles upload, download, clear and
set-current (https://mavlink.io/en/services/mission.html), the way each autopilot does:

- **ArduPilot** (``libraries/GCS_MAVLink/MissionItemProtocol.cpp``,
  ``MissionItemProtocol_Waypoints.cpp``): MISSION_COUNT truncates the stored mission to the
  new length at once and each item is written into the live mission as it arrives, so the
  aircraft sees the new mission item by item; a refused or abandoned upload leaves what was
  written (the new count, the new items so far, the old ones after them). Items are asked
  for with the legacy MISSION_REQUEST; an item out of sequence gets MISSION_ACK
  INVALID_SEQUENCE and the upload goes on; an item after the upload ended gets
  MISSION_ACK ERROR; another sender's MISSION_COUNT during an upload is DENIED. Item 0 is
  read back as home (zeros before home is known), whatever was uploaded there.
- **PX4** (``src/modules/mavlink/mavlink_mission.cpp``): items go to the inactive storage
  and the mission switches over only when the last one arrived, so a failed upload leaves
  the old mission whole; the last item sent again after the ACK gets the ACK again.

``hooks`` connects the store to the aircraft (what an item becomes in storage, what the
flight does with a changed mission); see ``StoreHooks``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable, Hashable

from pymavlink.dialects.v20 import common as mavlink

from protocol.autopilot import autopilot_for
from protocol.mission import MissionItem

from .stored_items import Problem
from .mission_id import MissionAck, MissionCount, px4_mission_id

log = logging.getLogger(__name__)

MISSION = mavlink.MAV_MISSION_TYPE_MISSION
SendFn = Callable[[Any, Hashable], None]
"""send(message, peer): the peer is whatever the link uses to address a ground station."""


@dataclass
class StoreHooks:
    """What the store asks of the vehicle. Every callable has a harmless default, so a test
    can build a store with only what it exercises."""

    problem: Callable[[MissionItem], Problem | None] = lambda item: None
    """The autopilot's refusal of one item (MAV_MISSION_RESULT, why), or None."""
    stored: Callable[[MissionItem], MissionItem] = lambda item: item
    """What the autopilot keeps of an accepted item (and reads back)."""
    on_change: Callable[[list[MissionItem], frozenset[int]], None] = lambda items, written: None
    """ArduPilot: the live mission changed (``written``: the indices just written; empty for
    a truncation or a clear)."""
    on_commit: Callable[[list[MissionItem]], None] = lambda items: None
    """PX4: a whole new mission replaced the old one."""
    on_accepted: Callable[[list[MissionItem]], None] = lambda items: None
    """An upload completed (both autopilots), with the items as they were sent."""
    on_set_current: Callable[[int, Hashable], bool] = lambda seq, peer: False
    """MISSION_SET_CURRENT; False if refused."""
    current_flag: Callable[[int], int] = lambda seq: 0
    """The ``current`` field of item ``seq`` in a download."""
    home_item: Callable[[], MissionItem | None] = lambda: None
    """ArduPilot: what item 0 reads back as (home), None for PX4."""
    can_clear: Callable[[], bool] = lambda: True
    """ArduPilot refuses MISSION_CLEAR_ALL while a mission is running."""
    text: Callable[[str, Hashable], None] = lambda text, peer: None
    """Send a STATUSTEXT to one peer (``Flight plan received``)."""


@dataclass
class _Upload:
    peer: Hashable
    target: tuple[int, int]
    count: int
    items: list[MissionItem] = field(default_factory=list)
    """The items received, as sent (PX4 commits what it keeps of them at the end)."""
    received: int = 0
    deadline: float = 0.0
    retries: int = 0


@dataclass
class _Done:
    """The last upload that completed, to repeat its ACK (PX4) when the ground station,
    having missed it, sends the last item again."""

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
        flavour: str = "ardupilot",
        hooks: StoreHooks | None = None,
        capacity: int = 512,
        item_timeout_s: float = 1.0,
        max_retries: int = 5,
    ) -> None:
        self._send = send
        self._clock = clock
        self.flavour = flavour
        self._autopilot = autopilot_for(flavour)
        self.hooks = hooks or StoreHooks()
        self.capacity = capacity
        self.item_timeout_s = item_timeout_s
        self.max_retries = max_retries
        self.items: list[MissionItem] = []
        """The mission as stored (ArduPilot: item 0 as uploaded; downloads show home)."""
        self._upload: _Upload | None = None
        self._done: _Done | None = None
        self.uploads_accepted = 0
        self.uploads_failed = 0

    @property
    def write_through(self) -> bool:
        """Items are stored as they arrive (``Autopilot.writes_items_as_they_arrive``); the
        store's other ArduPilot conventions (answers, home at item 0) go with it."""
        return self._autopilot.writes_items_as_they_arrive

    @property
    def uploading(self) -> bool:
        return self._upload is not None

    def count(self) -> int:
        """The number of items a MISSION_REQUEST_LIST answers."""
        return len(self.items)

    def home_known(self) -> None:
        """ArduPilot: home was set; an empty mission now holds home as item 0
        (``AP_Mission::write_home_to_storage``), so MISSION_COUNT says 1."""
        if self.write_through and not self.items:
            self.items = [MissionItem(seq=0, frame=mavlink.MAV_FRAME_GLOBAL, command=mavlink.MAV_CMD_NAV_WAYPOINT)]

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
            log.warning("mission upload timed out waiting for item %d of %d", up.received, up.count)
            if self.write_through:
                self.hooks.text("Mission upload timeout", up.peer)
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
        if up is not None and (up.peer != peer or up.target != src):
            # ArduPilot denies a second uploader; PX4 says it is busy.
            self._ack(peer, src, mavlink.MAV_MISSION_DENIED if self.write_through else mavlink.MAV_MISSION_ERROR,
                      MISSION)
            return
        if up is not None and not self.write_through and up.count == msg.count and up.received == 0:
            # PX4: our MISSION_REQUEST was lost; ask again.
            self._request_next(up)
            return
        if msg.count > self.capacity:
            self._ack(peer, src, mavlink.MAV_MISSION_NO_SPACE, MISSION)
            return
        if up is not None:
            log.info("mission upload restarted by a new MISSION_COUNT")
        self._upload = None
        self._done = None
        if self.write_through and msg.count < len(self.items):
            # ArduPilot truncates the live mission to the new length at once.
            self.items = self.items[:msg.count]
            self.hooks.on_change(list(self.items), frozenset())
        if msg.count == 0:
            self._complete(_Upload(peer=peer, target=src, count=0))
            return
        self._upload = _Upload(peer=peer, target=src, count=int(msg.count))
        self._request_next(self._upload)

    def _on_item(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        if getattr(msg, "mission_type", MISSION) != MISSION:
            return
        up = self._upload
        if up is None:
            done = self._done
            if self.write_through:
                self._ack(peer, src, mavlink.MAV_MISSION_ERROR, MISSION)  # ArduPilot: not receiving
            elif done and done.peer == peer and msg.seq == done.count - 1 and self._clock() < done.until:
                self._ack(peer, src, done.result, MISSION)
            else:
                self._ack(peer, src, mavlink.MAV_MISSION_ERROR, MISSION)
            return
        if peer != up.peer or src != up.target:
            if self.write_through:
                self._ack(peer, src, mavlink.MAV_MISSION_DENIED, MISSION)
            return
        expected = up.received
        if msg.seq != expected:
            if self.write_through:
                self._ack(peer, src, mavlink.MAV_MISSION_INVALID_SEQUENCE, MISSION)
            elif msg.seq == expected - 1:
                self._request_next(up)  # PX4 ignores an unexpected item; ask again for ours
            return
        try:
            item = MissionItem.from_message(msg)
        except ValueError:
            self._fail(up, mavlink.MAV_MISSION_INVALID)
            return
        problem = self.hooks.problem(item)
        if problem is not None:
            log.warning("mission item %d refused: %s", item.seq, problem[1])
            self._fail(up, problem[0])
            return
        up.received += 1
        up.retries = 0
        up.items.append(item)
        if self.write_through:
            kept = self.hooks.stored(item)
            if item.seq < len(self.items):
                self.items[item.seq] = kept
            else:
                self.items.append(kept)
            self.hooks.on_change(list(self.items), frozenset({item.seq}))
        if up.received < up.count:
            self._request_next(up)
            return
        self._upload = None
        self._complete(up)

    def _request_next(self, up: _Upload) -> None:
        up.deadline = self._clock() + self.item_timeout_s
        if self.write_through:
            # ArduPilot asks with the legacy MISSION_REQUEST and takes MISSION_ITEM_INT back.
            msg = mavlink.MAVLink_mission_request_message(up.target[0], up.target[1], up.received, MISSION)
        else:
            msg = mavlink.MAVLink_mission_request_int_message(up.target[0], up.target[1], up.received, MISSION)
        self._send(msg, up.peer)

    def _complete(self, up: _Upload) -> None:
        self.hooks.on_accepted(list(up.items))
        if not self.write_through:
            self.items = [self.hooks.stored(item) for item in up.items]
            self.hooks.on_commit(list(self.items))
        else:
            self.hooks.text("Flight plan received", up.peer)
        self.uploads_accepted += 1
        self._done = _Done(up.peer, up.target, up.count, mavlink.MAV_MISSION_ACCEPTED,
                           self._clock() + 10 * self.item_timeout_s)
        self._ack(up.peer, up.target, mavlink.MAV_MISSION_ACCEPTED, MISSION)

    def _fail(self, up: _Upload, result: int) -> None:
        self._upload = None
        self.uploads_failed += 1
        self._done = _Done(up.peer, up.target, up.count, result, self._clock() + 10 * self.item_timeout_s)
        self._ack(up.peer, up.target, result, MISSION)

    def _ack(self, peer: Hashable, target: tuple[int, int], result: int, mission_type: int) -> None:
        if self.write_through:
            self._send(mavlink.MAVLink_mission_ack_message(target[0], target[1], result, mission_type), peer)
            return
        # PX4 returns the mission's id in the ACK that accepts it (and repeats it)
        opaque = self._id() if result == mavlink.MAV_MISSION_ACCEPTED and mission_type == MISSION else 0
        self._send(MissionAck(target[0], target[1], result, mission_type, opaque), peer)

    def _id(self) -> int:
        return px4_mission_id(self.items)

    # --- download, clear, set current --------------------------------------------------------
    def _on_request_list(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if self.write_through and self._upload is not None:
            self._ack(peer, src, mavlink.MAV_MISSION_DENIED, mission_type)
            return
        # Fences and rally points are not kept: report none rather than leave a ground
        # station (QGroundControl asks for all three) waiting.
        count = self.count() if mission_type == MISSION else 0
        if self.write_through:
            self._send(mavlink.MAVLink_mission_count_message(src[0], src[1], count, mission_type), peer)
        else:  # PX4 names the mission it sends
            self._send(MissionCount(src[0], src[1], count, mission_type, self._id() if mission_type == MISSION else 0),
                       peer)

    def _on_request(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if mission_type != MISSION:
            self._ack(peer, src, mavlink.MAV_MISSION_INVALID_SEQUENCE, mission_type)
            return
        if self._upload is not None:
            if self.write_through:
                self._ack(peer, src, mavlink.MAV_MISSION_DENIED, MISSION)
            return  # PX4: our own upload partner cannot be asking
        item = self._download_item(int(msg.seq))
        if item is None:
            if self.write_through:
                # ArduPilot educates the ground station about the real size first.
                self._send(mavlink.MAVLink_mission_count_message(src[0], src[1], self.count(), MISSION), peer)
                self._ack(peer, src, mavlink.MAV_MISSION_ERROR, MISSION)
            else:
                self._ack(peer, src, mavlink.MAV_MISSION_INVALID_SEQUENCE, MISSION)
            return
        if msg.get_type() == "MISSION_REQUEST":
            self._send(item.to_legacy_message(src[0], src[1]), peer)
        else:
            self._send(item.to_message(src[0], src[1]), peer)

    def _download_item(self, seq: int) -> MissionItem | None:
        if self.write_through and seq == 0:
            home = self.hooks.home_item()  # "always allow HOME to be read"
            if home is not None:
                return MissionItem(**{**home.__dict__, "current": self.hooks.current_flag(0)})
        if not 0 <= seq < len(self.items):
            return None
        item = self.items[seq]
        return MissionItem(**{**item.__dict__, "seq": seq, "current": self.hooks.current_flag(seq)})

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
        if self.write_through:
            # ArduPilot: no clearing during an upload or while the mission runs.
            if self._upload is not None or not self.hooks.can_clear():
                self._ack(peer, src, mavlink.MAV_MISSION_ERROR, mission_type)
                return
            self.items = []
            self.hooks.on_change([], frozenset())
        else:
            self._upload = None
            self.items = []
            self.hooks.on_commit([])
        self._ack(peer, src, mavlink.MAV_MISSION_ACCEPTED, mission_type)

    def _on_set_current_msg(self, msg: Any, peer: Hashable, src: tuple[int, int]) -> None:
        self.hooks.on_set_current(int(msg.seq), peer)
