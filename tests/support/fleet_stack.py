"""A fleet on loopback for the end-to-end tests: two zenoh routers meshed, and for each UAV a
vehicle stub and its own ``serve`` (its journal, its layer), a client of both routers; the
simulated users submit to the fleet through one router. Every process is stopped at the end."""

from __future__ import annotations

import socket
import sqlite3
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from planner_service.harness.processes import Child, free_port
from planner_service.service.config import OriginConfig, build_config, to_toml
from planner_service.model.fleet.claims import Claim
from planner_service.service.fleet.ledger import claims_of
from protocol import Event, FleetKeys, GeoOrigin, ProtocolError, Status, local_to_global
from protocol.fleet_signing import FleetVerifier, Unverified, make_vehicle_key, read_roster
from protocol.messages import FleetIntentions, FleetPosition, decode
from protocol.zenoh_config import session_config


@dataclass
class Uav:
    vehicle: str
    folder: Path
    stub: Child | None
    """The vehicle stub; None: an autopilot of the test's own (SITL)."""
    service: Child

    @property
    def journal(self) -> Path:
        return self.folder / "journal.sqlite"

    def rows(self, sql: str) -> list[tuple[Any, ...]]:
        """Its journal, read as another process would (read-only, beside the WAL writer)."""
        db = sqlite3.connect(f"file:{self.journal}?mode=ro", uri=True)
        try:
            return db.execute(sql).fetchall()
        finally:
            db.close()

    def services(self) -> list[tuple[str, int]]:
        """(user id, tasks) of every service it recorded."""
        return self.rows("SELECT r.user_id, s.tasks FROM services s JOIN requests r USING (request_id) "
                         "ORDER BY s.service_id")


class Intentions:
    """Every member's intentions as published (``{prefix}/fleet/intentions/*``), with when
    each arrived: what each UAV meant to do, read from the wire as any client would."""

    def __init__(self, endpoint: str, roster: Path) -> None:
        self.session = zenoh.open(session_config("client", connect=[endpoint]))
        self.seen: list[tuple[float, FleetIntentions]] = []
        self._lock = threading.Lock()
        self._verifier = FleetVerifier(read_roster(roster))
        self._sub = self.session.declare_subscriber(FleetKeys().all_intentions, self._on)

    def _on(self, sample: Any) -> None:
        key = str(sample.key_expr)
        try:  # a member's, signed (as a member reads them)
            body, _ = self._verifier.open(key, FleetKeys().vehicle_of(key) or "", sample.payload.to_bytes(),
                                          time.time(), 900.0)
        except Unverified:
            return
        message = decode(body, FleetIntentions)
        with self._lock:
            self.seen.append((time.monotonic(), message))

    def claims(self) -> dict[str, dict[str, Claim]]:
        """Each vehicle's latest claims (vehicle -> user -> claim)."""
        with self._lock:
            last = {m.vehicle: m for _, m in self.seen}
        return {v: claims_of(m) for v, m in last.items()}

    def said(self, vehicle: str) -> list[FleetIntentions]:
        """Every intentions message of ``vehicle``, in the order they arrived."""
        with self._lock:
            return [m for _, m in self.seen if m.vehicle == vehicle]

    def since(self, vehicle: str, t: float) -> list[tuple[float, set[str]]]:
        with self._lock:
            return [(at, {i.user_id for i in m.users}) for at, m in self.seen if m.vehicle == vehicle and at >= t]

    def close(self) -> None:
        self._sub.undeclare()
        self.session.close()


