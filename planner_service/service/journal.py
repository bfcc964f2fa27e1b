"""The SQLite journal: every accepted request, every service, every uploaded mission.

A request is written (and, with ``synchronous = FULL``, synced) before it is acked, so an
ack is a promise that survives a crash. WAL mode lets readers (a test, the demo's summary)
read while the service writes. A restart opens the same file and resumes: pending requests
are still pending, service counts (the fairness rule) and the last mission are kept.

Request life: ``pending`` -> ``served`` (a service row names it), ``replaced`` (the user's
newer request took its place) or ``not_served`` (the sortie ended without it; ``reason``
says why). Nothing is ever deleted.
"""

from __future__ import annotations

import json
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from .errors import JournalError

SCHEMA = """
CREATE TABLE IF NOT EXISTS requests (
    request_id INTEGER PRIMARY KEY AUTOINCREMENT,
    user_id TEXT NOT NULL,
    x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL,
    tasks INTEGER NOT NULL,
    client_ref TEXT,
    accepted_at_s REAL NOT NULL,
    status TEXT NOT NULL DEFAULT 'pending'
        CHECK (status IN ('pending', 'served', 'replaced', 'not_served')),
    reason TEXT NOT NULL DEFAULT '',
    closed_at_s REAL
);
CREATE INDEX IF NOT EXISTS requests_by_user ON requests (user_id, status);
-- pending() runs for every request and status: without it a long journal is scanned each time
CREATE INDEX IF NOT EXISTS requests_by_status ON requests (status);
CREATE TABLE IF NOT EXISTS services (
    service_id INTEGER PRIMARY KEY AUTOINCREMENT,
    request_id INTEGER NOT NULL REFERENCES requests (request_id),
    user_id TEXT NOT NULL,
    tasks INTEGER NOT NULL,
    bits REAL NOT NULL,
    hover_index INTEGER NOT NULL,
    x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL,
    reward REAL NOT NULL,
    battery_j REAL NOT NULL,
    time_s REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS missions (
    mission_id INTEGER PRIMARY KEY AUTOINCREMENT,
    plan_id INTEGER NOT NULL,
    time_s REAL NOT NULL,
    result TEXT NOT NULL,
    items TEXT NOT NULL,
    points TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""


@dataclass(frozen=True)
class RequestRow:
    request_id: int
    user_id: str
    x_m: float
    y_m: float
    z_m: float
    tasks: int
    client_ref: str | None
    accepted_at_s: float
    status: str
    reason: str


@dataclass(frozen=True)
class UserRow:
    """A user the service has heard from: where it last said it was, how often served."""

    user_id: str
    x_m: float
    y_m: float
    z_m: float
    services: int


@dataclass(frozen=True)
class ServiceRow:
    service_id: int
    request_id: int
    user_id: str
    tasks: int
    bits: float
    hover_index: int
    x_m: float
    y_m: float
    z_m: float
    reward: float
    battery_j: float
    time_s: float


@dataclass(frozen=True)
class MissionRow:
    mission_id: int
    plan_id: int
    time_s: float
    result: str
    items: list[dict[str, Any]]
    points: list[dict[str, Any]]


class Journal:
    """One SQLite connection, used from one thread (the service's event loop)."""

    def __init__(self, path: str | Path, synchronous: str = "FULL") -> None:
        self.path = str(path)
        try:
            if self.path != ":memory:":
                Path(self.path).parent.mkdir(parents=True, exist_ok=True)
            self._db = sqlite3.connect(self.path, isolation_level=None)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute(f"PRAGMA synchronous={synchronous.upper()}")
            self._db.execute("PRAGMA foreign_keys=ON")
            self._db.executescript(SCHEMA)
        except sqlite3.Error as err:
            raise JournalError(f"cannot open the journal {self.path}: {err}") from None

    # --- writing --------------------------------------------------------------------------
    def _write(self, what: str, statements: Iterable[tuple[str, tuple[Any, ...]]]) -> list[int]:
        """Run ``statements`` in one transaction; the lastrowid of each."""
        ids: list[int] = []
        try:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                for sql, args in statements:
                    ids.append(int(self._db.execute(sql, args).lastrowid or 0))
                self._db.execute("COMMIT")
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
        except sqlite3.Error as err:
            raise JournalError(f"{what}: {err}") from None
        return ids

    def accept(self, user_id: str, x_m: float, y_m: float, z_m: float, tasks: int,
               client_ref: str | None, now_s: float) -> tuple[int, list[int]]:
        """Journal a validated request; the user's pending requests become ``replaced``.
        Returns (the new request id, the ids it replaced)."""
        older = [r.request_id for r in self.pending() if r.user_id == user_id]
        try:
            self._db.execute("BEGIN IMMEDIATE")
            try:
                request_id = int(self._db.execute(
                    "INSERT INTO requests (user_id, x_m, y_m, z_m, tasks, client_ref, accepted_at_s) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?)", (user_id, x_m, y_m, z_m, tasks, client_ref, now_s)).lastrowid)
                for rid in older:
                    self._db.execute(
                        "UPDATE requests SET status = 'replaced', reason = ?, closed_at_s = ? "
                        "WHERE request_id = ? AND status = 'pending'", (f"replaced by request {request_id}", now_s, rid))
                self._db.execute("COMMIT")
            except BaseException:
                self._db.execute("ROLLBACK")
                raise
        except sqlite3.Error as err:
            raise JournalError(f"accept: {err}") from None
        return request_id, older

    def record_service(self, request_id: int, hover_index: int, xyz: tuple[float, float, float], tasks: int,
                       bits: float, reward: float, battery_j: float, now_s: float) -> int:
        """The vehicle served ``tasks`` tasks of ``request_id`` at hovering point ``hover_index``."""
        row = self.request(request_id)
        if row is None or row.status != "pending":
            raise JournalError(f"record_service: request {request_id} is not pending")
        service_id, _ = self._write("record_service", [
            ("INSERT INTO services (request_id, user_id, tasks, bits, hover_index, x_m, y_m, z_m, reward, "
             "battery_j, time_s) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
             (request_id, row.user_id, tasks, bits, hover_index, *xyz, reward, battery_j, now_s)),
            ("UPDATE requests SET status = 'served', closed_at_s = ? WHERE request_id = ?", (now_s, request_id)),
        ])
        return service_id

    def close_pending(self, reasons: dict[int, str], now_s: float) -> None:
        """Pending requests the sortie will not serve, each with its reason."""
        self._write("close_pending", [(
            "UPDATE requests SET status = 'not_served', reason = ?, closed_at_s = ? "
            "WHERE request_id = ? AND status = 'pending'", (reason, now_s, rid)) for rid, reason in reasons.items()])

    def record_mission(self, plan_id: int, items: list[dict[str, Any]], points: list[dict[str, Any]],
                       result: str, now_s: float) -> int:
        (mission_id,) = self._write("record_mission", [(
            "INSERT INTO missions (plan_id, time_s, result, items, points) VALUES (?, ?, ?, ?, ?)",
            (plan_id, now_s, result, json.dumps(items), json.dumps(points)))])
        return mission_id

    def set_meta(self, key: str, value: str) -> None:
        self._write("set_meta", [("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, value))])

    # --- reading --------------------------------------------------------------------------
    def _rows(self, sql: str, args: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        try:
            return self._db.execute(sql, args).fetchall()
        except sqlite3.Error as err:
            raise JournalError(f"read: {err}") from None

    def request(self, request_id: int) -> RequestRow | None:
        rows = self._rows(f"SELECT {_REQ} FROM requests WHERE request_id = ?", (request_id,))
        return RequestRow(*rows[0]) if rows else None

    def requests(self) -> list[RequestRow]:
        return [RequestRow(*r) for r in self._rows(f"SELECT {_REQ} FROM requests ORDER BY request_id")]

    def pending(self) -> list[RequestRow]:
        """Pending requests in arrival order (at most one per user)."""
        return [RequestRow(*r) for r in self._rows(
            f"SELECT {_REQ} FROM requests WHERE status = 'pending' ORDER BY request_id")]

    def pending_count(self) -> int:
        return int(self._rows("SELECT COUNT(*) FROM requests WHERE status = 'pending'")[0][0])

    def user_ids(self) -> set[str]:
        """Every user id that has a request in the journal."""
        return {r[0] for r in self._rows("SELECT DISTINCT user_id FROM requests")}

    def users(self) -> list[UserRow]:
        """Every user heard from, in order of first request; position from its latest."""
        rows = self._rows(
            "SELECT r.user_id, r.x_m, r.y_m, r.z_m, "
            "(SELECT COUNT(*) FROM services s WHERE s.user_id = r.user_id) "
            "FROM requests r JOIN (SELECT user_id, MIN(request_id) AS first, MAX(request_id) AS last "
            "FROM requests GROUP BY user_id) u ON r.request_id = u.last ORDER BY u.first")
        return [UserRow(*r) for r in rows]

    def services(self) -> list[ServiceRow]:
        return [ServiceRow(*r) for r in self._rows(
            "SELECT service_id, request_id, user_id, tasks, bits, hover_index, x_m, y_m, z_m, reward, "
            "battery_j, time_s FROM services ORDER BY service_id")]

    def missions(self) -> list[MissionRow]:
        return [MissionRow(r[0], r[1], r[2], r[3], json.loads(r[4]), json.loads(r[5])) for r in self._rows(
            "SELECT mission_id, plan_id, time_s, result, items, points FROM missions ORDER BY mission_id")]

    def last_mission(self, result: str | None = "accepted") -> MissionRow | None:
        rows = [m for m in self.missions() if result is None or m.result == result]
        return rows[-1] if rows else None

    def get_meta(self, key: str, default: str | None = None) -> str | None:
        rows = self._rows("SELECT value FROM meta WHERE key = ?", (key,))
        return rows[0][0] if rows else default

    def close(self) -> None:
        """Checkpoint the WAL into the main file and close."""
        try:
            self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            self._db.close()
        except sqlite3.Error as err:
            raise JournalError(f"close: {err}") from None


_REQ = "request_id, user_id, x_m, y_m, z_m, tasks, client_ref, accepted_at_s, status, reason"
