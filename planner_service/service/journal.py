"""The SQLite journal: every accepted request, every service, every uploaded mission.

A request is written (and, with ``synchronous = FULL``, synced) before it is acked, so an
ack is a promise that survives a crash. WAL mode lets readers (a test, the demo's summary)
read while the service writes. A restart opens the same file and resumes: pending requests
are still pending, service counts (the fairness rule) and the last mission are kept.

Requests are data waiting (docs/PROTOCOL.md, "Requests"): each request a user sends is a
row, the statement of its whole backlog then, and its newest row is the request in force;
the ack's request id names that row, and the older rows stay as the history. Request life:
``pending`` (waiting; ``RequestRow.backlog`` is what is left of it) -> ``served`` (services
consumed all of it, or the sortie ended after a service of part of it; ``reason`` says what
was left), ``replaced`` (the user's newer request took its place; ``reason`` names it) or
``not_served`` (a request of no tasks, or of none left, closed as it arrives, or the sortie
ended without serving it; ``reason`` says why). Nothing is ever deleted.

A service names the request in force when its hold began (the loop binds to it); it
consumes its tasks from that request's backlog while the request is in force. A newer
request from the user is its whole backlog as the user knows it then, and replaces the
older one's backlog as it stands.

What a request's backlog is (``RequestRow.backlog``): a request that says ``served_seen``
(the tasks of the user served in this sortie that its count had already taken off) states
that the user had ``tasks + served_seen`` in the sortie, so what is left of it is that
less every task served to the user in the sortie (``tasks - (user_served - served_seen)``),
whichever request the services named and whenever they were recorded: a service recorded
after the user counted (one that crossed its request on the wire, or a hold that ended
after it) is never counted twice. A request that does not say it (an older client's) is
taken as it is: its tasks less those of the services naming it. Either way a request
never gives back what services naming it consumed, and a service that empties the user's
request in force, whichever request it named, closes it ``served``.

Sorties: one file holds every sortie of a service's life. ``sorties`` has a row per sortie
(number, started, ended, why); requests, services and missions carry the sortie they
belong to, and every query the service makes (pending, services, users, missions, the last
mission) reads the current sortie only, through an index, so the work and memory of a
decision stay bounded however many sorties the file holds. Fairness counts are per sortie
(the paper's rule (3), (9c) is per sortie). Plan and request ids run on across sorties.

Schema versions (``meta.schema_version``): 1, one sortie per file (no version row);
2, sorties; 3, ``requests.served_seen``. An older file is migrated in place on open (a
version-1 file's rows become sortie 1, ended if its meta said ``sortie_over``; the
requests of a version-2 file said no ``served_seen``: NULL); a file from a newer version
is refused.

The file (this module's own guarantees, apart from what the rows mean):

- **One service per journal.** ``Journal`` takes an exclusive ``flock`` on the database
  file itself (the file its path leads to: symlinks and hard links to it share the lock)
  before it touches the database, and holds it until ``close``; a second one is refused,
  naming the holder's pid where ``/proc/locks`` shows it. No file stands for the lock, so
  none can be deleted to get round it, and the kernel drops the lock when its process
  dies: a SIGKILLed service leaves nothing stale. SQLite's own locks are POSIX byte-range
  locks, which on Linux do not see a ``flock``, so readers still read. (SQLite's
  ``locking_mode = EXCLUSIVE`` would also keep out the readers the WAL is there for: the
  demo's summary, the tests, an operator's ``sqlite3``; and it names nobody.)
- **Only a journal is a journal.** A path that does not exist is created fresh, atomically
  (built as ``PATH.new``, locked, then linked into place with the lock held: a crash leaves
  no half-made journal, and two services starting together get one journal and one lock). An
  existing file must be an SQLite database carrying ``APPLICATION_ID`` (or, from before
  the id, the tables every layout has had: it is then stamped): an empty file, a file that is
  not SQLite, another application's database, or an SQLite file without our tables is
  refused, never taken as fresh, never written.
- **Fail loud.** A write that fails (disk or database full, I/O error, read-only file) is
  rolled back if SQLite has not already done so, and raises ``JournalError`` saying what
  happened in words; a storage failure also sets ``failed`` (why, one line), after which
  every write is refused at once (reads still answer from the open file), so the service
  can degrade instead of carrying on without a record. Before every write, and whenever
  ``check()`` is called, the path is compared with the file open (device and inode, the
  database and its WAL): a journal deleted or replaced under the service fails the same
  way, and what it held is first copied to ``PATH.rescued-TIME`` (SQLite's backup API, from
  the still open file), since everything in it would otherwise be lost at close.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3
import stat
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterable, Iterator

from protocol.file_lock import lock_or_holder, names

from .errors import JournalError
from .rows import MissionRow, RequestRow, ServiceRow, SortieRow, UserBacklog, UserRow

SCHEMA_VERSION = 4
"""The layout this module writes (``meta.schema_version``)."""
APPLICATION_ID = int.from_bytes(b"uavj", "big")
"""SQLite's ``PRAGMA application_id`` of a journal (0x7561766a, "uavj" in the header at
offset 68): what tells our file from any other SQLite database. ``file PATH`` shows it."""
SQLITE_MAGIC = b"SQLite format 3\x00"
LEGACY_TABLES = frozenset({"requests", "services", "missions", "meta"})
"""The tables every journal has had: a file without the application id (written before
it existed) is taken as a journal only if it holds them all."""
LOCK_TRIES = 5
"""Looks at the journal's path before ``Journal`` gives up, when each finds it changed by
another process (created, replaced, removed) between opening the file and locking it."""
TRANSIENT_CODES = frozenset({5, 6, 19})
"""SQLite's primary result codes BUSY, LOCKED and CONSTRAINT: the file is still sound
(another connection held a lock; a row broke a constraint), so the write is refused but
the journal is not marked failed. Any other error of a write is the storage failing."""
DAMAGE_CODES = frozenset({11, 26})
"""SQLite's CORRUPT and NOTADB: what is wrong is the file itself, not the storage under it."""
_STORAGE_WORDS = {
    13: "the disk (or the database's size limit) is full",  # SQLITE_FULL
    10: "an I/O error",  # SQLITE_IOERR
    8: "the file is read-only",  # SQLITE_READONLY
    11: "the file is damaged",  # SQLITE_CORRUPT
    26: "the file is not a database any more",  # SQLITE_NOTADB
    14: "the file cannot be opened",  # SQLITE_CANTOPEN
    3: "permission denied",  # SQLITE_PERM
}

