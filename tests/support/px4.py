"""PX4 SITL (the real PX4 autopilot with its own SIH quadcopter physics) for the tests.

Where it is: ``PX4_SITL`` in the environment (a folder holding ``bin/px4`` and ``etc/``), else
``<repo>/../shared/px4``, else ``/work/shared/px4``; the ``px4`` fixtures skip with that
reason where there is none, so ``make test`` passes without it.

Each PX4 runs in its own temporary folder (``-w``: parameters, the mission's ``dataman``,
logs) as instance N (1..9, unique on the machine: PX4 locks ``/tmp/px4_lock-N``), started
from the shipped startup tree with airframe 10040 (``sihsim_quadx``), home at the service's
default ``[origin]``, the ulog off, and always stopped with SIGTERM (SIGKILL if it lingers).
The shipped ``bin/px4-*`` command links are plain files in some copies (a folder copied
without its symbolic links), so the harness puts links to ``bin/px4`` of its own in the
folder and starts PX4 from there: the startup script calls them by name.

Who talks to it on which port (PX4's own ``px4-rc.mavlink``; UDP on 127.0.0.1):

- the service under test, as a companion computer does: the onboard (API) link, PX4 on
  14580+N sending to 14540+N from its first second, so a restarted service is heard at
  once (``url``);
- the harness's monitor, as the pilot's ground station does: the ground-station link, PX4 on
  18570+N, which locks onto its first peer. The monitor is that peer for PX4's whole life;
  it records what PX4 says of itself (positions, heartbeats, MISSION_CURRENT, STATUSTEXT) so a
  test holds the service's journal against where the vehicle really was, and it flies
  the pilot's part (``monitor``: modes, a mission of another station);
- a spare link (payload, onboard mode, PX4 on 14280+N sending to 14030+N) for a second
  station of a test's own (``spare_url``).
"""

from __future__ import annotations

import fcntl
import os
import re
import shutil
import signal
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from planner_service.harness.processes import tied_to_parent  # noqa: E402
from planner_service.service.link.extensions import MISSION_CURRENT_ID_OFFSET, extension_u32  # noqa: E402
from protocol.geodesy import GeoOrigin  # noqa: E402
from tests.support.sitl import end_group, port_is_free, reserve  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
ENV = "PX4_SITL"
INSTANCES = range(1, 10)
"""PX4 instance numbers for the tests (0 is left to people; above 9 the onboard links of all
instances share one remote port)."""
SPEED = 5
"""PX4_SIM_SPEED_FACTOR: simulated seconds per wall second (4 measured 3.7x on 2 busy cores)."""
M = mavutil.mavlink
PREARM_OK = M.MAV_SYS_STATUS_PREARM_CHECK
QUIETED = ("LOCAL_POSITION_NED", "ATTITUDE", "ATTITUDE_QUATERNION", "ATTITUDE_TARGET",
           "POSITION_TARGET_LOCAL_NED", "SERVO_OUTPUT_RAW", "RC_CHANNELS", "OPTICAL_FLOW_RAD",
           "VFR_HUD", "GPS_RAW_INT", "ALTITUDE")
"""Streams of the ground-station link the monitor has no use for (up to 50 Hz of simulated
time each): stopped, so they do not cost the 2 cores."""
TRUTH_HZ = 10.0
"""GLOBAL_POSITION_INT on the monitor's link, in simulated time."""


PARAMS = REPO / "docs" / "sitl-px4.params"
"""The parameters docs/sitl-px4.toml's scenario needs (battery, cruise speed)."""


