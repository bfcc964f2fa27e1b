"""The MAVSDK backend: the native mavsdk 4 binding (no mavsdk_server), asyncio API.

MAVSDK moves the missions (``mission_raw``: MISSION_ITEM_INT as the protocol encodes
them; the ``mission`` plugin is written for PX4 and loses the first waypoint to
ArduPilot's home item) and keeps the connection (it reconnects by itself). Everything else
goes through its ``mavlink_direct`` plugin, so that both backends judge the same messages
the same way (``state.VehicleState``): every incoming message with its source (system,
component), for trust, telemetry and progress; and the commands (stream requests, modes,
arming, the current item) as COMMAND_LONG. MAVSDK alone asks ArduPilot for nothing but
HOME_POSITION and AUTOPILOT_VERSION (seen on ArduCopter SITL: no GLOBAL_POSITION_INT, no
EXTENDED_SYS_STATE), so the link asks for what it needs, as the pymavlink backend does.
MAVSDK's coloured log lines are routed to the ``mavsdk`` logger instead of stdout.

Which mission a report is about: ``generation`` grows after each accepted upload or
download. MAVSDK hides the packets, so there is no sequence number to sort by; a report
arrives on the loop in the order MAVSDK received it, before the upload's result (the ACK
is handled after the messages before it). Right after an upload or a download, a
MISSION_CURRENT whose total (or, where the autopilot names its missions, id) does not fit
the mission just moved is about the one before and is dropped, until the first that fits
or ``STALE_REPORT_S``: after that a report that does not fit is news (another station's
mission), which the sortie logic must see.
"""

from __future__ import annotations

import asyncio
import json
import logging
import time
from types import SimpleNamespace
from typing import Any, Awaitable, Callable, Sequence, TypeVar

from mavsdk import log_subscribe
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.plugins.mavlink_direct import MavlinkDirectError, MavlinkMessage
from mavsdk.plugins.mission_raw import MissionItem as RawItem
from mavsdk.plugins.mission_raw import MissionRawError, MissionRawResult
from pymavlink.dialects.v20 import ardupilotmega as M

from protocol import MissionItem

from ..errors import LinkError
from .base import CURRENT_WAIT_S, LinkSettings, VehicleLink
from .events import Current, LinkEvent, Reached
from .progress import mission_progress
from .streams import INTERVAL_CMD, QUIET_INTERVAL_US, Request

_log = logging.getLogger("mavsdk")
log = logging.getLogger(__name__)
T = TypeVar("T")
RETRYABLE = {MissionRawResult.BUSY, MissionRawResult.TIMEOUT, MissionRawResult.ERROR,
             MissionRawResult.INVALID_SEQUENCE}
"""Transfer results worth a whole new transfer (MISSION_COUNT or MISSION_REQUEST_LIST restarts it). An
INVALID_SEQUENCE ack is the autopilot saying an item came out of turn (a repeat that crossed
its next request: ArduPilot sends it and goes on, MAVSDK ends the upload there), seen on
ArduCopter SITL at x10 over a serial line on a loaded machine."""
BUSY_TRANSFER_WAIT_S = 5.5
"""Wall seconds before a transfer refused as busy is tried again: PX4 drops a transfer its
partner abandoned 5 s after it last heard from it (MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT,
in its own time: at speed 1 wall seconds, less at speed 10) and refuses a new one until then."""
REPORTS = frozenset({"MISSION_CURRENT", "MISSION_ITEM_REACHED"})
REFUSAL_TEXT_WAIT_S = 0.3
STALE_REPORT_S = 2.0
"""Wall seconds after an upload or a download in which a MISSION_CURRENT that does not fit
the mission moved may still be about the one before (it was sent before, or crossed it)."""
ACK_WAIT_S = 0.3
"""Wall seconds to wait, after MAVSDK says an upload was accepted, for the MISSION_ACK
itself on the message stream (its ``opaque_id``: the mission's id)."""


def _to_logging(level: Any, message: str, file: str | None, line: int) -> bool:
    _log.debug("%s %s", getattr(level, "name", level), message)
    return True  # True: MAVSDK does not print it to stdout


log_subscribe(_to_logging)


