"""ArduCopter SITL (the real autopilot, built for software-in-the-loop) for the tests.

Where the binary is: ``ARDUPILOT_SITL`` in the environment, else
``<repo>/../shared/ardupilot/arducopter``, else ``/work/shared/ardupilot/arducopter``; the
``sitl`` fixtures skip with that reason where there is none, so ``make test`` passes
without it. Each SITL runs in its own temporary folder (it writes ``eeprom.bin`` and
``logs/`` where it starts) with its own instance number (``-I N``: its TCP ports are
5760 + 10 N for SERIAL0, 5762 + 10 N for SERIAL1, 5763 + 10 N for SERIAL2), on loopback
only, started from ``copter.parm`` beside the binary (then any ``defaults`` files, e.g.
docs/sitl-copter.parm) with ``--home`` at the service's default ``[origin]``, and always
stopped with SIGTERM (SIGKILL if it lingers).

SITL runs only once something connects to SERIAL0: the harness keeps a monitor connection
there (source 254/191; it sends a heartbeat a second, since ArduPilot sends STATUSTEXT only
to links it hears, and never asks for streams, so the links under test see ArduPilot's
defaults), which records STATUSTEXT for ``wait_text``; the links under test use SERIAL1 and
SERIAL2. ``read_log`` reads the autopilot's own dataflash log (POS, CMD, MSG)
so a test can hold what the link reported against where the vehicle really was.
"""

from __future__ import annotations

import fcntl
import os
import re
import signal
import socket
import subprocess
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from planner_service.harness.processes import tied_to_parent  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
ENV = "ARDUPILOT_SITL"
HOME = "47.397742,8.545594,488,0"
"""The service's default [origin] (protocol.geodesy), heading north."""
INSTANCES = range(10, 20)
"""Instance numbers for these tests (other suites use other ranges: the whole sorties of
tests/service/test_sortie_sitl.py take 30..39)."""
SPEEDUP = 10
READY_TEXT = re.compile(r"EKF3 IMU0 is using GPS")


def sitl_binary() -> Path | None:
    """The ArduCopter SITL binary, or None."""
    candidates = [os.environ.get(ENV, ""), str(REPO.parent / "shared" / "ardupilot" / "arducopter"),
                  "/work/shared/ardupilot/arducopter"]
    for candidate in candidates:
        if candidate and Path(candidate).is_file() and os.access(candidate, os.X_OK):
            return Path(candidate)
    return None


def skip_reason() -> str:
    return (f"no ArduCopter SITL binary: set {ENV}, or put it at {REPO.parent / 'shared/ardupilot/arducopter'} "
            "(see docs/OPERATIONS.md)")


def ports(instance: int) -> tuple[int, int, int]:
    """SERIAL0, SERIAL1, SERIAL2 TCP ports of an instance."""
    base = 5760 + 10 * instance
    return base, base + 2, base + 3


def port_is_free(port: int) -> bool:
    """Nothing is bound to ``port`` (TCP or UDP). A TCP port in TIME_WAIT after the last SITL
    counts as free: SITL binds with SO_REUSEADDR."""
    for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
        with socket.socket(socket.AF_INET, kind) as sock:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind(("127.0.0.1", port))
            except OSError:
                return False
    return True


_RESERVED: dict[str, Any] = {}
"""Instances this process holds (an open, locked file each): a test run split over
processes (pytest-xdist) never hands one instance to two SITLs started at the same time."""


def free_instance(instances: range = INSTANCES) -> int:
    """An instance number in ``instances`` whose ports 5760..5763 + 10 N are all free and
    that no other process of the test run holds (it stays this process's until it exits)."""
    for instance in instances:
        if not reserve(f"sitl-{instance}"):
            continue
        base = ports(instance)[0]
        if all(port_is_free(p) for p in range(base, base + 4)):
            return instance
    raise RuntimeError(f"no free SITL instance in {instances.start}..{instances.stop - 1}")


def reserve(name: str) -> bool:
    """``name`` (e.g. ``sitl-12``) is this process's now or was already; False: another
    process of the test run holds it."""
    if name in _RESERVED:
        return True
    handle = open(Path(tempfile.gettempdir()) / f"uav-planner-{name}.lock", "w")
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.close()
        return False
    _RESERVED[name] = handle
    return True