class Positions:
    """Every member's vehicle positions as its autopilot reported them (the signed positions on
    ``{prefix}/fleet/positions/*``, in the fleet's one local frame), with when each arrived
    (this process's monotonic clock): the vehicles side by side in one time."""

    def __init__(self, endpoint: str, roster: Path) -> None:
        self.session = zenoh.open(session_config("client", connect=[endpoint]))
        self.seen: list[tuple[float, str, float, float, float, bool]] = []
        """(arrived, vehicle, x, y, z, armed)."""
        self._lock = threading.Lock()
        self._verifier = FleetVerifier(read_roster(roster))
        self._sub = self.session.declare_subscriber(FleetKeys().positions, self._on)

    def _on(self, sample: Any) -> None:
        key = str(sample.key_expr)
        vehicle = FleetKeys().vehicle_of(key) or ""
        try:
            body, _ = self._verifier.open(key, vehicle, sample.payload.to_bytes(), time.time(), 60.0)
            p = decode(body, FleetPosition)
        except (Unverified, ProtocolError):
            return
        with self._lock:
            self.seen.append((time.monotonic(), vehicle, p.x_m, p.y_m, p.z_m, p.armed))

    def pairs(self, within_s: float = 0.3) -> list[tuple[float, str, str, float, float]]:
        """Each armed pair's positions reported within ``within_s`` of each other, in arrival
        order: (when, a, b, horizontal m, vertical m)."""
        with self._lock:
            rows = sorted(r for r in self.seen if r[5])
        out = []
        last: dict[str, tuple[float, float, float, float]] = {}
        for at, v, x, y, z, _ in rows:
            for w, (t, wx, wy, wz) in last.items():
                if w != v and at - t <= within_s:
                    out.append((at, min(v, w), max(v, w), ((x - wx) ** 2 + (y - wy) ** 2) ** 0.5, abs(z - wz)))
            last[v] = (at, x, y, z)
        return out

    def stacked(self, radius_m: float, at_least_s: float) -> list[str]:
        """Pairs that stood within ``radius_m`` of each other horizontally (over one point,
        whatever their layers) for ``at_least_s`` or longer: "uav1-uav2 8.2 s"."""
        since: dict[tuple[str, str], float] = {}
        longest: dict[tuple[str, str], float] = {}
        for at, a, b, horizontal, _ in self.pairs():
            if horizontal < radius_m:
                start = since.setdefault((a, b), at)
                longest[(a, b)] = max(longest.get((a, b), 0.0), at - start)
            else:
                since.pop((a, b), None)
        return [f"{a}-{b} {t:.1f} s" for (a, b), t in sorted(longest.items()) if t >= at_least_s]

    def close(self) -> None:
        self._sub.undeclare()
        self.session.close()


class Arrivals:
    """Every member's arrivals at its points, from its own events (``waypoint_reached``, stamped
    with its service's wall clock, the clock of its intentions' ``time_s``)."""

    def __init__(self, endpoint: str, prefix: str = "uavmec") -> None:
        self.session = zenoh.open(session_config("client", connect=[endpoint]))
        self.seen: list[tuple[str, int, float]] = []
        """(vehicle, hovering point, time_s) of each arrival."""
        self._lock = threading.Lock()
        self._sub = self.session.declare_subscriber(f"{prefix}/*/events", self._on)

    def _on(self, sample: Any) -> None:
        try:
            event = decode(sample.payload.to_bytes(), Event)
        except ProtocolError:
            return
        head = event.detail.split(":", 1)[0]
        if event.event == "waypoint_reached" and head.startswith("point ") and head[6:].isdigit():
            with self._lock:
                self.seen.append((str(sample.key_expr).split("/")[1], int(head[6:]), event.time_s))

    def of(self, vehicle: str) -> list[tuple[int, float]]:
        with self._lock:
            return [(k, t) for v, k, t in self.seen if v == vehicle]

    def close(self) -> None:
        self._sub.undeclare()
        self.session.close()


ENROLLED = 6
"""Vehicles uav1..uav6 are enrolled in every stack's fleet."""