def read_params(path: Path) -> dict[str, float]:
    """A parameter file of ``NAME VALUE`` lines (``#`` comments)."""
    params: dict[str, float] = {}
    for number, line in enumerate(path.read_text().splitlines(), 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if len(words) != 2:
            raise ValueError(f"{path}:{number}: expected NAME VALUE, got {line!r}")
        params[words[0]] = float(words[1])
    return params


def px4_root() -> Path | None:
    """The folder holding ``bin/px4`` and ``etc/``, or None."""
    candidates = [os.environ.get(ENV, ""), str(REPO.parent / "shared" / "px4"), "/work/shared/px4"]
    for candidate in candidates:
        binary = Path(candidate) / "bin" / "px4" if candidate else None
        if binary is not None and binary.is_file() and os.access(binary, os.X_OK):
            return Path(candidate)
    return None


def skip_reason() -> str:
    return (f"no PX4 SITL: set {ENV} to a folder with bin/px4 and etc/, or put it at "
            f"{REPO.parent / 'shared/px4'} (see docs/OPERATIONS.md)")


def ports(instance: int) -> dict[str, int]:
    """Every UDP port PX4 instance N listens on or sends to (px4-rc.mavlink)."""
    return {"gcs": 18570 + instance, "onboard": 14580 + instance, "onboard_remote": 14540 + instance,
            "payload": 14280 + instance, "payload_remote": 14030 + instance, "gimbal": 13030 + instance,
            "gimbal_remote": 13280 + instance, "sih": 19450 + instance, "sih_remote": 19410 + instance}


def free_instance(instances: range = INSTANCES) -> int:
    """An instance number no other test process holds, with all its ports free and no PX4
    of anybody's running as it."""
    for instance in instances:
        if not reserve(f"px4-{instance}"):
            continue
        if Path(f"/tmp/px4_lock-{instance}").exists() and _px4_running(instance):
            continue
        if all(port_is_free(port) for port in ports(instance).values()):
            return instance
    raise RuntimeError(f"no free PX4 instance in {instances.start}..{instances.stop - 1}")


def _px4_running(instance: int) -> bool:
    try:
        handle = open(f"/tmp/px4_lock-{instance}", "r")
    except OSError:
        return False
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return True
        fcntl.flock(handle, fcntl.LOCK_UN)
        return False


@dataclass(frozen=True)
class Fix:
    """One GLOBAL_POSITION_INT as PX4 sent it to the monitor."""

    at: float
    """Monotonic wall time of receipt."""
    boot_ms: int
    lat_e7: int
    lon_e7: int
    relative_alt_mm: int


@dataclass
class Px4:
    """One PX4 SITL process in ``folder``."""

    root: Path
    folder: Path
    instance: int
    speed: int = SPEED
    params: dict[str, float] = field(default_factory=dict)
    """Parameters set at boot (``PX4_PARAM_<NAME>``), e.g. from docs/sitl-px4.params."""
    proc: subprocess.Popen[bytes] | None = None
    texts: list[tuple[float, str]] = field(default_factory=list)
    fixes: list[Fix] = field(default_factory=list)
    heartbeats: list[tuple[float, int, bool]] = field(default_factory=list)
    """(monotonic, custom_mode, armed) of each HEARTBEAT of the autopilot."""
    mission_ids: list[tuple[float, int, int, int]] = field(default_factory=list)
    """(monotonic, seq, total, mission_id) of each MISSION_CURRENT."""
    last: dict[str, Any] = field(default_factory=dict)
    """The last message of each type the monitor heard."""
    _stop: threading.Event = field(default_factory=threading.Event)
    _monitor: threading.Thread | None = None
    _conn: Any = None
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _boots: int = 0

    # --- addresses ----------------------------------------------------------------------------
    @property
    def url(self) -> str:
        """The pymavlink connection string of the onboard link (the service's)."""
        return f"udpin:127.0.0.1:{ports(self.instance)['onboard_remote']}"

    @property
    def spare_url(self) -> str:
        """A second station's connection string (the payload link, onboard mode)."""
        return f"udpin:127.0.0.1:{ports(self.instance)['payload_remote']}"

    @property
    def system(self) -> int:
        return self.instance + 1

    # --- lifecycle ----------------------------------------------------------------------------
    def _bin(self) -> Path:
        """A folder of links to ``bin/px4`` under every name the startup script calls."""
        own = self.folder / "bin"
        if not own.is_dir():
            own.mkdir()
            real = (self.root / "bin" / "px4").resolve()
            for shipped in (self.root / "bin").iterdir():
                if shipped.name.endswith(".sh"):
                    shutil.copy(shipped, own / shipped.name)
                elif shipped.name == "px4" or shipped.name.startswith("px4-"):
                    (own / shipped.name).symlink_to(real)
        return own

    def start(self) -> None:
        origin = GeoOrigin()
        env = dict(os.environ, PX4_SYS_AUTOSTART="10040", PX4_SIM_MODEL="sihsim_quadx",
                   PX4_SIM_SPEED_FACTOR=str(self.speed), PX4_HOME_LAT=f"{origin.lat_deg}",
                   PX4_HOME_LON=f"{origin.lon_deg}", PX4_HOME_ALT=f"{origin.alt_m}",
                   PX4_PARAM_SDLOG_BACKEND="0")
        env.update({f"PX4_PARAM_{name}": f"{value:g}" for name, value in self.params.items()})
        self._boots += 1
        out = open(self.folder / f"px4-{self._boots}.out", "wb")
        args = [str(self._bin() / "px4"), "-i", str(self.instance), "-d", "-w", str(self.folder / "work"),
                str(self.root / "etc")]
        self.proc = subprocess.Popen(args, cwd=self.folder, env=env, stdout=out, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True,
                                     preexec_fn=tied_to_parent())
        out.close()
        if self._monitor is None or not self._monitor.is_alive():
            self._stop.clear()
            self._monitor = threading.Thread(target=self._watch, name="px4-monitor", daemon=True)
            self._monitor.start()
        self.wait(lambda: self.last.get("HEARTBEAT") is not None, 30.0, "a heartbeat on the ground-station link")

    def output(self) -> str:
        paths = sorted(self.folder.glob("px4-*.out"))
        return paths[-1].read_text(errors="replace") if paths else ""

    def kill(self, sig: int = signal.SIGKILL) -> None:
        """End the autopilot as a crash or power loss would (SIGKILL) or cleanly (SIGTERM)."""
        end_group(self.proc, sig, wait_s=10.0)

    def restart(self) -> None:
        """Kill it and start it again in the same folder (its parameters and mission kept)."""
        self.kill()
        with self._lock:
            self.last.clear()
        self.start()

    def stop(self) -> None:
        self._stop.set()
        self.kill(signal.SIGTERM)
        if self._monitor is not None:
            self._monitor.join(3.0)

    # --- the monitor ---------------------------------------------------------------------------
    def _watch(self) -> None:
        port = ports(self.instance)["gcs"]
        while not self._stop.is_set():
            conn = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=254,
                                              source_component=191)
            self._conn = conn
            beat = quiet = 0.0
            try:
                while not self._stop.is_set():
                    now = time.monotonic()
                    if now - beat >= 1.0:  # the first datagram makes the monitor PX4's peer
                        conn.mav.heartbeat_send(M.MAV_TYPE_GCS, M.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                        beat = now
                    if self.last.get("HEARTBEAT") is not None and now - quiet >= 5.0:
                        self._quiet(conn)  # again after a restart of PX4
                        quiet = now
                    msg = conn.recv_match(blocking=True, timeout=0.2)
                    if msg is not None:
                        self._record(msg)
            except OSError:
                self._stop.wait(0.2)
            finally:
                conn.close()

    def _quiet(self, conn: Any) -> None:
        for name in QUIETED:
            msg_id = getattr(M, f"MAVLINK_MSG_ID_{name}")
            conn.mav.command_long_send(self.system, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0, msg_id, -1, 0, 0, 0, 0, 0)
        conn.mav.command_long_send(self.system, 1, M.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                   M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 1e6 / TRUTH_HZ, 0, 0, 0, 0, 0)

    def _record(self, msg: Any) -> None:
        kind = msg.get_type()
        if msg.get_srcSystem() != self.system or kind == "BAD_DATA":
            return
        now = time.monotonic()
        with self._lock:
            self.last[kind] = msg
            if kind == "GLOBAL_POSITION_INT":
                self.fixes.append(Fix(now, msg.time_boot_ms, msg.lat, msg.lon, msg.relative_alt))
            elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                self.heartbeats.append((now, msg.custom_mode, bool(msg.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)))
            elif kind == "MISSION_CURRENT":
                self.mission_ids.append((now, msg.seq, getattr(msg, "total", 0),
                                         extension_u32(msg, "mission_id", MISSION_CURRENT_ID_OFFSET)))
            elif kind == "STATUSTEXT":
                self.texts.append((now, str(msg.text)))

    # --- waiting --------------------------------------------------------------------------------
    def wait(self, condition: Any, timeout_s: float, what: str) -> None:
        deadline = time.monotonic() + timeout_s
        while not condition():
            if self.proc is not None and self.proc.poll() is not None:
                raise RuntimeError(f"PX4 exited with {self.proc.returncode} waiting for {what}: "
                                   f"{self.output()[-1500:]}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"PX4: no {what} within {timeout_s:g} s; heard "
                                   f"{[t for _, t in self.texts][-10:]}")
            time.sleep(0.05)

    def wait_text(self, pattern: str, timeout_s: float = 60.0, since: float = 0.0) -> str:
        """The first STATUSTEXT matching ``pattern`` heard after ``since`` (monotonic)."""
        regex = re.compile(pattern)
        found: list[str] = []

        def heard() -> bool:
            found.extend(text for at, text in list(self.texts) if at >= since and regex.search(text))
            return bool(found)

        self.wait(heard, timeout_s, f"STATUSTEXT matching {pattern!r}")
        return found[0]

    def wait_ready(self, timeout_s: float = 90.0) -> None:
        """Until PX4's pre-arm checks pass (SYS_STATUS) with home set: it can arm and fly."""
        def ready() -> bool:
            status, home = self.last.get("SYS_STATUS"), self.last.get("HOME_POSITION")
            return (status is not None and home is not None
                    and bool(status.onboard_control_sensors_health & PREARM_OK))

        self.wait(ready, timeout_s, "pre-arm checks passed and home")

    # --- the pilot's ground station --------------------------------------------------------------
    def send(self, build: Any) -> None:
        """Send on the monitor's (the ground station's) link: ``build(conn.mav)``."""
        build(self._conn.mav)

    def mode(self) -> tuple[int, bool] | None:
        """(custom_mode, armed) of the last heartbeat."""
        with self._lock:
            return self.heartbeats[-1][1:] if self.heartbeats else None