@dataclass
class Sitl:
    """One ArduCopter SITL process in ``folder``."""

    binary: Path
    folder: Path
    instance: int
    speedup: int = SPEEDUP
    serials: dict[int, str] = field(default_factory=dict)
    """SITL's ``--serialN`` devices, e.g. {1: "udpclient:127.0.0.1:14550"} (default: TCP)."""
    defaults: tuple[Path, ...] = ()
    """Parameter files loaded after ``copter.parm`` (e.g. docs/sitl-copter.parm)."""
    home: str = HOME
    """``--home`` LAT,LON,ALT,HEADING (a fleet's UAVs each stand on their own)."""
    proc: subprocess.Popen[bytes] | None = None
    texts: list[tuple[float, str]] = field(default_factory=list)
    _stop: threading.Event = field(default_factory=threading.Event)
    _monitor: threading.Thread | None = None
    _linked: threading.Event = field(default_factory=threading.Event)
    _boots: int = 0

    # --- addresses ----------------------------------------------------------------------------
    def url(self, serial: int = 1) -> str:
        """The pymavlink connection string of SERIAL1 (default) or SERIAL2 (SERIAL0 is the monitor's)."""
        return f"tcp:127.0.0.1:{ports(self.instance)[serial if serial < 2 else 2]}"

    @property
    def serial0(self) -> str:
        return f"tcp:127.0.0.1:{ports(self.instance)[0]}"

    # --- lifecycle ----------------------------------------------------------------------------
    def start(self) -> None:
        defaults = self.binary.parent / "copter.parm"
        args = [str(self.binary), "--model", "+", "--speedup", str(self.speedup), "--home", self.home,
                "-I", str(self.instance)]
        files = [str(defaults)] if defaults.is_file() else []
        files += [str(path) for path in self.defaults]
        if files:
            args += ["--defaults", ",".join(files)]  # SITL loads them in this order
        for number, device in sorted(self.serials.items()):
            args += [f"--serial{number}", device]
        self._boots += 1
        out = open(self.folder / f"sitl-{self._boots}.out", "wb")
        self.proc = subprocess.Popen(args, cwd=self.folder, stdout=out, stderr=subprocess.STDOUT,
                                     start_new_session=True, preexec_fn=tied_to_parent())
        out.close()
        self._linked.clear()
        if self._monitor is None or not self._monitor.is_alive():
            self._stop.clear()
            self._monitor = threading.Thread(target=self._watch, name="sitl-monitor", daemon=True)
            self._monitor.start()
        deadline = time.monotonic() + 20.0
        while not self._linked.wait(0.1):  # the monitor's SERIAL0 connection got a heartbeat
            if self.proc.poll() is not None:
                raise RuntimeError(f"SITL exited with {self.proc.returncode}: {self.output()[-1500:]}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"SITL did not answer on SERIAL0 within 20 s: {self.output()[-1500:]}")

    def output(self) -> str:
        paths = sorted(self.folder.glob("sitl-*.out"))
        return paths[-1].read_text(errors="replace") if paths else ""

    def kill(self, sig: int = signal.SIGKILL) -> None:
        """End the autopilot as a crash or power loss would (SIGKILL) or cleanly (SIGTERM)."""
        end_group(self.proc, sig)

    def restart(self) -> None:
        """Kill it and start it again in the same folder (same parameters, logs appended)."""
        self.kill()
        self.start()

    def stop(self) -> None:
        self._stop.set()
        self.kill(signal.SIGTERM)
        if self._monitor is not None:
            self._monitor.join(3.0)

    # --- the monitor ---------------------------------------------------------------------------
    def _watch(self) -> None:
        """Keep SERIAL0 connected (SITL runs only then) and record STATUSTEXT."""
        while not self._stop.is_set():
            try:
                conn = mavutil.mavlink_connection(self.serial0, source_system=254, source_component=191,
                                                  retries=0)
            except OSError:
                self._stop.wait(0.2)
                continue
            conn.handle_eof = conn.handle_disconnect = _closed
            beat = 0.0
            try:
                while not self._stop.is_set():
                    if time.monotonic() - beat >= 1.0:  # ArduPilot sends STATUSTEXT only to links it hears
                        conn.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID,
                                                0, 0, 0)
                        beat = time.monotonic()
                    msg = conn.recv_match(type=["STATUSTEXT", "HEARTBEAT"], blocking=True, timeout=0.2)
                    if msg is None:
                        continue
                    if msg.get_type() == "HEARTBEAT":
                        self._linked.set()
                    else:
                        self.texts.append((time.monotonic(), str(msg.text)))
            except Exception:  # noqa: BLE001 - SITL went away: connect again
                pass
            finally:
                try:
                    conn.close()
                except Exception:  # noqa: BLE001
                    pass

    def wait_text(self, pattern: str | re.Pattern[str], timeout_s: float = 60.0, since: float = 0.0) -> str:
        """The first STATUSTEXT matching ``pattern`` heard after ``since`` (monotonic)."""
        regex = re.compile(pattern) if isinstance(pattern, str) else pattern
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            for at, text in list(self.texts):
                if at >= since and regex.search(text):
                    return text
            time.sleep(0.05)
        raise TimeoutError(f"no STATUSTEXT matching {regex.pattern!r} within {timeout_s:g} s; heard "
                           f"{[t for _, t in self.texts][-15:]}")

    def wait_ready(self, timeout_s: float = 60.0, since: float = 0.0) -> None:
        """Until the EKF uses the GPS (arming and AUTO are possible from then on)."""
        self.wait_text(READY_TEXT, timeout_s, since)

    # --- the dataflash log ----------------------------------------------------------------------
    def logs(self) -> list[Path]:
        return sorted((self.folder / "logs").glob("*.BIN"))

    def read_log(self, kinds: tuple[str, ...] = ("POS", "CMD", "MSG")) -> list[dict[str, Any]]:
        """The records of ``kinds`` from every dataflash log SITL wrote, oldest first (each a
        dict with ``mavpackettype``; ``TimeUS`` is the autopilot's clock)."""
        return list(read_dataflash(self.logs(), kinds))