def mavsdk_url(url: str) -> str:
    """pymavlink's connection strings in MAVSDK's form (udpout:H:P -> udpout://H:P)."""
    if "://" in url:
        return url
    scheme, _, rest = url.partition(":")
    if scheme in ("udpout", "udpin"):
        return f"{scheme}://{rest}"
    if scheme == "udp":
        return f"udpin://{rest}"
    if scheme == "tcp":
        return f"tcpout://{rest}"
    if scheme == "tcpin":
        return f"tcpin://{rest}"
    device, _, baud = url.partition(",")
    return f"serial://{device}:{baud or 57600}"


def _name(result: Any) -> str:
    return str(getattr(result, "name", result))


def result_name(code: int) -> str:
    entry = M.enums["MAV_RESULT"].get(code)
    return entry.name if entry is not None else f"MAV_RESULT {code}"


def mission_item(raw: RawItem) -> MissionItem:
    return MissionItem(seq=raw.seq, frame=raw.frame, command=raw.command, current=raw.current,
                       autocontinue=raw.autocontinue, param1=raw.param1, param2=raw.param2, param3=raw.param3,
                       param4=raw.param4, x=raw.x, y=raw.y, z=raw.z, mission_type=raw.mission_type)


def raw_item(item: MissionItem) -> RawItem:
    return RawItem(seq=item.seq, frame=item.frame, command=item.command, current=item.current,
                   autocontinue=item.autocontinue, param1=item.param1, param2=item.param2, param3=item.param3,
                   param4=item.param4, x=item.x, y=item.y, z=item.z, mission_type=item.mission_type)


def fields(message: Any) -> SimpleNamespace:
    """A mavlink_direct message's fields as attributes (the names of the MAVLink XML, as
    pymavlink's)."""
    return SimpleNamespace(**json.loads(message.fields_json or "{}"))


