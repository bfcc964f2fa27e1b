"""The pymavlink backend: a reader thread turns bytes into messages and hands each to the
event loop (``call_soon_threadsafe``); everything else (uploads, commands, heartbeats,
the link watchdog) runs on the loop and never blocks it: UDP sends do not block, and the
mission protocol waits with ``asyncio.wait_for`` on a queue.

Reconnect: the reader reopens the connection after a socket error (TCP); over UDP a
silent vehicle (no message at all from it) is "lost" after ``link_timeout_s`` and
"restored" on its next message (our heartbeats keep going, so a ``udpin`` vehicle learns
our address again). Any message counts, not only heartbeats: at 20 % loss three heartbeats
in a row go missing every couple of minutes, the telemetry stream never does.

Which mission a report is about: the mission protocol runs on the reader's order (each
message is fed to the upload or download state machine as it is handed over), and the
MISSION_ACK that accepts an upload starts a new ``generation``. A MISSION_CURRENT or
MISSION_ITEM_REACHED the vehicle sent before that ACK but that arrives after it (a delayed
or reordered datagram) is not about the new one: the MAVLink packet sequence number
(mod 256) says which was sent first, within ``REORDER_WINDOW_S`` of the ACK. A
MISSION_ITEM_REACHED sent before the ACK is passed on with the previous mission's
generation (a point completed just before the new mission replaced it is a service all the
same); a MISSION_CURRENT sent before it is dropped, since an autopilot may announce the
new mission's current item just before acking it (the stub does). Between our sending the
last item and the end of the upload the vehicle may already fly the new mission: reports
of that span are held back and sorted by the ACK's sequence number when it comes (all
about the old mission if the upload fails; dropped if only a read-back could tell).

A vehicle restart shows as its clock (time_boot_ms) going back by more than reordering can
explain: a "restarted" event and a new generation (its mission is gone or stale).

Signing (``signing_key_file``): one ``protocol.signing.Signer`` for the link's life, attached
to every connection it opens, so the timestamp keeps growing across reopens and restarts;
messages from the vehicle that are unsigned or wrongly signed are dropped, counted, and
named in the errors when the vehicle does not answer.
"""

from __future__ import annotations

import asyncio
import logging
import os
import threading
import time
from typing import Any, Callable, Sequence

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from protocol import MissionItem, same_mission  # noqa: E402
from protocol.errors import SigningError  # noqa: E402
from protocol.signing import Signer, TimestampStore, default_timestamp_path, load_key  # noqa: E402

from ..errors import LinkError  # noqa: E402
from .base import ClockRate, LinkEvent, LinkSettings, Telemetry, VehicleLink, mode_name  # noqa: E402
from .rtt import RetryTimer  # noqa: E402
from .upload import MissionDownload, MissionUpload, cancel_message  # noqa: E402

M = mavutil.mavlink
log = logging.getLogger(__name__)
AIRBORNE_STATES = frozenset({M.MAV_LANDED_STATE_IN_AIR, M.MAV_LANDED_STATE_TAKEOFF, M.MAV_LANDED_STATE_LANDING})
MISSION_REPLIES = frozenset({"MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_COUNT",
                             "MISSION_ITEM_INT"})
REORDER_WINDOW_S = 1.0
"""A datagram sent before another arrives after it only within this much wall time."""
RESTART_SLACK_S = 2.0
"""Wall seconds (times the vehicle's clock rate) by which its clock must go back to count
as a restart rather than a reordered datagram."""
SIGNING_WARN_S = 10.0
"""Least time between two warnings about dropped (wrongly signed or unsigned) messages."""


def result_name(code: int) -> str:
    entry = M.enums["MAV_RESULT"].get(code)
    return entry.name if entry is not None else f"MAV_RESULT {code}"