TABLES = """
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
    closed_at_s REAL,
    sortie INTEGER NOT NULL DEFAULT 1,
    served_seen INTEGER
);
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
    time_s REAL NOT NULL,
    sortie INTEGER NOT NULL DEFAULT 1,
    bound_tasks INTEGER
);
CREATE TABLE IF NOT EXISTS missions (
    mission_id INTEGER PRIMARY KEY AUTOINCREMENT,
    plan_id INTEGER NOT NULL,
    time_s REAL NOT NULL,
    result TEXT NOT NULL,
    items TEXT NOT NULL,
    points TEXT NOT NULL,
    sortie INTEGER NOT NULL DEFAULT 1
);
CREATE TABLE IF NOT EXISTS sorties (
    number INTEGER PRIMARY KEY,
    started_at_s REAL NOT NULL,
    ended_at_s REAL,
    why TEXT NOT NULL DEFAULT ''
);
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
"""

INDEXES = """
CREATE INDEX IF NOT EXISTS requests_by_user ON requests (user_id, status);
-- pending(), users() and the fairness counts run for every request and decision: through
-- these indexes they read the current sortie only, however long the journal
CREATE INDEX IF NOT EXISTS requests_by_sortie ON requests (sortie, status, user_id);
CREATE INDEX IF NOT EXISTS services_by_sortie ON services (sortie, user_id);
CREATE INDEX IF NOT EXISTS missions_by_sortie ON missions (sortie, result);
-- a request's backlog is its tasks less those of the services that name it
CREATE INDEX IF NOT EXISTS services_by_request ON services (request_id);
"""
MIGRATE_1_TO_2 = [
    "ALTER TABLE requests ADD COLUMN sortie INTEGER NOT NULL DEFAULT 1",
    "ALTER TABLE services ADD COLUMN sortie INTEGER NOT NULL DEFAULT 1",
    "ALTER TABLE missions ADD COLUMN sortie INTEGER NOT NULL DEFAULT 1",
]
"""Version 1 had one sortie per file: every row belongs to sortie 1."""
MIGRATE_2_TO_3 = [
    "ALTER TABLE requests ADD COLUMN served_seen INTEGER",
]
"""Version 2's requests said nothing of what their users knew was served: NULL, taken as
they are (``RequestRow.backlog``)."""
MIGRATE_3_TO_4 = [
    "ALTER TABLE services ADD COLUMN bound_tasks INTEGER",
]
"""Version 3's services did not say the backlog their hold was bound to: NULL, taken as the
tasks served (``ServiceRow.bound``)."""