class FleetStack:
    """Two meshed routers (``endpoints``), and UAVs added with ``uav``."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.endpoints = [f"tcp/127.0.0.1:{free_port()}" for _ in range(2)]
        first = zenoh.open(session_config("router", listen=[self.endpoints[0]]))
        second = zenoh.open(session_config("router", listen=[self.endpoints[1]], connect=[self.endpoints[0]]))
        self.routers: list[Any] = [first, second]
        self.children: list[Child] = []
        self.uavs: dict[str, Uav] = {}
        self.keys = tmp / "fleet-keys"
        """Each UAV's fleet key and the fleet's roster (``roster``), made as ``fleet-key`` does,
        for every vehicle a test may start (a service reads the roster when it starts)."""
        self.keys.mkdir(mode=0o700)
        self.roster = self.keys / "roster"
        for n in range(1, ENROLLED + 1):
            make_vehicle_key(self.keys / f"uav{n}.key", self.roster, f"uav{n}")

    def enrol(self, vehicle: str) -> dict[str, str]:
        """``vehicle``'s service's ``[fleet]`` enrolment settings."""
        return {"fleet.key_file": str(self.keys / f"{vehicle}.key"), "fleet.roster_file": str(self.roster)}

    def uav(self, vehicle: str, altitude_m: float, speedup: str, home_east_m: float = 0.0, autopilot: str = "",
            **overrides: str) -> Uav:
        """A vehicle stub standing ``home_east_m`` east of the fleet's origin (two UAVs cannot
        stand on one spot, nor climb through each other's layers there) and its service, a
        fleet member in its own layer, in the fleet's one local frame."""
        folder = self.tmp / vehicle
        folder.mkdir()
        port = free_port(socket.SOCK_DGRAM)
        stub = None
        if not autopilot:  # else the autopilot at that address (SITL), standing where it was started
            stub = Child("sim_bridge", ["vehicle", "--mavlink", f"udpin:127.0.0.1:{port}", "--speedup", speedup,
                                        "--gps-delay-s", "2", "--disarm-delay-s", "0",
                                        "--origin", home(home_east_m), "--track", str(folder / "track.csv")],
                         folder / "vehicle.log")
            self.children.append(stub)
            stub.wait_ready("listening")
        settings = {"zenoh.mode": "peer", "zenoh.listen": f"tcp/127.0.0.1:{free_port()}", "zenoh.connect": ",".join(self.endpoints),
                    "zenoh.vehicle": vehicle, "mavlink.url": autopilot or f"udpout:127.0.0.1:{port}",
                    "journal.path": str(folder / "journal.sqlite"), "planner.budget_ms": "100",
                    "fleet.enabled": "true", "fleet.discovery_s": "1.0", "scenario.altitude_m": str(altitude_m),
                    **self.enrol(vehicle), **overrides}
        config = build_config({}, settings)
        path = folder / "planner.toml"
        path.write_text(to_toml(config))
        service = Child("planner_service", ["serve", "--config", str(path)], folder / "service.log")
        self.children.append(service)
        service.wait_ready("ready:", 90.0)
        self.uavs[vehicle] = Uav(vehicle, folder, stub, service)
        return self.uavs[vehicle]

    def users(self, *extra: str) -> Child:
        """The simulated users, submitting to the fleet, connected to both routers."""
        connect = [arg for e in self.endpoints for arg in ("--connect", e)]
        child = Child("sim_bridge", ["users", "--fleet", *connect, *extra],
                      self.tmp / "users.log")
        self.children.append(child)
        return child

    def kill_router(self, index: int) -> None:
        self.routers[index].close()

    def logs(self) -> str:
        return "\n".join(f"--- {c.name}\n{c.log()[-3000:]}" for c in self.children)

    def close(self) -> None:
        for child in reversed(self.children):
            child.stop()
        for router in self.routers:
            try:
                router.close()
            except zenoh.ZError:
                pass


def home(east_m: float) -> str:
    """LAT,LON,ALT ``east_m`` east of the services' default origin: a stub's ``--origin``, with
    a heading (",0") SITL's ``--home``."""
    o = OriginConfig()
    lat, lon, alt = local_to_global(GeoOrigin(o.lat_deg, o.lon_deg, o.alt_m), east_m, 0.0, 0.0)
    return f"{lat:.7f},{lon:.7f},{alt:.2f}"