class PymavlinkLink(VehicleLink):
    def __init__(self, settings: LinkSettings, on_event: Callable[[LinkEvent], None]) -> None:
        super().__init__(settings, on_event)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._conn: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._target = (1, 1)
        self._last_heard = 0.0
        self._lost = False
        self._connected = asyncio.Event()
        self._mission_op: MissionUpload | MissionDownload | None = None
        self._mission_moved = asyncio.Event()
        """Set when the operation in progress sent something or ended."""
        self._mark: tuple[int, float] | None = None
        """(packet seq, monotonic time) of the message that began this generation."""
        self._commit_possible = False
        """An upload's last item went out: the vehicle may hold either mission until it ends."""
        self._unsorted: list[Any] = []
        self._generation_on_download = True
        """Progress reports that came while ``_commit_possible``: sorted when the upload ends."""
        self._boot_s: float | None = None
        """The vehicle's clock (time_boot_ms, s): the latest reading."""
        self._acks: dict[int, asyncio.Future[int]] = {}
        self._mission_lock = asyncio.Lock()
        self._command_lock = asyncio.Lock()
        self._tasks: list[asyncio.Task[None]] = []
        self._clock_rate = ClockRate()
        self._signer: Signer | None = None
        self._warned_drops = 0
        self._warned_at = -SIGNING_WARN_S
        self.timer = RetryTimer(settings.item_timeout_s)
        """Wait before repeating a mission message or a command: the measured round trip."""

    # --- lifecycle ------------------------------------------------------------------------
    async def connect(self, timeout_s: float) -> None:
        self._loop = asyncio.get_running_loop()
        if self.settings.signing_key_file and self._signer is None:
            self._signer = self._open_signer()
        self._thread = threading.Thread(target=self._reader, name="mavlink-reader", daemon=True)
        self._thread.start()
        self._tasks.append(asyncio.create_task(self._heartbeats(), name="mavlink-heartbeats"))
        try:
            await asyncio.wait_for(self._connected.wait(), timeout_s)
        except TimeoutError:
            raise LinkError("connect", f"no autopilot heartbeat at {self.settings.url} within {timeout_s:g} s"
                            f"{self.signing_hint()}") from None

    async def close(self) -> None:
        self._stop.set()
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 2.0)
        conn, self._conn = self._conn, None
        if conn is not None:
            conn.close()
        signer, self._signer = self._signer, None
        if signer is not None:
            try:
                signer.close()
            except SigningError as err:
                log.error("signing timestamp not stored: %s", err)
            log.info("signing: %s", signer.stats.summary())

    def _open_signer(self) -> Signer:
        s = self.settings
        try:
            key = load_key(s.signing_key_file)
            stamps = s.signing_timestamp_file or default_timestamp_path(s.signing_key_file, "service")
            return Signer(key, TimestampStore(stamps))
        except SigningError as err:
            raise LinkError("connect", f"signing: {err}") from None

    def _open(self) -> Any:
        s = self.settings
        kwargs: dict[str, Any] = {"source_system": s.source_system, "source_component": s.source_component}
        if s.url.startswith("tcp:"):
            kwargs["autoreconnect"] = True
        conn = mavutil.mavlink_connection(s.url, **kwargs)
        if self._signer is not None:
            self._signer.attach(conn.mav)  # before anything is sent on it
        return conn

    def signing_hint(self) -> str:
        """Why the vehicle may be silent or deaf, as far as signing tells ('' without signing)."""
        signer = self._signer
        if signer is None:
            return ""
        dropped = signer.stats.dropped
        bad = dropped.get("bad signature", 0)
        if bad:
            return (f" (signing: {bad} messages with a bad signature dropped, the last {signer.last_drop}: the vehicle "
                    f"signs with another key than {self.settings.signing_key_file})")
        if dropped.get("unsigned", 0):
            return (f" (signing: {dropped['unsigned']} unsigned messages dropped: the vehicle does not sign; give it "
                    f"the key in {self.settings.signing_key_file})")
        return (" (signing is on: a vehicle with another key or without signing ignores our messages; check that it "
                f"holds the key in {self.settings.signing_key_file})")

    def _reader(self) -> None:
        """Reader thread: messages to the loop; reopen the connection after an error."""
        backoff = 0.2
        while not self._stop.is_set():
            conn = self._conn
            if conn is None:
                try:
                    conn = self._conn = self._open()
                    backoff = 0.2
                except (OSError, ValueError):
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, 2.0)
                    continue
            try:
                msg = conn.recv_match(blocking=True, timeout=0.05)
            except (OSError, ValueError):
                self._conn = None
                try:
                    conn.close()
                except OSError:
                    pass
                continue
            if msg is None or msg.get_type() == "BAD_DATA" or self._stop.is_set():
                continue
            try:
                self._loop.call_soon_threadsafe(self._on_message, msg)  # type: ignore[union-attr]
            except RuntimeError:  # the loop closed under us: shutting down
                return

    def _send(self, msg: Any) -> None:
        conn = self._conn
        if conn is None:
            raise LinkError("send", f"{msg.get_type()}: the connection is not open")
        try:
            conn.mav.send(msg)
        except OSError as err:
            raise LinkError("send", f"{msg.get_type()}: {err}") from None

    async def _heartbeats(self) -> None:
        """Our heartbeat at 1 Hz (a udpin vehicle answers the last peer heard), the link
        watchdog, and the signing timestamp's upkeep."""
        while True:
            self._signing_upkeep()
            if self._conn is not None:
                try:
                    self._conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                except OSError:
                    pass
            silent = time.monotonic() - self._last_heard
            if self._connected.is_set() and not self._lost and silent > self.settings.link_timeout_s:
                self._lost = True
                self._set(connected=False)
                self.on_event(LinkEvent("lost", text=f"nothing heard from the autopilot for {silent:.1f} s"))
            await asyncio.sleep(0.5 if not self._connected.is_set() else 1.0)

    def _signing_upkeep(self) -> None:
        """On the loop's thread, the one that signs: advance the timestamp (and its stored
        reservation); warn when messages are being dropped for their signature."""
        signer = self._signer
        if signer is None:
            return
        try:
            signer.tick()
        except SigningError as err:
            log.error("signing timestamp not stored (a restart could reuse timestamps): %s", err)
        total = signer.stats.dropped_total
        now = time.monotonic()
        if total > self._warned_drops and now - self._warned_at >= SIGNING_WARN_S:
            log.warning("%d messages from the link dropped for their signature%s", total - self._warned_drops,
                        self.signing_hint())
            self._warned_drops, self._warned_at = total, now

    # --- incoming -------------------------------------------------------------------------
    def _set(self, **changes: Any) -> None:
        self.telemetry = Telemetry(**{**self.telemetry.__dict__, **changes})

    def _fresh(self, msg: Any) -> bool:
        """Was ``msg`` sent after the message that began the current generation?"""
        if self._mark is None:
            return True
        seq, at = self._mark
        if time.monotonic() - at > REORDER_WINDOW_S:
            self._mark = None
            return True
        return 0 < (msg.get_seq() - seq) % 256 < 128

    def _new_generation(self, msg: Any | None) -> None:
        self.generation += 1
        self._mark = (msg.get_seq(), time.monotonic()) if msg is not None else None

    def _on_message(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.autopilot == M.MAV_AUTOPILOT_INVALID or msg.get_srcComponent() != 1:
                return  # another ground station or a component that is not the autopilot
            source = (msg.get_srcSystem(), msg.get_srcComponent())
            if self._connected.is_set() and source != self._target:
                # Another vehicle on the same network: the link stays with the first
                # autopilot heard. Following it would show that vehicle's state as ours,
                # and its landing would end our sortie.
                return
            self._target = source
            armed = bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)
            mode = mode_name(self.settings.flavour, msg.custom_mode)
            old_mode = self.telemetry.mode
            self._set(armed=armed, mode=mode, connected=True)
            self._heard()
            if not self._connected.is_set():
                self._connected.set()
                self.on_event(LinkEvent("connected", text=mode))
            if old_mode and mode != old_mode:
                self.on_event(LinkEvent("mode", text=mode))
            return
        if msg.get_srcSystem() != self._target[0]:
            return
        if self._connected.is_set():
            self._heard()
        if kind in MISSION_REPLIES:
            self._on_mission_reply(msg)
        elif kind == "COMMAND_ACK":
            future = self._acks.get(msg.command)
            if future is not None and not future.done():
                future.set_result(int(msg.result))
        elif kind == "GLOBAL_POSITION_INT":
            self._check_clock(msg.time_boot_ms / 1e3)
            rate = self._clock_rate.update(msg.time_boot_ms / 1e3, time.monotonic())
            self._set(valid=True, lat_deg=msg.lat / 1e7, lon_deg=msg.lon / 1e7, rel_alt_m=msg.relative_alt / 1e3,
                      time_rate=rate, position_at=time.monotonic())
        elif kind == "BATTERY_STATUS":
            changes: dict[str, Any] = {"battery_at": time.monotonic()}
            if msg.energy_consumed >= 0:
                changes["energy_used_j"] = msg.energy_consumed * 100.0  # hJ -> J
            if msg.battery_remaining >= 0:
                changes["battery_fraction"] = msg.battery_remaining / 100.0
            self._set(**changes)
        elif kind == "SYS_STATUS" and msg.battery_remaining >= 0 and self.telemetry.energy_used_j is None:
            self._set(battery_fraction=msg.battery_remaining / 100.0, battery_at=time.monotonic())
        elif kind == "EXTENDED_SYS_STATE":
            airborne = msg.landed_state in AIRBORNE_STATES
            was = self.telemetry.airborne
            self._set(airborne=airborne, landed_known=True)
            if was and msg.landed_state == M.MAV_LANDED_STATE_ON_GROUND:
                self.on_event(LinkEvent("landed"))
        elif kind in ("MISSION_CURRENT", "MISSION_ITEM_REACHED"):
            if self._commit_possible:
                self._unsorted.append(msg)  # about either mission: the ACK's sequence number will say
            elif self._fresh(msg):
                self._report(msg, self.generation)
            elif kind == "MISSION_ITEM_REACHED":
                self._report(msg, self.generation - 1)
            # else a MISSION_CURRENT sent before the ACK: about either mission (below)
        elif kind == "STATUSTEXT":
            self.on_event(LinkEvent("text", text=str(msg.text)))

    def _report(self, msg: Any, mission: int) -> None:
        """A progress report about ``mission`` (a generation): the current one updates the
        telemetry; the one before is passed on too, since the points it completed just
        before a new mission replaced it are services all the same."""
        if msg.get_type() == "MISSION_ITEM_REACHED":
            self.on_event(LinkEvent("reached", seq=int(msg.seq), mission=mission))
            return
        raw = int(getattr(msg, "total", 0) or 0)
        # MAVLink: 0 when the autopilot does not say, UINT16_MAX when it has no mission.
        total = -1 if raw == 0 else 0 if raw == 0xFFFF else raw
        if mission != self.generation:
            self.on_event(LinkEvent("current", seq=int(msg.seq), total=total, mission=mission))
            return
        changed = (msg.seq, total) != (self.telemetry.mission_seq, self.telemetry.mission_total)
        self._set(mission_seq=int(msg.seq), mission_total=total)
        if changed:
            self.on_event(LinkEvent("current", seq=int(msg.seq), total=total, mission=mission))

    def _sort_reports(self, ack: Any | None, total: int = 0) -> None:
        """Pass on the reports held back while an upload could commit: a MISSION_ITEM_REACHED
        the vehicle sent before the ``ack`` that accepted it (packet sequence, mod 256) is
        about the mission before; what it sent after, about the new one (of ``total``
        items). A MISSION_CURRENT sent before the ACK is about either (an autopilot may
        announce the new mission's current item just before it acks it): dropped, the
        stream repeats it. Without an ACK (the upload failed) all are about the mission the
        vehicle kept."""
        held, self._unsorted = self._unsorted, []
        if ack is None:
            for msg in held:
                self._report(msg, self.generation)
            return
        before = [m for m in held if 0 < (ack.get_seq() - m.get_seq()) % 256 < 128]
        for msg in before:
            if msg.get_type() == "MISSION_ITEM_REACHED":
                self._report(msg, self.generation)
        self._new_generation(ack)
        self._set(mission_seq=0, mission_total=total)
        for msg in held:
            if msg not in before:
                self._report(msg, self.generation)

    def _heard(self) -> None:
        self._last_heard = time.monotonic()
        if self._lost:
            self._lost = False
            self._set(connected=True)
            self.on_event(LinkEvent("restored", text=self.telemetry.mode))

    def _check_clock(self, boot_s: float) -> None:
        """A restart: the vehicle's clock went back further than reordering explains."""
        last = self._boot_s
        if last is not None and boot_s < last - RESTART_SLACK_S * max(self.telemetry.time_rate, 1.0):
            self._boot_s = boot_s
            self._new_generation(None)
            self._set(mission_seq=0, mission_total=0)
            self.on_event(LinkEvent("restarted", text=f"its clock went back from {last:.1f} s to {boot_s:.1f} s"))
            return
        self._boot_s = boot_s if last is None else max(last, boot_s)

    def _on_mission_reply(self, msg: Any) -> None:
        """Feed the upload or download in progress, in the order messages arrived."""
        op = self._mission_op
        if op is None or op.done is not None:
            return
        sent = op.sent
        done = op.on_message(msg)
        self._note_commit_possible(op)
        if done is not None and isinstance(op, MissionUpload) and done.accepted:
            # Accepted: from this message on the vehicle's reports are about the new mission.
            self._sort_reports(msg, len(op.items))
        elif done is not None and isinstance(op, MissionDownload) and done.ok and self._generation_on_download:
            self._new_generation(msg)
            self._set(mission_seq=-1, mission_total=-1)  # the next MISSION_CURRENT is news
        if done is not None or op.sent != sent:
            self._mission_moved.set()

    # --- operations -------------------------------------------------------------------------
    async def _run(self, op: MissionUpload | MissionDownload) -> Any:
        """Run a mission operation to its end: repeats on silence, each wait measured from
        the last message we sent. Abandoned (cancelled) uploads are cancelled on the
        vehicle too."""
        self._mission_op = op
        self._mission_moved.clear()
        try:
            op.begin()
            sent_at, repeated = time.monotonic(), False
            while op.done is None:
                try:
                    await asyncio.wait_for(self._mission_moved.wait(), self.timer.timeout_s)
                    now = time.monotonic()
                    if not repeated:
                        self.timer.sample(now - sent_at)
                    sent_at, repeated = now, False
                except TimeoutError:
                    op.on_timeout()
                    self._note_commit_possible(op)
                    sent_at, repeated = time.monotonic(), True
                self._mission_moved.clear()
            return op.done
        finally:
            self._mission_op = None
            if isinstance(op, MissionUpload) and (op.done is None or not op.done.accepted) and op.sent:
                self._cancel_upload()

    def _note_commit_possible(self, op: MissionUpload | MissionDownload) -> None:
        if isinstance(op, MissionUpload) and op.last_sent == len(op.items) - 1 and op.done is None:
            self._commit_possible = True

    def _cancel_upload(self) -> None:
        for _ in range(2):  # best effort: either copy may be lost
            try:
                self._send(cancel_message(self._target))
            except LinkError:
                return

    async def upload(self, items: Sequence[MissionItem]) -> None:
        async with self._mission_lock:
            if not self._connected.is_set() or self._lost:
                raise LinkError("upload_mission()", f"NO_LINK: the autopilot is not connected{self.signing_hint()}")
            try:
                await self._upload(items)
            finally:
                self._commit_possible = False
                self._sort_reports(None)  # left over: the upload failed, the vehicle kept its mission

    async def _upload(self, items: Sequence[MissionItem]) -> None:
        done = await self._run(MissionUpload(items, self._send, self._target, self.settings.retries))
        if done.accepted:
            return
        if not done.maybe_committed:
            hint = self.signing_hint() if done.result.startswith("NO_ANSWER") else ""
            raise LinkError("upload_mission()", done.result + hint)
        # Every item went out and only the ACK is missing: the vehicle may hold the new
        # mission. Read it back rather than assume either way.
        try:
            held = await self._download(new_generation=False)
        except LinkError as err:
            self._unsorted.clear()  # about either mission: nobody can tell
            raise LinkError("upload_mission()", f"{done.result}; reading the mission back failed too "
                            f"({err.result}): the vehicle may hold either mission", outcome_unknown=True) from None
        if same_mission(held, items, self.settings.flavour):  # type: ignore[arg-type]
            self._unsorted.clear()  # about either mission, sent while it committed
            self._new_generation(None)
            self._set(mission_seq=-1, mission_total=-1)  # the next MISSION_CURRENT is news
            return
        raise LinkError("upload_mission()", f"{done.result}; the vehicle kept its previous mission (read back)")

    async def download(self) -> list[MissionItem]:
        async with self._mission_lock:
            if not self._connected.is_set() or self._lost:
                raise LinkError("download_mission()", f"NO_LINK: the autopilot is not connected{self.signing_hint()}")
            return await self._download()

    async def _download(self, *, new_generation: bool = True) -> list[MissionItem]:
        """Read the mission back; with ``new_generation`` the vehicle's reports from then on
        count as about what was read (an upload's read-back decides that itself)."""
        self._generation_on_download = new_generation
        done = await self._run(MissionDownload(self._send, self._target, self.settings.retries))
        if not done.ok:
            raise LinkError("download_mission()", done.result)
        return list(done.items)

    async def command(self, command: int, *params: float, what: str) -> None:
        """COMMAND_LONG with the confirmation counting up on each repeat."""
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        async with self._command_lock:
            assert self._loop is not None
            for confirmation in range(self.settings.retries):
                future: asyncio.Future[int] = self._loop.create_future()
                self._acks[command] = future
                try:
                    sent_at = time.monotonic()
                    self._send(M.MAVLink_command_long_message(*self._target, command, confirmation, *p))
                    result = await asyncio.wait_for(future, self.timer.timeout_s)
                    if confirmation == 0:
                        self.timer.sample(time.monotonic() - sent_at)
                except TimeoutError:
                    continue
                finally:
                    self._acks.pop(command, None)
                if result in (M.MAV_RESULT_ACCEPTED, M.MAV_RESULT_IN_PROGRESS):
                    return
                raise LinkError(what, result_name(result))
            raise LinkError(what, f"NO_ANSWER after {self.settings.retries} tries{self.signing_hint()}")

    async def start(self) -> None:
        await self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1, what="arm()")
        await self.resume()

    async def resume(self) -> None:
        if self.settings.flavour == "px4":
            await self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 4, what="set_mode(AUTO.MISSION)")
        else:
            await self.command(M.MAV_CMD_DO_SET_MODE, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 3, what="set_mode(AUTO)")
        await self.command(M.MAV_CMD_MISSION_START, 0, 0, what="start_mission()")

    async def return_to_launch(self) -> None:
        await self.command(M.MAV_CMD_NAV_RETURN_TO_LAUNCH, what="return_to_launch()")