class Journal:
    """One SQLite connection, used from one thread (the service's event loop).

    ``sortie`` is the current sortie's number: the last one in the file, running or over.
    A new file starts sortie 1 at ``now_s`` (default: the wall clock).

    ``failed`` is None while the journal can be written; after a storage failure (see the
    module's docstring) it says why, in one line, and every write raises ``JournalError``."""

    def __init__(self, path: str | Path, synchronous: str = "FULL", now_s: float | None = None) -> None:
        self.path = str(path)
        self.failed: str | None = None
        self.rescued: str | None = None
        """Where the journal's rows were copied when its file was deleted or replaced."""
        self._synchronous = synchronous.upper()
        self._lock_fd: int | None = None
        self._identity: dict[str, tuple[int, int]] = {}
        """(device, inode) of the database file and its WAL, as opened: the path must keep them."""
        self._closed = False
        now = time.time() if now_s is None else now_s
        memory = self.path == ":memory:"
        try:
            if not memory:
                try:
                    Path(self.path).parent.mkdir(parents=True, exist_ok=True)
                except OSError as err:
                    raise JournalError(f"cannot open the journal {self.path}: cannot create its folder: "
                                       f"{err.strerror or err}") from None
                self._lock_fd = self._lock_or_create(now)
                _check_file(self.path)
            self._db = self._connect(self.path, check=not memory)
        except BaseException:
            self._unlock()
            raise
        try:
            self._open_schema(now)
            (number,) = self._db.execute("SELECT MAX(number) FROM sorties").fetchone()
            if not memory:
                self._identity = _identities(self.path)
        except (sqlite3.Error, JournalError) as err:
            self._db.close()
            self._unlock()
            if isinstance(err, JournalError):
                raise
            raise JournalError(f"cannot open the journal {self.path}: {_words(err, self.path)}") from None
        self.sortie = int(number)

    def _connect(self, path: str, check: bool = False, doing: str = "open") -> sqlite3.Connection:
        """A connection in WAL mode; with ``check``, only after the file was found to be a
        journal (switching to WAL writes the header of a file that is not). ``doing`` is
        what a refusal says the service was doing with the journal: "open" or "create"."""
        try:
            db = sqlite3.connect(path, isolation_level=None)
        except sqlite3.Error as err:
            raise JournalError(f"cannot {doing} the journal {self.path}: {_words(err, path)}") from None
        try:
            if check:
                self._check_ours(db)
            db.execute("PRAGMA journal_mode=WAL")
            db.execute(f"PRAGMA synchronous={self._synchronous}")
            db.execute("PRAGMA foreign_keys=ON")
        except sqlite3.Error as err:
            db.close()
            raise JournalError(f"cannot {doing} the journal {self.path}: {_words(err, path)}") from None
        except JournalError:
            db.close()
            raise
        return db

    def _lock_or_create(self, now_s: float) -> int:
        """Lock the journal's file, first creating it if nothing is there: the descriptor
        that holds the lock. Another process may create or move the file between our look
        and our lock; each such race costs one more try."""
        real = os.path.realpath(self.path)
        for _ in range(LOCK_TRIES):
            fd = _lock(real, self.path)
            if fd is None:
                fd = self._create(real, now_s)
            if fd is not None:
                return fd
        raise JournalError(f"cannot open the journal {self.path}: {real} kept being created, replaced or removed "
                           f"while this service tried to lock it ({LOCK_TRIES} tries); is another program using it?")

    def _create(self, real: str, now_s: float) -> int | None:
        """A fresh journal at ``real``, built beside it and linked into place complete, so
        that no crash leaves an empty or half-made file there (which would be refused). The
        file is locked before it is built and linked with the lock held: the descriptor
        returned holds the journal's lock. None if another process made the journal first."""
        building = f"{real}.new"
        fd = _lock(building, self.path, create=True)
        if fd is None:
            return None  # another creator moved it away under us: look again
        try:
            _remove(f"{building}-wal", f"{building}-shm")  # ours: we hold their database's lock
            info = os.fstat(fd)
            if info.st_size or info.st_nlink != 1:
                # a crashed creation's leftover (which may also be linked elsewhere): away
                # with its name, never its contents, and start again
                _remove(building)
                os.close(fd)
                return None
            self._db = self._connect(building, doing="create")
            try:
                self._open_schema(now_s)
                self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
            except sqlite3.Error as err:
                raise JournalError(f"cannot create the journal {self.path}: {_words(err, building)}") from None
            finally:
                self._db.close()  # the last connection: the WAL is folded in and removed
            try:
                os.link(building, real)  # fails if anything appeared there meanwhile
            except FileExistsError:
                _remove(building)
                os.close(fd)
                return None
            _remove(building)
            _sync_folder(real)
        except BaseException as err:
            _remove_quietly(building, f"{building}-wal", f"{building}-shm")  # a full disk wants its room back
            os.close(fd)
            if isinstance(err, OSError):
                raise JournalError(f"cannot create the journal {self.path}: {err.strerror or err}") from None
            raise
        return fd

    def _check_ours(self, db: sqlite3.Connection) -> None:
        """Refuse an SQLite database that is not a journal (another application's, or one
        without our tables); a journal from before the application id is stamped by
        ``_open_schema``. Reads only."""
        try:
            (app_id,) = db.execute("PRAGMA application_id").fetchone()
            tables = {name for (name,) in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        except sqlite3.Error as err:
            if _primary(err) in _STORAGE_WORDS and _primary(err) not in DAMAGE_CODES:
                # the storage failed (a full disk: SQLite cannot make the WAL's shared
                # memory), not the file: saying "not a journal" would send the pilot after
                # a sound journal
                raise JournalError(f"cannot open the journal {self.path}: {_words(err, self.path)}") from None
            raise JournalError(f"{self.path} is not a journal, or a damaged one: SQLite cannot read it ({err}); "
                               "refused, not written") from None
        if app_id == APPLICATION_ID:
            if not LEGACY_TABLES <= tables:
                raise JournalError(f"the journal {self.path} has the journal's application id but not its tables "
                                   f"(missing {sorted(LEGACY_TABLES - tables)}): damaged; refused")
            return
        if app_id != 0:
            raise JournalError(f"{self.path} is not a journal: it is another application's SQLite database "
                               f"(application_id {app_id:#x}; a journal's is {APPLICATION_ID:#x}); refused, "
                               "not written")
        if not LEGACY_TABLES <= tables:
            shown = ", ".join(sorted(tables)[:6]) or "none"
            raise JournalError(f"{self.path} is not a journal: an SQLite database without the journal's "
                               f"application id or tables (its tables: {shown}); refused, not written")

    def _schema_version(self) -> int:
        """0 for a new file, 1 for the one-sortie layout (it had no version row)."""
        tables = {name for (name,) in self._db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        if "requests" not in tables:
            return 0
        row = self._db.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone() \
            if "meta" in tables else None
        if row is None:
            return 1
        try:
            return int(row[0])
        except ValueError:
            raise JournalError(f"the journal {self.path} has schema version {row[0]!r}, not a number") from None

    def _open_schema(self, now_s: float) -> None:
        """Create, migrate (1 -> 2 -> 3) or check the layout, in one transaction."""
        version = self._schema_version()
        if version > SCHEMA_VERSION:
            raise JournalError(f"the journal {self.path} has schema version {version}; this service reads "
                               f"versions up to {SCHEMA_VERSION}: run a newer service or use another file")
        with self._transaction():
            for statement in TABLES.split(";"):
                if statement.strip():
                    self._db.execute(statement)
            if version == 1:
                for statement in MIGRATE_1_TO_2:
                    self._db.execute(statement)
                over = self._db.execute("SELECT value FROM meta WHERE key = 'sortie_over'").fetchone()
                started, ended = self._db.execute(
                    "SELECT MIN(accepted_at_s), MAX(closed_at_s) FROM requests").fetchone()
                self._db.execute(
                    "INSERT INTO sorties (number, started_at_s, ended_at_s, why) VALUES (1, ?, ?, ?)",
                    (now_s if started is None else started,
                     None if over is None else (now_s if ended is None else ended), "" if over is None else over[0]))
                self._db.execute("DELETE FROM meta WHERE key = 'sortie_over'")  # now sorties.why
            if version in (1, 2):
                for statement in MIGRATE_2_TO_3:
                    self._db.execute(statement)
            if version in (1, 2, 3):
                for statement in MIGRATE_3_TO_4:
                    self._db.execute(statement)
            elif version == 0:
                self._db.execute("INSERT INTO sorties (number, started_at_s) VALUES (1, ?)", (now_s,))
            self._db.execute("INSERT OR REPLACE INTO meta (key, value) VALUES ('schema_version', ?)",
                             (str(SCHEMA_VERSION),))
            for statement in INDEXES.split(";"):
                if statement.strip():
                    self._db.execute(statement)
            self._db.execute(f"PRAGMA application_id = {APPLICATION_ID}")  # this file is a journal

    # --- writing --------------------------------------------------------------------------
    @contextmanager
    def _transaction(self) -> Iterator[None]:
        """One write transaction: committed at the end of the block, rolled back on any error.

        Refused at once (``JournalError``) if the journal failed or its file is no longer
        the one open. On a full disk or an I/O error SQLite rolls the transaction back
        itself; a ROLLBACK then would fail ("no transaction is active") and hide the
        cause, so it is sent only while a transaction is still open."""
        self._writable()
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield
            self._db.execute("COMMIT")
        except BaseException:
            if self._db.in_transaction:
                try:
                    self._db.execute("ROLLBACK")
                except sqlite3.Error:
                    pass  # the error that brought us here is the one to report
            raise

    def _write(self, what: str, statements: Iterable[tuple[str, tuple[Any, ...]]]) -> list[int]:
        """Run ``statements`` in one transaction; the lastrowid of each."""
        ids: list[int] = []
        try:
            with self._transaction():
                for sql, args in statements:
                    ids.append(int(self._db.execute(sql, args).lastrowid or 0))
        except sqlite3.Error as err:
            raise self._failure(what, err) from None
        return ids

    # --- the file's health ---------------------------------------------------------------------
    def _failure(self, what: str, err: sqlite3.Error) -> JournalError:
        """The ``JournalError`` for an SQLite error of ``what``; a storage failure (anything
        but a lock held elsewhere or a broken constraint) also marks the journal failed."""
        primary = _primary(err)
        name = getattr(err, "sqlite_errorname", None) or type(err).__name__
        if primary in TRANSIENT_CODES:
            return JournalError(f"{what}: {err} ({name}); nothing was written")
        words = _STORAGE_WORDS.get(primary, "SQLite failed")  # type: ignore[arg-type]
        reason = (f"the journal {self.path} cannot be written: {words} ({name}: {err}); the write ({what}) "
                  f"was rolled back and the journal takes no more writes")
        if self.failed is None:
            self.failed = reason
        return JournalError(f"{what}: {reason}")

    def _writable(self) -> None:
        if self._closed:
            raise JournalError(f"the journal {self.path} is closed")
        if self.check() is not None:
            raise JournalError(f"the journal failed and takes no more writes: {self.failed}")

    def check(self) -> str | None:
        """None while the journal can be written; otherwise why not (``failed``).

        Compares the path with the file open (the database and its WAL: device and
        inode). A file deleted or replaced under the service marks the journal failed,
        once, after copying its rows from the still open file to ``PATH.rescued-TIME``.
        Cheap (two ``stat`` calls): call it at every status tick; every write calls it."""
        if self.failed is not None or not self._identity:
            return self.failed
        why = _moved(self.path, self._identity)
        if why is not None:
            self.rescued, kept = self._rescue()
            self.failed = (f"the journal {self.path} {why} while the service ran: nothing more is written to it; "
                           f"{kept}")
        return self.failed

    def _rescue(self) -> tuple[str | None, str]:
        """Copy the open database (as this connection sees it, WAL included) to a new file
        beside the path: (its path or None, what happened in words)."""
        target = f"{self.path}.rescued-{time.strftime('%Y%m%dT%H%M%S')}-{os.getpid()}"
        if os.path.exists(target):
            return None, f"its rows could not be copied: {target} exists"
        try:
            copy = sqlite3.connect(target)
            try:
                self._db.backup(copy)
            finally:
                copy.close()
        except (sqlite3.Error, OSError) as err:
            return None, f"its rows could not be copied to {target}: {err}"
        return target, f"its rows were copied to {target}"

    def accept(self, user_id: str, x_m: float, y_m: float, z_m: float, tasks: int,
               client_ref: str | None, now_s: float, served_seen: int | None = None) -> tuple[int, list[int]]:
        """Journal a validated request in the current sortie: it becomes the user's request
        in force and its pending requests become ``replaced``. ``served_seen``: the tasks of
        the user served in this sortie that ``tasks`` has already taken off (None: not said;
        ``RequestRow.backlog``). A request with no tasks left (none stated, or all of them
        served since the user counted) closes as it arrives (``not_served``, "no tasks to
        offload"): nothing is waiting. Returns (the new request id, the ids it replaced)."""
        if self.current_sortie().over:
            raise JournalError(f"accept: sortie {self.sortie} is over; no request joins it")
        older = [int(r[0]) for r in self._rows(
            "SELECT request_id FROM requests WHERE sortie = ? AND user_id = ? AND status = 'pending'",
            (self.sortie, user_id))]
        left = RequestRow(0, user_id, x_m, y_m, z_m, tasks, client_ref, now_s, "pending", "", 0, served_seen,
                          self.served_tasks(user_id) if served_seen is not None else 0)
        try:
            with self._transaction():  # the replaced rows name the new id: not one _write
                request_id = int(self._db.execute(
                    "INSERT INTO requests (user_id, x_m, y_m, z_m, tasks, client_ref, accepted_at_s, sortie, "
                    "served_seen) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (user_id, x_m, y_m, z_m, tasks, client_ref, now_s, self.sortie, served_seen)).lastrowid)
                if left.backlog <= 0:
                    why = NO_TASKS if tasks <= 0 else (
                        f"{NO_TASKS}: its {tasks} tasks were served before it arrived ({left.user_served} served to "
                        f"the user in this sortie, {served_seen} of them taken off its count)")
                    self._db.execute(
                        "UPDATE requests SET status = 'not_served', reason = ?, closed_at_s = ? WHERE request_id = ?",
                        (why, now_s, request_id))
                for rid in older:
                    self._db.execute(
                        "UPDATE requests SET status = 'replaced', reason = ?, closed_at_s = ? "
                        "WHERE request_id = ? AND status = 'pending'", (f"replaced by request {request_id}", now_s, rid))
        except sqlite3.Error as err:
            raise self._failure("accept", err) from None
        return request_id, older

    def record_service(self, request_id: int, hover_index: int, xyz: tuple[float, float, float], tasks: int,
                       bits: float, reward: float, battery_j: float, now_s: float, bound_tasks: int | None = None) -> int:
        """The vehicle served ``tasks`` tasks of ``request_id`` (the request in force when
        the hold began, with ``bound_tasks`` left then: default ``tasks``, a whole service)
        at hovering point ``hover_index``. They are consumed from that
        request's backlog: if it is still in force (pending) and nothing is left it becomes
        ``served``, else it stays pending with the rest. If the user sent a newer request
        meanwhile (it is ``replaced``), the service is recorded against the request it was
        bound to; the newer one, the user's own count, loses these tasks too if it said
        ``served_seen`` (it counted them: they were served after it counted), and is left as
        it is if it did not (``RequestRow.backlog``). Either way, the user's request in force
        closes ``served`` if nothing is left of it."""
        rows = self._rows(f"SELECT {_REQ}, sortie FROM requests WHERE request_id = ?", (request_id,))
        if not rows or rows[0][-1] != self.sortie:
            raise JournalError(f"record_service: request {request_id} is not a request of sortie {self.sortie}")
        row = RequestRow(*rows[0][:-1])
        if row.status not in ("pending", "replaced"):
            raise JournalError(f"record_service: request {request_id} is {row.status}, not pending (nor replaced during "
                               f"the hold): no service can be recorded on it")
        if not 1 <= tasks <= row.backlog:
            raise JournalError(f"record_service: {tasks} tasks served of request {request_id}, whose backlog is "
                               f"{row.backlog} ({row.served_tasks} of its {row.tasks} already served)")
        bound = tasks if bound_tasks is None else bound_tasks
        if bound < tasks:
            raise JournalError(f"record_service: {tasks} tasks served of a hold bound to {bound}")
        try:
            with self._transaction():  # which requests it empties is read after the insert
                service_id = int(self._db.execute(
                    "INSERT INTO services (request_id, user_id, tasks, bits, hover_index, x_m, y_m, z_m, reward, "
                    "battery_j, time_s, sortie, bound_tasks) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (request_id, row.user_id, tasks, bits, hover_index, *xyz, reward, battery_j, now_s,
                     self.sortie, bound)).lastrowid)
                for r in self._db.execute(f"SELECT {_REQ} FROM requests WHERE sortie = ? AND user_id = ? AND "
                                          "status = 'pending'", (self.sortie, row.user_id)).fetchall():
                    left = RequestRow(*r)
                    if left.backlog <= 0:
                        self._db.execute(
                            "UPDATE requests SET status = 'served', reason = ?, closed_at_s = ? WHERE request_id = ?",
                            ("" if left.request_id == request_id else
                             f"its tasks were served under request {request_id}", now_s, left.request_id))
        except sqlite3.Error as err:
            raise self._failure("record_service", err) from None
        return service_id

    def _closing(self, reasons: dict[int, str], now_s: float) -> list[tuple[str, tuple[Any, ...]]]:
        """Pending requests closed with their reasons: ``served`` if a service consumed part of
        one (the reason says how much was left), else ``not_served``. (Read before the
        transaction that writes them: the journal has one writer, on one thread.)"""
        out: list[tuple[str, tuple[Any, ...]]] = []
        for rid, reason in reasons.items():
            row = self.request(rid)
            if row is None or row.status != "pending":
                continue
            status, text = ("served", f"{row.backlog} of {row.tasks} tasks left: {reason}") if row.served_tasks \
                else ("not_served", reason)
            out.append(("UPDATE requests SET status = ?, reason = ?, closed_at_s = ? WHERE request_id = ? AND "
                        "status = 'pending'", (status, text, now_s, rid)))
        return out

    def close_pending(self, reasons: dict[int, str], now_s: float) -> None:
        """Pending requests the sortie will not serve, each with its reason."""
        self._write("close_pending", self._closing(reasons, now_s))

    def end_sortie(self, why: str, reasons: dict[int, str], now_s: float) -> None:
        """End the current sortie: its pending requests closed with their reasons, the
        sortie row marked ended, in one transaction."""
        self._write("end_sortie", [*self._closing(reasons, now_s), (
            "UPDATE sorties SET ended_at_s = ?, why = ? WHERE number = ? AND ended_at_s IS NULL",
            (now_s, why, self.sortie))])

    def begin_sortie(self, now_s: float) -> int:
        """Start the next sortie (the current one must be over); its number."""
        if not self.current_sortie().over:
            raise JournalError(f"begin_sortie: sortie {self.sortie} has not ended")
        self._write("begin_sortie", [(
            "INSERT INTO sorties (number, started_at_s) VALUES (?, ?)", (self.sortie + 1, now_s))])
        self.sortie += 1
        return self.sortie

    def record_mission(self, plan_id: int, items: list[dict[str, Any]], points: list[dict[str, Any]],
                       result: str, now_s: float) -> int:
        (mission_id,) = self._write("record_mission", [(
            "INSERT INTO missions (plan_id, time_s, result, items, points, sortie) VALUES (?, ?, ?, ?, ?, ?)",
            (plan_id, now_s, result, json.dumps(items), json.dumps(points), self.sortie))])
        return mission_id

    def set_meta(self, key: str, value: str) -> None:
        self._write("set_meta", [("INSERT OR REPLACE INTO meta (key, value) VALUES (?, ?)", (key, value))])

    # --- reading (``sortie``: None is the current one) ---------------------------------------
    def _rows(self, sql: str, args: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        if self._closed:
            raise JournalError(f"the journal {self.path} is closed")
        try:
            return self._db.execute(sql, args).fetchall()
        except sqlite3.Error as err:
            raise self._failure("read", err) from None

    def current_sortie(self) -> SortieRow:
        row = self.sortie_row(self.sortie)
        if row is None:  # the constructor made or found it; only a foreign writer could remove it
            raise JournalError(f"read: sortie {self.sortie} is missing from {self.path}")
        return row

    def sortie_row(self, number: int) -> SortieRow | None:
        rows = self._rows("SELECT number, started_at_s, ended_at_s, why FROM sorties WHERE number = ?", (number,))
        return SortieRow(*rows[0]) if rows else None

    def sorties(self) -> list[SortieRow]:
        return [SortieRow(*r) for r in self._rows(
            "SELECT number, started_at_s, ended_at_s, why FROM sorties ORDER BY number")]

    def request(self, request_id: int) -> RequestRow | None:
        rows = self._rows(f"SELECT {_REQ} FROM requests WHERE request_id = ?", (request_id,))
        return RequestRow(*rows[0]) if rows else None

    def request_in_force(self, user_id: str, at_s: float | None = None) -> RequestRow | None:
        """The user's request in force at ``at_s`` (the journal's clock, as ``accepted_at_s``;
        None: now) in the current sortie: its newest request accepted by then, whatever has
        become of it since (``status`` is today's), with ``served_tasks`` counting the
        services recorded on it by then, so that ``backlog`` is what the user had waiting at
        ``at_s``. None if the user had sent no request in this sortie by then. A request of no
        tasks in force means the user has nothing to offload."""
        until = math.inf if at_s is None else at_s
        rows = self._rows(
            f"SELECT {_req_columns(' AND s.time_s <= ?')} FROM requests "
            "WHERE sortie = ? AND user_id = ? AND accepted_at_s <= ? ORDER BY request_id DESC LIMIT 1",
            (until, until, self.sortie, user_id, until))
        return RequestRow(*rows[0]) if rows else None

    def user_backlogs(self) -> list[UserBacklog]:
        """Every user of the current sortie, in order of first request: its request in force,
        the backlog left on it (``RequestRow.backlog``; 0 once it is closed), its services and
        the tasks they served."""
        rows = self._rows(
            f"SELECT {_req_columns(table='r')}, "
            "(SELECT COUNT(*) FROM services s WHERE s.sortie = ? AND s.user_id = r.user_id), "
            "(SELECT COALESCE(SUM(s.tasks), 0) FROM services s WHERE s.sortie = ? AND s.user_id = r.user_id) "
            "FROM requests r JOIN (SELECT user_id, MIN(request_id) AS first, MAX(request_id) AS last "
            "FROM requests WHERE sortie = ? GROUP BY user_id) u ON r.request_id = u.last ORDER BY u.first",
            (self.sortie, self.sortie, self.sortie))
        out = []
        for r in rows:
            row = RequestRow(*r[:-2])
            out.append(UserBacklog(row.user_id, row.request_id, row.backlog if row.status == "pending" else 0,
                                   int(r[-2]), int(r[-1])))
        return out

    def served_tasks(self, user_id: str) -> int:
        """The tasks of ``user_id`` served in the current sortie."""
        return int(self._rows("SELECT COALESCE(SUM(tasks), 0) FROM services WHERE sortie = ? AND user_id = ?",
                              (self.sortie, user_id))[0][0])

    def service_counts(self) -> dict[str, int]:
        """How many times each user was served in the current sortie (the fairness count)."""
        return {user: int(n) for user, n in self._rows(
            "SELECT user_id, COUNT(*) FROM services WHERE sortie = ? GROUP BY user_id", (self.sortie,))}

    def requests(self, sortie: int | None = None) -> list[RequestRow]:
        return [RequestRow(*r) for r in self._rows(
            f"SELECT {_REQ} FROM requests WHERE sortie = ? ORDER BY request_id", (self._n(sortie),))]

    def pending(self) -> list[RequestRow]:
        """The current sortie's pending requests in arrival order (at most one per user)."""
        return [RequestRow(*r) for r in self._rows(
            f"SELECT {_REQ} FROM requests WHERE sortie = ? AND status = 'pending' ORDER BY request_id",
            (self.sortie,))]

    def pending_count(self) -> int:
        """How many requests of the current sortie are pending."""
        return int(self._rows("SELECT COUNT(*) FROM requests WHERE sortie = ? AND status = 'pending'",
                              (self.sortie,))[0][0])

    def counted_user_ids(self) -> set[str]:
        """The user ids that hold a place in the current sortie (``intake.max_users``): every
        user with a request that did not close as it arrived for having no tasks left."""
        return {r[0] for r in self._rows(
            f"SELECT DISTINCT user_id FROM requests WHERE sortie = ? AND {_COUNTED}", (self.sortie, *_COUNTED_ARGS))}

    def users(self, sortie: int | None = None) -> list[UserRow]:
        """Every user that holds a place in the sortie (``counted_user_ids``: a user that only
        ever said it had nothing to offload is not one, so that such users cannot grow the
        planner), in order of first request; position from its latest; services counted in
        that sortie."""
        n = self._n(sortie)
        rows = self._rows(
            "SELECT r.user_id, r.x_m, r.y_m, r.z_m, "
            "(SELECT COUNT(*) FROM services s WHERE s.sortie = ? AND s.user_id = r.user_id) "
            "FROM requests r JOIN (SELECT user_id, MIN(request_id) AS first, MAX(request_id) AS last "
            f"FROM requests WHERE sortie = ? GROUP BY user_id HAVING MAX({_COUNTED})) u ON r.request_id = u.last "
            "ORDER BY u.first", (n, n, *_COUNTED_ARGS))
        return [UserRow(*r) for r in rows]

    def services(self, sortie: int | None = None) -> list[ServiceRow]:
        return [ServiceRow(*r) for r in self._rows(
            "SELECT service_id, request_id, user_id, tasks, bits, hover_index, x_m, y_m, z_m, reward, "
            "battery_j, time_s, bound_tasks FROM services WHERE sortie = ? ORDER BY service_id", (self._n(sortie),))]

    def missions(self, sortie: int | None = None) -> list[MissionRow]:
        return [_mission(r) for r in self._rows(
            "SELECT mission_id, plan_id, time_s, result, items, points FROM missions WHERE sortie = ? "
            "ORDER BY mission_id", (self._n(sortie),))]

    def last_mission(self, result: str | None = "accepted") -> MissionRow | None:
        """The current sortie's last mission (with ``result``; None: any)."""
        rows = self._rows(
            "SELECT mission_id, plan_id, time_s, result, items, points FROM missions WHERE sortie = ? "
            "AND (? IS NULL OR result = ?) ORDER BY mission_id DESC LIMIT 1", (self.sortie, result, result))
        return _mission(rows[0]) if rows else None

    def last_plan_id(self) -> int:
        """The highest plan id of any sortie (plan ids run on across sorties); 0 if none."""
        (value,) = self._rows("SELECT COALESCE(MAX(plan_id), 0) FROM missions")[0]
        return int(value)

    def get_meta(self, key: str, default: str | None = None) -> str | None:
        rows = self._rows("SELECT value FROM meta WHERE key = ?", (key,))
        return rows[0][0] if rows else default

    def _n(self, sortie: int | None) -> int:
        return self.sortie if sortie is None else sortie

    def close(self) -> None:
        """Checkpoint the WAL into the main file, close and release the lock. A journal
        that failed is only closed (no checkpoint into a full, replaced or deleted file):
        ``failed`` still says why. ``JournalError`` if the checkpoint fails (the rows stay
        in the WAL, which the next open reads). Closing twice does nothing."""
        if self._closed:
            return
        self._closed = True
        try:
            if self.check() is None:
                try:
                    self._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
                except sqlite3.Error as err:
                    raise self._failure("close", err) from None
        finally:
            try:
                self._db.close()
            except sqlite3.Error:
                pass
            self._unlock()

    def _unlock(self) -> None:
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing our only descriptor of the lock releases it
            self._lock_fd = None


def _lock(path: str, shown: str, create: bool = False) -> int | None:
    """A descriptor of the file at ``path`` holding an exclusive ``flock`` on it; None if
    no file is there (or, with ``create``, if the file made was moved away before it was
    locked). ``JournalError`` naming the holder if another process has the lock; ``shown``
    is the journal's path as the user gave it, for the messages.

    ``flock``, not ``fcntl``/``lockf``: SQLite takes POSIX byte-range locks on this same
    file, and a process loses every POSIX lock it holds on a file when it closes any
    descriptor of that file, which SQLite does (closing a connection, checking a path).
    A ``flock`` belongs to this descriptor alone: closing SQLite's connections leaves it
    held, and on Linux the two kinds do not see each other, so SQLite works as before. (Over
    NFS the kernel makes a ``flock`` a POSIX lock; a journal belongs on local storage anyway,
    as SQLite's WAL does not work over a network file system.)"""
    flags = os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY  # NONBLOCK: a FIFO there must not hang us
    if create:
        flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW
    try:
        fd = os.open(path, flags, 0o644)
    except FileNotFoundError:
        if create:
            raise JournalError(f"cannot create the journal {shown}: the folder {os.path.dirname(path)} "
                               "does not exist") from None
        return None
    except OSError as err:
        verb = "create" if create else "open"
        raise JournalError(f"cannot {verb} the journal {shown}: {path}: {err.strerror or err}") from None
    try:
        who = lock_or_holder(fd)
    except OSError as err:
        raise JournalError(f"cannot lock the journal {shown}: {err.strerror or err}") from None
    if who is not None:
        doing = "creating" if create else "using"
        raise JournalError(f"the journal {shown} is in use by another service ({who} is {doing} it): "
                           "one service per journal; stop it or give this one another journal.path")
    if not names(path, fd):
        os.close(fd)  # replaced, removed or (ours to build) moved into place since we opened it
        return None
    return fd


def _primary(err: sqlite3.Error) -> int | None:
    """SQLite's primary result code of ``err`` (its extended code's low byte), if it has one."""
    code = getattr(err, "sqlite_errorcode", None)
    return code & 0xFF if isinstance(code, int) else None


def _words(err: sqlite3.Error, path: str) -> str:
    """An SQLite error of opening or creating the file at ``path``, in words: what it means,
    SQLite's name and text, and, for a full disk or an I/O error, the room left where the
    file is (SQLite says "disk I/O error" when a full disk keeps it from making the WAL's
    shared memory: the figure tells the two apart)."""
    primary = _primary(err)
    name = getattr(err, "sqlite_errorname", None) or type(err).__name__
    words = _STORAGE_WORDS.get(primary)  # type: ignore[arg-type]
    text = f"{words} ({name}: {err})" if words else f"{err} ({name})"
    if primary in (10, 13):  # SQLITE_IOERR, SQLITE_FULL
        try:
            room = os.statvfs(os.path.dirname(os.path.abspath(path)))
            free = room.f_bavail * room.f_frsize
            text += f"; {free} bytes free" if free < 10**6 else f"; {free // 10**6} MB free"
            text += " on its file system"
        except OSError:
            pass
    return text


def _remove(*paths: str) -> None:
    """Unlink each of ``paths`` that exists."""
    for path in paths:
        try:
            os.unlink(path)
        except FileNotFoundError:
            pass


def _remove_quietly(*paths: str) -> None:
    """``_remove``, on the way out of a failure that is the one to report."""
    try:
        _remove(*paths)
    except OSError:
        pass


def _check_file(path: str) -> None:
    """``JournalError`` for a file that cannot be a journal: not a regular file, empty, or
    not SQLite."""
    try:
        info = os.stat(path)
    except OSError as err:
        raise JournalError(f"cannot open the journal {path}: {err.strerror or err}") from None
    if not stat.S_ISREG(info.st_mode):
        raise JournalError(f"{path} is not a journal: not a regular file")
    if info.st_size == 0:
        raise JournalError(f"{path} is not a journal: the file is empty (a journal never is: a new one is made "
                           "only where no file exists); remove it, or give the journal's right path")
    try:
        with open(path, "rb") as handle:
            head = handle.read(len(SQLITE_MAGIC))
    except OSError as err:
        raise JournalError(f"cannot open the journal {path}: {err.strerror or err}") from None
    if head != SQLITE_MAGIC:
        raise JournalError(f"{path} is not a journal: not an SQLite database (it begins {head[:16]!r}); "
                           "refused, not written")


def _identities(path: str) -> dict[str, tuple[int, int]]:
    """(device, inode) of the database file and of its WAL (if there is one)."""
    out: dict[str, tuple[int, int]] = {}
    for name in (path, f"{path}-wal"):
        try:
            info = os.stat(name)
        except FileNotFoundError:
            continue
        out[name] = (info.st_dev, info.st_ino)
    return out


def _moved(path: str, identity: dict[str, tuple[int, int]]) -> str | None:
    """How the files at ``identity``'s paths differ from those opened, or None."""
    for name, (dev, ino) in identity.items():
        what = "" if name == path else " (its write-ahead log, " + os.path.basename(name) + ")"
        try:
            info = os.stat(name)
        except FileNotFoundError:
            return f"was deleted{what}"
        except OSError as err:
            return f"cannot be checked{what}: {err.strerror or err}"
        if (info.st_dev, info.st_ino) != (dev, ino):
            return f"was replaced by another file{what}"
    return None


def _sync_folder(path: str) -> None:
    """fsync the folder holding ``path``, so that a new name in it survives a power cut."""
    fd = os.open(os.path.dirname(os.path.abspath(path)), os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _req_columns(services_until: str = "", table: str = "requests") -> str:
    """The columns of a ``RequestRow`` read from ``table``: ``served_tasks`` counted from the
    services naming it, ``user_served`` from every service of its user in its sortie (only
    for a request that says ``served_seen``: the others do not need it), both restricted by
    ``services_until``, a condition on the services ``s`` (its parameters are bound twice,
    before any of the caller's)."""
    t = table
    return (f"{t}.request_id, {t}.user_id, {t}.x_m, {t}.y_m, {t}.z_m, {t}.tasks, {t}.client_ref, "
            f"{t}.accepted_at_s, {t}.status, {t}.reason, "
            f"(SELECT COALESCE(SUM(s.tasks), 0) FROM services s WHERE s.request_id = {t}.request_id{services_until}), "
            f"{t}.served_seen, CASE WHEN {t}.served_seen IS NULL THEN 0 ELSE (SELECT COALESCE(SUM(s.tasks), 0) "
            f"FROM services s WHERE s.sortie = {t}.sortie AND s.user_id = {t}.user_id{services_until}) END")


_REQ = _req_columns()
"""The columns of a ``RequestRow``, as the journal stands."""
NO_TASKS = "no tasks to offload"
"""The reason of a request of no tasks (closed as it arrives)."""
_COUNTED = "NOT (status = 'not_served' AND substr(reason, 1, ?) = ?)"
"""A request that gives its user a place in the sortie: any but one closed as it arrived
for having no tasks left (``accept``; its reason starts with ``NO_TASKS``). The intake gives
a place to a user's first request that can be served; under the model's rule (3), (9c),
and without one, that is exactly a request with tasks left, as the rule leaves out only
users already served, who hold a place. So a restart counts what the intake counted."""
_COUNTED_ARGS = (len(NO_TASKS), NO_TASKS)


def _mission(r: tuple[Any, ...]) -> MissionRow:
    return MissionRow(r[0], r[1], r[2], r[3], json.loads(r[4]), json.loads(r[5]))