class PtyBridge:
    """A serial line for the tests: a pseudo-terminal whose other end is joined to a TCP
    port of SITL (reconnecting when SITL restarts), so a link opens ``device`` as it would
    a flight controller's UART."""

    def __init__(self, port: int) -> None:
        import pty
        import tty

        self.port = port
        self.master, slave = pty.openpty()
        tty.setraw(slave)
        self.device = os.ttyname(slave)
        self._slave = slave  # kept open: a pty whose last slave closes reports EIO to the master
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pty-bridge", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import select

        sock: socket.socket | None = None
        while not self._stop.is_set():
            if sock is None:
                try:
                    sock = socket.create_connection(("127.0.0.1", self.port), timeout=0.2)
                    sock.setblocking(False)
                except OSError:
                    sock = None
            watched = [self.master] + ([sock] if sock is not None else [])
            ready, _, _ = select.select(watched, [], [], 0.1)
            try:
                if self.master in ready:
                    data = os.read(self.master, 65536)
                    if sock is not None:  # else lost, as on a UART with nobody listening
                        sock.sendall(data)
                if sock is not None and sock in ready:
                    data = sock.recv(65536)
                    if not data:
                        raise ConnectionResetError("SITL went away")
                    os.write(self.master, data)
            except OSError:
                if sock is not None:
                    sock.close()
                sock = None
        if sock is not None:
            sock.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(3.0)
        for fd in (self.master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass


def end_group(proc: subprocess.Popen[bytes] | None, sig: int, wait_s: float = 5.0) -> None:
    """Send ``sig`` to ``proc``'s process group (started with a session of its own) and wait;
    SIGKILL to the group if it lingers. Nothing if it is not running."""
    if proc is None or proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        return
    try:
        proc.wait(wait_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(5.0)


def _closed() -> None:
    raise ConnectionResetError("SITL closed the connection")


def read_dataflash(paths: list[Path], kinds: tuple[str, ...]) -> Iterator[dict[str, Any]]:
    for path in paths:
        log = mavutil.mavlink_connection(str(path))
        try:
            while True:
                msg = log.recv_match(type=list(kinds))
                if msg is None:
                    break
                yield msg.to_dict()
        finally:
            log.close()


def set_param(url: str, name: str, value: float, timeout_s: float = 10.0) -> None:
    """Set an autopilot parameter over its own connection (a test's set-up, not the link's)."""
    conn = mavutil.mavlink_connection(url, source_system=253, source_component=192, retries=0)
    try:
        conn.wait_heartbeat(timeout=timeout_s)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            conn.mav.param_set_send(1, 1, name.encode(), float(value), mavutil.mavlink.MAV_PARAM_TYPE_REAL32)
            msg = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1.0)
            if msg is not None and msg.param_id == name and abs(msg.param_value - value) < 1e-6:
                return
        raise TimeoutError(f"SITL did not confirm {name} = {value}")
    finally:
        conn.close()