class MavsdkLink(VehicleLink):
    def __init__(self, settings: LinkSettings, on_event: Callable[[LinkEvent], None]) -> None:
        super().__init__(settings, on_event)
        self._sdk: Any = None
        self._raw: Any = None
        self._direct: Any = None
        self._tasks: list[asyncio.Task[None]] = []
        self._streams_task: asyncio.Task[None] | None = None
        self._upload_lock = asyncio.Lock()
        self._expect_total: int | None = None
        """After an upload: the mission's size, which a MISSION_CURRENT about it reports."""
        self._expect_until = 0.0
        """``time.monotonic()`` until which a report that does not fit is taken as stale."""
        self._ack_seen = asyncio.Event()
        """A MISSION_ACK from the autopilot arrived on the message stream."""
        self._connected = asyncio.Event()
        self._inflight: set[asyncio.Future[Any]] = set()
        """MAVSDK calls running in executor threads: a cancelled task leaves them running, and
        destroying MAVSDK under them hangs, so ``close`` waits for them (MAVSDK times a
        command out after about 2 s)."""
        self.state.request_streams = self._request_streams
        self.state.on_restart = self._on_restart

    async def connect(self, timeout_s: float) -> None:
        self._sdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        url = mavsdk_url(self.settings.url)
        await self._sdk.add_any_connection(url)
        system = await self._sdk.first_autopilot(timeout_s=timeout_s)
        if system is None:
            raise LinkError("connect", f"no autopilot at {url} within {timeout_s:g} s")
        self._raw = MissionRawAsync(system)
        self._direct = MavlinkDirectAsync(system)
        self._tasks = [asyncio.create_task(self._pump(), name="mavsdk-messages"),
                       asyncio.create_task(self._watchdog(), name="mavsdk-watchdog")]
        try:
            await asyncio.wait_for(self._connected.wait(), timeout_s)
        except TimeoutError:
            if self.state.wrong_autopilot:
                raise LinkError("connect", self.state.wrong_autopilot) from None
            raise LinkError("connect", f"no autopilot heartbeat at {url} within {timeout_s:g} s") from None

    async def close(self) -> None:
        tasks = [*self._tasks, *([self._streams_task] if self._streams_task is not None else [])]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        self._tasks = []
        if self._inflight:
            await asyncio.wait(set(self._inflight), timeout=5.0)
        for plugin in (self._raw, self._direct):
            # Destroyed here, before MAVSDK itself: a plugin collected later, in whichever
            # thread drops it last (an executor's, after a call), destroyed its native
            # handle while MAVSDK was destroyed under it and aborted the process (a test's
            # MAVSDK client, in a CI run). Destroying twice is a no-op.
            if plugin is not None:
                plugin.destroy()
        if self._sdk is not None:
            result = self._sdk.destroy()
            if asyncio.iscoroutine(result):
                await result
            self._sdk = None

    # --- incoming -----------------------------------------------------------------------------
    async def _pump(self) -> None:
        """Every message MAVSDK receives, with its source; a message that trips a bug is
        logged and dropped, it never ends the stream."""
        while True:
            try:
                async for message in self._direct.subscribe_message(""):
                    try:
                        self._on_message(message)
                    except Exception:  # noqa: BLE001
                        log.exception("link: handling %s failed", message.message_name)
            except asyncio.CancelledError:
                raise
            except Exception:  # noqa: BLE001
                log.exception("link: the message subscription failed; subscribing again")
                await asyncio.sleep(1.0)

    def _on_message(self, message: Any) -> None:
        name, source = message.message_name, (int(message.system_id), int(message.component_id))
        if name == "HEARTBEAT":
            first = self.state.autopilot is None
            if self.state.on_heartbeat(*source, fields(message)) and first:
                self._connected.set()
                self._request_streams()
            return
        msg = fields(message)
        msg_id = int(getattr(msg, "message_id", -1))
        if name in ("MISSION_ACK", "MISSION_COUNT") and self._upload_lock.locked() and self.state.trusted(*source):
            # the mission's id, which MAVSDK's mission_raw does not return
            if name == "MISSION_COUNT" or int(getattr(msg, "type", -1)) == M.MAV_MISSION_ACCEPTED:
                self.mission_id = int(getattr(msg, "opaque_id", 0) or 0)
            if name == "MISSION_ACK":
                self._ack_seen.set()
        if name in REPORTS:
            if not self.state.trusted(*source):
                return
            self.state.heard()
            self.state.streams.heard(msg_id)
            self._report(name, msg)
            return
        self.state.on_message(name, msg_id, *source, msg)

    def _report(self, name: str, msg: Any) -> None:
        if name == "MISSION_ITEM_REACHED":
            self.state.current_watch.reached(int(msg.seq))
            if self.state.new_reach(self.generation, int(msg.seq)):
                self.on_event(Reached(int(msg.seq), self.generation))
            return
        seq, total = mission_progress(msg)
        mission_id = int(getattr(msg, "mission_id", 0) or 0)
        expect = self._expect_total
        if expect is not None and time.monotonic() < self._expect_until:
            stale = ((total >= 0 and total not in (expect, expect - 1))  # ArduPilot leaves home out of total
                     or (self.mission_id != 0 and mission_id not in (0, self.mission_id)))
            if stale:
                return  # about the mission before the last upload
            self._expect_total = None  # the first report of the mission moved: what follows is news
        if not self.state.current_watch.observe(seq, time.monotonic()):
            return  # another item, not yet confirmed by the vehicle's stream (``progress.CurrentWatch``)
        t = self.telemetry
        changed = (seq, total, mission_id) != (t.mission_seq, t.mission_total, t.mission_id)
        self.state.set_progress(seq, total, mission_id)
        if seq >= 0:  # an item named: the answer to whoever waits for the index
            self._current = (self.generation, seq)
            self._current_moved.set()
        if changed:
            self.on_event(Current(seq, total, self.generation))

    def _on_restart(self) -> None:
        self.generation += 1
        self._expect_total, self._current = None, None

    async def _watchdog(self) -> None:
        while True:
            await asyncio.sleep(1.0)
            try:
                repeat = self.state.tick()
                if repeat and (self._streams_task is None or self._streams_task.done()):
                    self._streams_task = asyncio.ensure_future(self._send_requests(repeat))
            except Exception:  # noqa: BLE001
                log.exception("link: watchdog round failed")

    # --- commands -----------------------------------------------------------------------------
    def _request_streams(self) -> None:
        if not self._connected.is_set():
            return
        if self._streams_task is not None and not self._streams_task.done():
            self._streams_task.cancel()
        self._streams_task = asyncio.ensure_future(self._send_requests(self.state.streams.begin()))

    async def _send_requests(self, requests: list[Request]) -> None:
        streams = self.state.streams
        for request in requests:
            spec = request.spec
            results = [request]
            if request.kind == "quiet":
                log.debug("%s: stopped (%s)", spec.name,
                          await self._command_result(INTERVAL_CMD, spec.msg_id, QUIET_INTERVAL_US))
                continue
            if request.kind == "interval":
                result = await self._command_result(INTERVAL_CMD, spec.msg_id, spec.interval_s * 1e6)
                if result != "MAV_RESULT_ACCEPTED":
                    log.info("%s: SET_MESSAGE_INTERVAL refused (%s); falling back", spec.name, result)
                results = streams.on_interval_result(spec.name, result)
            for fallback in results:
                if fallback.kind == "stream" and spec.group is not None:
                    rate = max(1, round(max(1.0 / s.interval_s for s in streams.plan if s.group == spec.group)))
                    await self._send_message("REQUEST_DATA_STREAM", req_stream_id=spec.group, req_message_rate=rate,
                                             start_stop=1)
                elif fallback.kind == "message":
                    await self._command_result(M.MAV_CMD_REQUEST_MESSAGE, spec.msg_id)

    def _target(self) -> tuple[int, int]:
        return self.state.autopilot or (1, 1)

    async def _send_message(self, name: str, **values: Any) -> None:
        target = self._target()
        body = {"target_system": target[0], "target_component": target[1], **values}
        try:
            await self._direct.send_message(MavlinkMessage(message_name=name, target_system_id=target[0],
                                                           target_component_id=target[1],
                                                           fields_json=json.dumps(body)))
        except MavlinkDirectError as err:
            log.debug("%s not sent: %s", name, err)

    async def _command_result(self, command: int, *params: float) -> str:
        """COMMAND_LONG through MAVSDK (it repeats and waits for the final ACK): the
        result's name or NO_ANSWER."""
        target = self._target()
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        body = {"target_system": target[0], "target_component": target[1], "command": command, "confirmation": 0,
                **{f"param{i + 1}": v for i, v in enumerate(p)}}
        message = MavlinkMessage(message_name="COMMAND_LONG", target_system_id=target[0],
                                 target_component_id=target[1], fields_json=json.dumps(body))
        call = asyncio.get_running_loop().run_in_executor(None, self._direct._plugin.send_command, message)
        self._inflight.add(call)
        call.add_done_callback(self._inflight.discard)
        try:
            ack = await asyncio.shield(call)
        except MavlinkDirectError as err:
            return "NO_ANSWER" if err.result.name == "TIMEOUT" else f"NO_ANSWER ({_name(err.result)})"
        if (int(ack.system_id), int(ack.component_id)) != target and ack.system_id:
            return "NO_ANSWER (an ACK from another component)"
        result = int(fields(ack).result)
        return "MAV_RESULT_ACCEPTED" if result == M.MAV_RESULT_IN_PROGRESS else result_name(result)

    async def _refusal_texts(self, since: float) -> str:
        await asyncio.sleep(REFUSAL_TEXT_WAIT_S)
        texts = self.state.texts_since(since)
        return f" (autopilot: {'; '.join(texts)})" if texts else ""

    async def command(self, command: int, *params: float, what: str) -> None:
        sent_at = time.monotonic()
        result = await self._command_result(command, *params)
        if result != "MAV_RESULT_ACCEPTED":
            raise LinkError(what, result + await self._refusal_texts(sent_at))

    def _check_link(self, operation: str) -> None:
        if not self._connected.is_set() or self.state.lost:
            raise LinkError(operation, "NO_LINK: the autopilot is not connected")

    # --- operations ---------------------------------------------------------------------------
    async def upload(self, items: Sequence[MissionItem], *, current_seq: int | None = None,
                     restart_current: bool = False) -> None:
        if current_seq is not None and not 0 <= current_seq < len(items):
            raise LinkError("upload_mission()", f"current_seq {current_seq} is not an item of the {len(items)}")
        for seq in [current_seq, *(i.seq for i in items if i.current)]:
            if seq is not None:
                self.state.current_watch.expect(seq)  # the vehicle's report of the item asked for is news
        raw = [raw_item(i) for i in items]
        async with self._upload_lock:
            self._check_link("upload_mission()")

            async def send() -> None:
                self.mission_id = 0
                self._ack_seen.clear()
                await self._raw.upload_mission(raw)
            await self._transfer("upload_mission()", send)
            try:
                await asyncio.wait_for(self._ack_seen.wait(), ACK_WAIT_S)
            except TimeoutError:
                log.debug("link: the upload's MISSION_ACK did not show on the message stream; its id is unknown")
            self.generation += 1
            self._expect_total, self._current = len(raw), None
            self._expect_until = time.monotonic() + STALE_REPORT_S
            self.state.set_progress(0, len(raw))
            if current_seq is not None:
                await self._ensure_current(current_seq, wait_for_report=True, restart=restart_current)

    async def _transfer(self, what: str, run: Callable[[], Awaitable[T]]) -> T:
        """A whole MAVSDK mission transfer, begun again (up to ``retries`` times) where it ended
        in a result worth another try: MAVSDK gives an item a few tries only, and over a lossy
        link (a fifth of the datagrams lost each way) a 20-item download on PX4 SITL ended in
        TIMEOUT now and then; the protocol restarts cleanly from MISSION_COUNT or
        MISSION_REQUEST_LIST. After a try that failed, a PROTOCOL_ERROR is taken for that try's
        echo (PX4 still in the abandoned transfer answers the new one MAV_MISSION_ERROR, "WPM:
        REJ. CMD: Busy", which MAVSDK reports so) and is tried again after PX4 has dropped the
        abandoned one; as a first answer it ends the transfer."""
        last: MissionRawError | None = None
        for _ in range(self.settings.retries):
            self._check_link(what)  # a lost link is not retried into: it is lost
            try:
                return await run()
            except MissionRawError as err:
                echo = last is not None and err.result == MissionRawResult.PROTOCOL_ERROR
                last = err
                if err.result not in RETRYABLE and not echo:
                    break
                log.info("link: %s ended %s; trying it again", what, _name(err.result))
                if echo:
                    await asyncio.sleep(BUSY_TRANSFER_WAIT_S)
        raise LinkError(what, _name(last.result) if last is not None else "UNKNOWN")

    async def set_current(self, seq: int) -> None:
        async with self._upload_lock:
            self._check_link("set_current()")
            await self._ensure_current(seq, wait_for_report=False)

    async def _ensure_current(self, seq: int, *, wait_for_report: bool, restart: bool = False) -> None:
        """As the pymavlink backend: nothing when MISSION_CURRENT already says ``seq``, else
        MAV_CMD_DO_SET_MISSION_CURRENT, or MAVSDK's MISSION_SET_CURRENT where refused."""
        seen = await self._wait_current(CURRENT_WAIT_S if wait_for_report else 0.0)
        if seen == seq and restart and not self.profile.flies_changed_current_item:
            # the index stays: the command's ACK confirms the restart (see the pymavlink backend)
            result = await self._command_result(M.MAV_CMD_DO_SET_MISSION_CURRENT, seq, 0)
            if result != "MAV_RESULT_ACCEPTED":
                raise LinkError("set_current()", f"restarting item {seq}: {result}")
            return
        if seen == seq:
            return
        sent_at = time.monotonic()
        self.state.current_watch.expect(seq)
        for attempt in range(3):
            result = ("not tried" if not self.profile.set_current_by_command
                      else await self._command_result(M.MAV_CMD_DO_SET_MISSION_CURRENT, seq, 0))
            if result != "MAV_RESULT_ACCEPTED":
                try:
                    await self._raw.set_current_mission_item(seq)
                except MissionRawError as err:
                    log.info("set_current(%d): %s, then %s", seq, result, _name(err.result))
            seen = await self._wait_current(CURRENT_WAIT_S, want=seq)
            if seen == seq:
                log.info("mission: current item set to %d", seq)
                return
        raise LinkError("set_current()", f"the vehicle reports item {seen}, not {seq}{await self._refusal_texts(sent_at)}")

    async def download(self) -> list[MissionItem]:
        async with self._upload_lock:
            self._check_link("download_mission()")
            self.mission_id = 0
            try:
                raw = await self._transfer("download_mission()", self._raw.download_mission)
            except LinkError as err:
                if err.result != _name(MissionRawResult.NO_MISSION_AVAILABLE):
                    raise
                raw = []  # the vehicle holds none
            self.generation += 1
            self._expect_total, self._current = len(raw), None
            self._expect_until = time.monotonic() + STALE_REPORT_S
            self.state.set_progress(-1, -1)
            return [mission_item(r) for r in raw]
