"""The pymavlink backend: a reader thread turns bytes into messages and hands each to the
event loop (``call_soon_threadsafe``); everything else (uploads, commands, heartbeats,
the link watchdog, the telemetry requests) runs on the loop and never blocks it: sends do
not block, and the mission protocol waits with ``asyncio.wait_for`` on a queue.

Connections that survive (TCP, UDP, serial): the reader owns the connection and reopens
it after any failure, with a back-off; nothing that comes off the wire or out of pymavlink
ends the thread. pymavlink's own TCP reconnect is not used (it dies inside
``reconnect`` with ``AttributeError: 'NoneType' object has no attribute 'close'`` when the
autopilot restarts): an end of stream or a reset raises, the reader reports the link
``Lost`` at once and reconnects. Over UDP a silent vehicle (no message at all from it) is
lost after ``link_timeout_s`` and restored on its next message (our heartbeats keep going,
so a ``udpin`` vehicle learns our address again). Any message counts, not only
heartbeats: at 20 % loss three heartbeats in a row go missing every couple of minutes,
the telemetry stream never does. After every (re)connection the telemetry is asked for
again (``streams``): a restarted ArduPilot streams nothing until asked.

Which mission a report is about: the mission protocol runs on the reader's order (each
message is fed to the upload or download state machine as it is handed over), and the
MISSION_ACK that accepts an upload starts a new ``generation``; the pure ``reports``
module sorts MISSION_CURRENT and MISSION_ITEM_REACHED between missions by their MAVLink
packet sequence number, and this link applies what it decides.

Trust: only the autopilot's own (system, component) counts (``state.VehicleState``), for
telemetry, mission replies, reports and COMMAND_ACKs alike.

Signing (``signing_key_file``): one ``protocol.signing.Signer`` for the link's life, attached
to every connection it opens, so the timestamp keeps growing across reopens and restarts;
messages that are unsigned, wrongly signed or replayed are dropped, counted, and told by
reason (a replay as a replay, a forgery as a forgery: ``protocol.signing.Drop``) in a
warning and in the errors when the vehicle does not answer.
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
from .base import CURRENT_WAIT_S, LinkSettings, VehicleLink  # noqa: E402
from .events import Current, LinkEvent, Reached  # noqa: E402
from .extensions import (MISSION_ACK_ID_OFFSET, MISSION_COUNT_ID_OFFSET, MISSION_CURRENT_ID_OFFSET,  # noqa: E402
                         extension_u32)
from .progress import mission_progress  # noqa: E402
from .reports import Begin, Pass, ReportSequencer  # noqa: E402
from .rtt import RetryTimer  # noqa: E402
from .streams import INTERVAL_CMD, QUIET_INTERVAL_US, Request  # noqa: E402
from .udp_peers import safe_peers  # noqa: E402
from .upload import MissionDownload, MissionUpload, cancel_message  # noqa: E402

M = mavutil.mavlink
log = logging.getLogger(__name__)
MISSION_REPLIES = frozenset({"MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK", "MISSION_COUNT",
                             "MISSION_ITEM_INT"})
SIGNING_WARN_S = 10.0
"""Least time between two warnings about dropped (wrongly signed or unsigned) messages."""
REFUSAL_TEXT_WAIT_S = 0.3
"""After a refused command, wait this long for the STATUSTEXT that says why."""
STREAM_RETRIES = 2
"""Tries of one SET_MESSAGE_INTERVAL before falling back (an autopilot that never answers
must not hold the other requests up)."""
BACKOFF_S = (0.2, 2.0)
"""Reopening a failed connection: first and longest wait."""
REFUSED = frozenset({M.MAV_RESULT_DENIED, M.MAV_RESULT_UNSUPPORTED, M.MAV_RESULT_FAILED})


def result_name(code: int) -> str:
    entry = M.enums["MAV_RESULT"].get(code)
    return entry.name if entry is not None else f"MAV_RESULT {code}"


class _Closed(ConnectionResetError):
    """The TCP peer closed or reset the connection."""


def _raise_closed() -> None:
    raise _Closed("connection closed by the autopilot")


class PymavlinkLink(VehicleLink):
    def __init__(self, settings: LinkSettings, on_event: Callable[[LinkEvent], None]) -> None:
        super().__init__(settings, on_event)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._conn: Any = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._target = (1, 1)
        self._connected = asyncio.Event()
        self._mission_op: MissionUpload | MissionDownload | None = None
        self._mission_moved = asyncio.Event()
        """Set when the operation in progress sent something or ended."""
        self.reports: ReportSequencer[Any] = ReportSequencer()
        """Which mission each progress report is about (pure; ``reports``)."""
        self._generation_on_download = True
        self._acks: dict[int, asyncio.Future[int]] = {}
        self._mission_lock = asyncio.Lock()
        self._command_lock = asyncio.Lock()
        self._tasks: list[asyncio.Task[None]] = []
        self._streams_task: asyncio.Task[None] | None = None
        self._reopened = False
        """The connection was (re)opened: ask for telemetry at the next heartbeat."""
        self._signer: Signer | None = None
        self._warned_drops = 0
        self._warned_by_reason: dict[str, int] = {}
        """Drops by reason as of the last warning: the next one tells only what came since."""
        self._warned_at = -SIGNING_WARN_S
        self.timer = RetryTimer(settings.item_timeout_s)
        """Wait before repeating a mission message or a command: the measured round trip."""
        self.state.request_streams = self._request_streams
        self.state.on_restart = self._on_restart

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
            if self.state.wrong_autopilot:
                raise LinkError("connect", self.state.wrong_autopilot) from None
            raise LinkError("connect", f"no autopilot heartbeat at {self.settings.url} within {timeout_s:g} s"
                            f"{self.signing_hint()}") from None

    async def close(self) -> None:
        self._stop.set()
        tasks = [*self._tasks, *([self._streams_task] if self._streams_task is not None else [])]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        if self._thread is not None:
            await asyncio.to_thread(self._thread.join, 2.0)
        conn, self._conn = self._conn, None
        if conn is not None:
            _close_quietly(conn)
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
        tcp = s.url.startswith("tcp:")
        if tcp:
            kwargs.update(autoreconnect=False, retries=0)  # we reconnect ourselves (see the module's notes)
        conn = mavutil.mavlink_connection(s.url, **kwargs)
        safe_peers(conn)  # udpin: the reader adds peers while a send iterates them
        if tcp:
            # pymavlink only prints on an end of stream and returns b"" for ever after:
            # raise instead, so the reader sees the autopilot go and reconnects.
            conn.handle_eof = conn.handle_disconnect = _raise_closed
        if self._signer is not None:
            self._signer.attach(conn.mav)  # before anything is sent on it
        return conn

    def signing_hint(self, told: dict[str, int] | None = None) -> str:
        """Why the vehicle may be silent or deaf, as far as signing tells ('' without signing):
        the messages dropped by reason (beyond the counts in ``told``), each with its latest
        packet and what that reason means. A replay is named a replay and a forgery a
        forgery: only a bad signature from a sender none of whose messages pass points to the
        key (they blamed the key for every drop)."""
        signer = self._signer
        if signer is None:
            return ""
        key = self.settings.signing_key_file
        told = told or {}
        fresh = {r: n - told.get(r, 0) for r, n in sorted(signer.stats.dropped.items()) if n > told.get(r, 0)}
        if not fresh:
            return (" (signing is on: a vehicle with another key or without signing ignores our messages; check that it "
                    f"holds the key in {key})")
        parts = [f"{n} {reason}, the last {signer.last_drops[reason].describe()}" for reason, n in fresh.items()]
        bad = signer.last_drops.get("bad signature")
        if "bad signature" in fresh and bad is not None and not bad.sender_heard:
            parts.append(f"check that the vehicle holds the key in {key}")
        elif "unsigned" in fresh and signer.stats.accepted == 0:
            parts.append(f"give the vehicle the key in {key}")
        return f" (signing: {'; '.join(parts)})"

    def _reader(self) -> None:
        """Reader thread: messages to the loop; reopen the connection after any failure.
        Nothing raised here may end the thread: the link would be dead for ever."""
        backoff = BACKOFF_S[0]
        failed_to_open = ""
        while not self._stop.is_set():
            conn = self._conn
            if conn is None:
                try:
                    conn = self._conn = self._open()
                except Exception as err:  # noqa: BLE001 - any failure to open: try again later
                    if str(err) != failed_to_open:
                        log.info("cannot open %s (%s); trying again", self.settings.url, err)
                        failed_to_open = str(err)
                    self._stop.wait(backoff)
                    backoff = min(backoff * 2, BACKOFF_S[1])
                    continue
                backoff, failed_to_open = BACKOFF_S[0], ""
                self._to_loop(self._on_opened)
            try:
                msg = conn.recv_match(blocking=True, timeout=0.05)
                batch = [msg, *_buffered(conn)] if msg is not None else []
            except Exception as err:  # noqa: BLE001 - a closed socket, a vanished serial device, a pymavlink bug
                self._conn = None
                _close_quietly(conn)
                self._to_loop(self._on_broken, f"{type(err).__name__}: {err}")
                self._stop.wait(backoff)
                continue
            for msg in batch:
                if msg.get_type() == "BAD_DATA" or self._stop.is_set():
                    continue
                if not self._to_loop(self._on_message, msg):
                    return

    def _to_loop(self, fn: Callable[..., None], *args: Any) -> bool:
        try:
            self._loop.call_soon_threadsafe(self._guarded, fn, *args)  # type: ignore[union-attr]
            return True
        except RuntimeError:  # the loop closed under us: shutting down
            return False

    def _guarded(self, fn: Callable[..., None], *args: Any) -> None:
        """Run a handler on the loop; a message that trips a bug is logged and dropped, it
        never stops the link."""
        try:
            fn(*args)
        except Exception:  # noqa: BLE001
            log.exception("link: handling %s failed", args[0].get_type() if args and hasattr(args[0], "get_type")
                          else getattr(fn, "__name__", fn))

    def _on_opened(self) -> None:
        self._reopened = True  # a new TCP connection may reach a new boot: ask again at its heartbeat

    def _on_broken(self, detail: str) -> None:
        log.warning("connection %s broken (%s): reconnecting", self.settings.url, detail)
        self.state.lose(f"connection broken: {detail}")

    def _send(self, msg: Any) -> None:
        conn = self._conn
        if conn is None:
            raise LinkError("send", f"{msg.get_type()}: the connection is not open")
        try:
            conn.mav.send(msg)
        except (OSError, AttributeError) as err:  # AttributeError: pymavlink after its socket went
            raise LinkError("send", f"{msg.get_type()}: {err}") from None

    async def _heartbeats(self) -> None:
        """Our heartbeat at 1 Hz (a udpin vehicle answers the last peer heard), the link
        watchdog, the telemetry bookkeeping and the signing timestamp's upkeep. Never ends
        but by cancellation: a failure in one round is logged and the next goes on."""
        while True:
            try:
                self._signing_upkeep()
                conn = self._conn
                if conn is not None:
                    try:
                        conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                    except (OSError, AttributeError):
                        pass  # the reader sees the broken connection and reopens it
                repeat = self.state.tick()
                if repeat and self._connected.is_set():
                    self._spawn_requests(repeat)
            except Exception:  # noqa: BLE001
                log.exception("link: heartbeat round failed")
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
                        self.signing_hint(self._warned_by_reason))
            self._warned_by_reason = dict(signer.stats.dropped)
            self._warned_drops, self._warned_at = total, now

    # --- telemetry requests -------------------------------------------------------------------
    def _request_streams(self) -> None:
        """Ask for every message the service needs (on connect, reconnect, restart)."""
        if self._loop is None or not self._connected.is_set():
            return
        if self._streams_task is not None and not self._streams_task.done():
            self._streams_task.cancel()
        self._streams_task = asyncio.ensure_future(self._send_requests(self.state.streams.begin()))

    def _spawn_requests(self, requests: list[Request]) -> None:
        if self._streams_task is not None and not self._streams_task.done():
            return  # a round is under way
        self._streams_task = asyncio.ensure_future(self._send_requests(requests))

    async def _send_requests(self, requests: list[Request]) -> None:
        streams = self.state.streams
        groups: dict[int, float] = {}
        for spec in streams.plan:  # a stream group at the highest rate any of its messages needs
            if spec.group is not None:
                groups[spec.group] = max(groups.get(spec.group, 0.0), 1.0 / spec.interval_s)
        for request in requests:
            spec = request.spec
            try:
                if request.kind == "quiet":
                    result = await self._command_result(INTERVAL_CMD, spec.msg_id, QUIET_INTERVAL_US, retries=1)
                    log.debug("%s: stopped (%s)", spec.name, result)
                elif request.kind == "interval":
                    result = await self._command_result(INTERVAL_CMD, spec.msg_id, spec.interval_s * 1e6,
                                                        retries=STREAM_RETRIES)
                    if result != "MAV_RESULT_ACCEPTED":
                        log.info("%s: SET_MESSAGE_INTERVAL refused (%s); falling back", spec.name, result)
                    for fallback in streams.on_interval_result(spec.name, result):
                        await self._send_fallback(fallback, groups)
                else:
                    await self._send_fallback(request, groups)
            except LinkError as err:
                log.debug("telemetry request for %s not sent: %s", spec.name, err)

    async def _send_fallback(self, request: Request, groups: dict[int, float]) -> None:
        spec = request.spec
        if request.kind == "stream" and spec.group is not None:
            rate = max(1, round(groups.get(spec.group, 1.0)))
            self._send(M.MAVLink_request_data_stream_message(*self._target, spec.group, rate, 1))
        else:
            await self._command_result(M.MAV_CMD_REQUEST_MESSAGE, spec.msg_id, retries=1)

    # --- incoming -------------------------------------------------------------------------
    def _new_generation(self, msg: Any | None) -> None:
        self.generation += 1
        self._current = None
        self.reports.begin(msg.get_seq() if msg is not None else None, time.monotonic())

    def _set_progress(self, seq: int, total: int, mission_id: int = 0) -> None:
        self.state.set_progress(seq, total, mission_id)

    def _on_restart(self) -> None:
        self._new_generation(None)

    def _on_message(self, msg: Any) -> None:
        kind = msg.get_type()
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "HEARTBEAT":
            first = self.state.autopilot is None
            if not self.state.on_heartbeat(*source, msg):
                return
            if first:
                self._target = source
                self._connected.set()
                self._reopened = False
                self._request_streams()
            elif self._reopened:
                self._reopened = False
                self._request_streams()
            return
        if kind in MISSION_REPLIES or kind in ("COMMAND_ACK", "MISSION_CURRENT", "MISSION_ITEM_REACHED"):
            if not self.state.trusted(*source):
                return
            self.state.heard()
            self.state.streams.heard(msg.get_msgId())
        elif not self.state.on_message(kind, msg.get_msgId(), *source, msg):
            return
        if kind in MISSION_REPLIES:
            self._on_mission_reply(msg)
        elif kind == "COMMAND_ACK":
            future = self._acks.get(msg.command)
            if future is not None and not future.done():
                future.set_result(int(msg.result))
        elif kind in ("MISSION_CURRENT", "MISSION_ITEM_REACHED"):
            self._apply(self.reports.on_report(msg, kind, msg.get_seq(), time.monotonic()))

    def _report(self, msg: Any, mission: int) -> None:
        """A progress report about ``mission`` (a generation): the current one updates the
        telemetry; the one before is passed on too, since the points it completed just
        before a new mission replaced it are services all the same."""
        if msg.get_type() == "MISSION_ITEM_REACHED":
            if mission == self.generation:
                self.state.current_watch.reached(int(msg.seq))
            if self.state.new_reach(mission, int(msg.seq)):
                self.on_event(Reached(int(msg.seq), mission))
            return
        seq, total = mission_progress(msg)
        if mission != self.generation:
            self.on_event(Current(seq, total, mission))
            return
        if not self.state.current_watch.observe(seq, time.monotonic()):
            return  # another item, not yet confirmed by the vehicle's stream (``progress.CurrentWatch``)
        t = self.telemetry
        mission_id = extension_u32(msg, "mission_id", MISSION_CURRENT_ID_OFFSET)
        changed = (seq, total, mission_id) != (t.mission_seq, t.mission_total, t.mission_id)
        self._set_progress(seq, total, mission_id)
        if seq >= 0:  # an item named: the answer to whoever waits for the index
            self._current = (mission, seq)
            self._current_moved.set()
        if changed:
            self.on_event(Current(seq, total, mission))

    def _apply(self, decisions: Sequence[Pass[Any] | Begin]) -> None:
        """Carry out the sequencer's decisions in order (``reports``)."""
        for decision in decisions:
            if isinstance(decision, Begin):
                self.generation += 1
                self._current = None
                self._set_progress(0, decision.total)
            else:
                self._report(decision.report, self.generation - 1 if decision.before else self.generation)

    def _on_mission_reply(self, msg: Any) -> None:
        """Feed the upload or download in progress, in the order messages arrived."""
        op = self._mission_op
        if op is None or op.done is not None:
            return
        sent = op.sent
        done = op.on_message(msg)
        self._note_commit_possible(op)
        if isinstance(op, MissionDownload) and msg.get_type() == "MISSION_COUNT":
            self.mission_id = extension_u32(msg, "opaque_id", MISSION_COUNT_ID_OFFSET)
        if done is not None and isinstance(op, MissionUpload) and done.accepted:
            # Accepted: from this message on the vehicle's reports are about the new mission.
            self.mission_id = extension_u32(msg, "opaque_id", MISSION_ACK_ID_OFFSET)
            self._apply(self.reports.on_accepted(msg.get_seq(), time.monotonic(), len(op.items)))
        elif done is not None and isinstance(op, MissionDownload) and done.ok and self._generation_on_download:
            self._new_generation(msg)
            self._set_progress(-1, -1)  # the next MISSION_CURRENT is news
        if done is not None or op.sent != sent:
            self._mission_moved.set()

    # --- operations -------------------------------------------------------------------------
    async def _run(self, op: MissionUpload | MissionDownload) -> Any:
        """Run a mission operation to its end: repeats on silence, each wait measured from
        the last message we sent. Abandoned (cancelled) uploads are cancelled on the
        vehicle too."""
        self._mission_op = op
        self.mission_id = 0  # until the vehicle names the mission this operation ends with
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
            self.reports.upload_may_commit()

    def _cancel_upload(self) -> None:
        for _ in range(2):  # best effort: either copy may be lost
            try:
                self._send(cancel_message(self._target))
            except LinkError:
                return

    def _check_link(self, operation: str) -> None:
        if not self._connected.is_set() or self.state.lost:
            raise LinkError(operation, f"NO_LINK: the autopilot is not connected{self.signing_hint()}")

    async def upload(self, items: Sequence[MissionItem], *, current_seq: int | None = None,
                     restart_current: bool = False) -> None:
        if current_seq is not None and not 0 <= current_seq < len(items):
            raise LinkError("upload_mission()", f"current_seq {current_seq} is not an item of the {len(items)}")
        for seq in [current_seq, *(i.seq for i in items if i.current)]:
            if seq is not None:
                self.state.current_watch.expect(seq)  # the vehicle's report of the item asked for is news
        async with self._mission_lock:
            self._check_link("upload_mission()")
            try:
                await self._upload(items)
            finally:
                self._apply(self.reports.on_upload_ended())  # left over: the vehicle kept its mission
            if current_seq is not None:
                await self._ensure_current(current_seq, wait_for_report=True, restart=restart_current)

    async def _upload(self, items: Sequence[MissionItem]) -> None:
        done = await self._run(MissionUpload(items, self._send, self._target, self.settings.retries,
                                               self._patience_s()))
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
            self.reports.forget()  # about either mission: nobody can tell
            raise LinkError("upload_mission()", f"{done.result}; reading the mission back failed too "
                            f"({err.result}): the vehicle may hold either mission", outcome_unknown=True) from None
        if same_mission(held, items, self.settings.flavour):  # type: ignore[arg-type]
            self.reports.forget()  # about either mission, sent while it committed
            self._new_generation(None)
            self._set_progress(-1, -1)  # the next MISSION_CURRENT is news
            return
        raise LinkError("upload_mission()", f"{done.result}; the vehicle kept its previous mission (read back)")

    async def set_current(self, seq: int) -> None:
        async with self._mission_lock:
            self._check_link("set_current()")
            await self._ensure_current(seq, wait_for_report=False)

    async def _ensure_current(self, seq: int, *, wait_for_report: bool, restart: bool = False) -> None:
        """Make the vehicle fly ``seq``: nothing when its MISSION_CURRENT already says so (a
        command would restart the item), else MAV_CMD_DO_SET_MISSION_CURRENT, or the older
        MISSION_SET_CURRENT message where the command is refused or the autopilot's profile
        says it takes only the message (PX4); confirmed from MISSION_CURRENT. ``restart``:
        start the item again where the autopilot would not fly its new content by itself."""
        wait_s = CURRENT_WAIT_S if wait_for_report else 0.0
        seen = await self._wait_current(wait_s)
        if seen == seq and restart and not self.profile.flies_changed_current_item:
            await self._restart_current(seq)
            return
        if seen == seq:
            return
        sent_at = time.monotonic()
        self.state.current_watch.expect(seq)
        use_message = not self.profile.set_current_by_command
        for _ in range(max(self.settings.retries // 3, 2)):
            if not use_message:
                result = await self._command_result(M.MAV_CMD_DO_SET_MISSION_CURRENT, seq, 0,
                                                    retries=max(self.settings.retries // 3, 2))
                if result != "MAV_RESULT_ACCEPTED":
                    log.info("MAV_CMD_DO_SET_MISSION_CURRENT %d: %s; trying MISSION_SET_CURRENT", seq, result)
                    use_message = True  # refused or no answer: the message every autopilot knows
            if use_message:
                self._send(M.MAVLink_mission_set_current_message(*self._target, seq))
            seen = await self._wait_current(CURRENT_WAIT_S, want=seq)
            if seen == seq:
                log.info("mission: current item set to %d", seq)
                return
        raise LinkError("set_current()", f"the vehicle reports item {seen}, not {seq}{await self._refusal_texts(sent_at)}")

    async def _restart_current(self, seq: int) -> None:
        """Start item ``seq`` again although the vehicle already flies it: the new content of
        that index is flown (ArduPilot restarts no return-to-launch, takeoff or land item on
        an upload). MISSION_CURRENT cannot confirm it (the index stays): the ACK does."""
        result = await self._command_result(M.MAV_CMD_DO_SET_MISSION_CURRENT, seq, 0,
                                            retries=max(self.settings.retries // 3, 2))
        if result != "MAV_RESULT_ACCEPTED":
            raise LinkError("set_current()", f"restarting item {seq}: {result}")
        log.info("mission: item %d started again", seq)

    async def download(self) -> list[MissionItem]:
        async with self._mission_lock:
            self._check_link("download_mission()")
            return await self._download()

    async def _download(self, *, new_generation: bool = True) -> list[MissionItem]:
        """Read the mission back; with ``new_generation`` the vehicle's reports from then on
        count as about what was read (an upload's read-back decides that itself)."""
        self._generation_on_download = new_generation
        done = await self._run(MissionDownload(self._send, self._target, self.settings.retries,
                                                 self._patience_s()))
        if not done.ok:
            raise LinkError("download_mission()", done.result)
        return list(done.items)

    def _patience_s(self) -> float:
        """The silence a mission transfer bears before giving up: ``retries`` of the longest
        wait, however short the measured round trip makes each repeat (upload.Silence)."""
        return self.settings.retries * self.settings.item_timeout_s

    async def _command_result(self, command: int, *params: float, retries: int | None = None) -> str:
        """COMMAND_LONG with the confirmation counting up on each repeat; the result's name
        (MAV_RESULT_*) or "NO_ANSWER" after ``retries`` tries. Unlike a mission transfer, a
        command is answered at once (COMMAND_ACK), so its repeats need no patience beyond the
        measured wait; and a long one would carry a command across a vehicle's restart (tried:
        the operator's hold's LOITER, repeated for 5 s, reached the vehicle started after it)."""
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        tries = self.settings.retries if retries is None else retries
        async with self._command_lock:
            assert self._loop is not None
            for confirmation in range(tries):
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
                return "MAV_RESULT_ACCEPTED" if result == M.MAV_RESULT_IN_PROGRESS else result_name(result)
            return "NO_ANSWER"

    async def _refusal_texts(self, since: float) -> str:
        """What the autopilot said (STATUSTEXT) since ``since``: why it refused."""
        await asyncio.sleep(REFUSAL_TEXT_WAIT_S)
        texts = self.state.texts_since(since)
        return f" (autopilot: {'; '.join(texts)})" if texts else ""

    async def command(self, command: int, *params: float, what: str) -> None:
        """A command that must be accepted: ``LinkError`` names the result and what the
        autopilot said about it."""
        sent_at = time.monotonic()
        result = await self._command_result(command, *params)
        if result == "MAV_RESULT_ACCEPTED":
            return
        if result == "NO_ANSWER":
            raise LinkError(what, f"NO_ANSWER after {self.settings.retries} tries{self.signing_hint()}")
        raise LinkError(what, result + await self._refusal_texts(sent_at))


def _buffered(conn: Any) -> list[Any]:
    """The messages already in pymavlink's parse buffer. Over UDP pymavlink reads one
    datagram and parses one message from it per call; PX4 packs several messages into
    each datagram, so without this the rest waited behind every later datagram and the
    backlog grew for as long as PX4 kept sending (seconds behind on PX4 SITL at speed 10:
    mission replies late, PX4's mission protocol timing out)."""
    out = []
    while (msg := conn.mav.parse_char(b"")) is not None:
        out.append(msg)
    return out


def _close_quietly(conn: Any) -> None:
    try:
        conn.close()
    except Exception:  # noqa: BLE001 - pymavlink may fail closing what is already gone
        pass
