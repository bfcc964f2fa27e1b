"""The journal's file: one service per journal (a lock), only a journal is a journal (an empty,
foreign or table-less file is refused and left as it was), and writes that fail loud (a full
database or disk, an I/O error, the file deleted or replaced while open): each raises
``JournalError`` saying what happened, never SQLite's "cannot rollback - no transaction is
active", marks the journal ``failed`` and leaves it consistent, with every acked row kept.

The full disk is real where it can be: a write past RLIMIT_FSIZE in a child process (the
kernel refuses it with EFBIG, as a file system would with ENOSPC), and, where this user may
mount one, a 1 MiB tmpfs in a private mount namespace (``unshare -m``) filled up. SQLite's
``max_page_count`` gives the same SQLITE_FULL in process.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import textwrap
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from planner_service.service.errors import JournalError
from planner_service.service.journal import APPLICATION_ID, Journal
from planner_service.harness.processes import REPO, free_port
from tests.support.stack import Stack

ROLLBACK_NOISE = "no transaction is active"
CHILD_ENV = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
"""A child interpreter imports this checkout's packages, installed or not."""


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def fill(j: Journal, count: int, start: int = 0) -> None:
    for i in range(start, start + count):
        j.accept(f"u{i}", 10.0, 20.0, 0.0, 5, f"ref-{i}", 100.0 + i)


def rows(path: Path, sql: str) -> list[tuple[object, ...]]:
    db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        return db.execute(sql).fetchall()
    finally:
        db.close()


# --- one service per journal ---------------------------------------------------------------------
def test_a_second_journal_on_the_same_file_is_refused_naming_the_holder(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    first = Journal(path)
    try:
        with pytest.raises(JournalError, match=rf"in use by another service \(pid {os.getpid()} is using it\): "
                                               "one service per journal"):
            Journal(path)
        link = tmp_path / "link.sqlite"
        link.symlink_to(path)  # another path to the same file shares the lock
        with pytest.raises(JournalError, match="in use by another service"):
            Journal(link)
        hard = tmp_path / "hard.sqlite"
        os.link(path, hard)  # so does another name of it: the lock is the file's own
        with pytest.raises(JournalError, match="in use by another service"):
            Journal(hard)
        hard.unlink()
        fill(first, 3)
        sqlite3.connect(path).close()  # would drop a POSIX lock of this process on the file: not a flock
        with pytest.raises(JournalError, match="in use by another service"):
            Journal(path)
    finally:
        first.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["j.sqlite", "link.sqlite"]  # no lock file
    again = Journal(path)  # released by close
    assert [r.user_id for r in again.pending()] == ["u0", "u1", "u2"]
    again.close()


def test_the_lock_names_another_process_and_dies_with_it(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import sqlite3, time
            from planner_service.service.journal import Journal
            j = Journal({str(path)!r})
            sqlite3.connect({str(path)!r}).close()  # closing a descriptor of the file keeps the lock
            print("ready", flush=True)
            time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True, env=CHILD_ENV)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "ready"
        with pytest.raises(JournalError) as refused:
            Journal(path)
        message = str(refused.value)
        assert f"the journal {path} is in use by another service (pid {holder.pid} is using it)" in message, message
        assert "one service per journal" in message
        assert rows(path, "SELECT COUNT(*) FROM sorties") == [(1,)]  # a reader still reads beside it
        holder.kill()  # SIGKILL: no clean close, the kernel drops the lock
        holder.wait(10)
        j = Journal(path)  # no stale lock
        assert j.sortie == 1
        j.close()
    finally:
        if holder.poll() is None:
            holder.kill()
            holder.wait(10)


def test_services_creating_one_journal_at_once_get_one_journal_and_one_lock(tmp_path: Path) -> None:
    for attempt in range(5):
        path = tmp_path / f"j{attempt}.sqlite"
        start, tried = threading.Barrier(4), threading.Barrier(4)

        def open_one() -> str:
            start.wait()
            try:
                j = Journal(path)
            except JournalError as err:
                tried.wait()
                return str(err)
            tried.wait()  # the others tried while this one held the journal
            fill(j, 1)
            j.close()
            return "opened"

        with ThreadPoolExecutor(4) as pool:
            outcomes = list(pool.map(lambda _: open_one(), range(4)))
        refused = [o for o in outcomes if o != "opened"]
        assert outcomes.count("opened") == 1 and all("in use by another service" in r for r in refused), outcomes
        assert rows(path, "SELECT user_id FROM requests") == [("u0",)]
    left = sorted(p.name for p in tmp_path.iterdir() if not p.name.endswith(("-wal", "-shm")))  # the reader's
    assert left == [f"j{n}.sqlite" for n in range(5)]  # no lock file, nothing half-built


def test_no_file_deleted_beside_the_journal_lets_a_second_service_on(stack: Stack) -> None:
    """Service A runs; every file beside its journal (the WAL and shared memory included:
    whatever one might take for a lock) is deleted; service B, started on the same journal,
    is refused at start with one line naming A, and A is the one still running."""
    (stack.tmp / "data").mkdir()
    stack.journal_path = stack.tmp / "data" / "journal.sqlite"
    a = stack.service()
    beside = [p for p in stack.journal_path.parent.iterdir() if p != stack.journal_path]
    for p in beside:
        p.unlink()
    log = stack.tmp / "second.log"
    with open(log, "w") as err:
        b = subprocess.Popen([sys.executable, "-m", "planner_service", "serve", "--journal", str(stack.journal_path),
                              "--mavlink", f"udpout:127.0.0.1:{free_port(socket.SOCK_DGRAM)}",
                              "--listen", f"tcp/127.0.0.1:{free_port()}"],
                             cwd=REPO, env=CHILD_ENV, stdout=subprocess.DEVNULL, stderr=err, start_new_session=True)
    try:
        deadline = time.monotonic() + 60.0
        while b.poll() is None and "ready:" not in log.read_text() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert b.poll() is not None, f"a second service ran on the journal A holds:\n{log.read_text()[-2000:]}"
    finally:
        if b.poll() is None:
            os.killpg(b.pid, signal.SIGKILL)
            b.wait(10)
    lines = log.read_text().strip().splitlines()
    assert b.returncode == 1 and len(lines) == 1, lines
    assert lines[0] == (f"error: the journal {stack.journal_path} is in use by another service (pid {a.proc.pid} "
                        "is using it): one service per journal; stop it or give this one another journal.path"), lines
    assert a.proc.poll() is None, a.log()[-2000:]
    print(f"\ndeleted {sorted(p.name for p in beside)}; the second service: {lines[0]}")


# --- only a journal is a journal ----------------------------------------------------------------
def test_a_new_path_is_created_whole_with_the_application_id(tmp_path: Path) -> None:
    path = tmp_path / "deep" / "j.sqlite"
    (tmp_path / "deep").mkdir()
    (tmp_path / "deep" / "j.sqlite.new").write_bytes(b"half-made by a creation that crashed")
    j = Journal(path, now_s=5.0)
    fill(j, 2)
    j.close()
    assert sorted(p.name for p in path.parent.iterdir()) == ["j.sqlite"]
    assert rows(path, "PRAGMA application_id") == [(APPLICATION_ID,)]
    assert rows(path, "SELECT number, started_at_s FROM sorties") == [(1, 5.0)]


@pytest.mark.parametrize("what", ["empty", "text", "foreign-sqlite", "sqlite-no-tables", "sqlite-other-tables",
                                  "folder"])
def test_a_file_that_is_not_a_journal_is_refused_and_left_alone(tmp_path: Path, what: str) -> None:
    path = tmp_path / "j.sqlite"
    expected = {
        "empty": "is not a journal: the file is empty",
        "text": "is not a journal: not an SQLite database",
        "foreign-sqlite": "another application's SQLite database (application_id 0x1234",
        "sqlite-no-tables": "without the journal's application id or tables (its tables: none)",
        "sqlite-other-tables": "without the journal's application id or tables (its tables: photos, requests)",
        "folder": "is not a journal: not a regular file",
    }[what]
    if what == "empty":
        path.touch()
    elif what == "text":
        path.write_text("requests,services\n1,2\n")
    elif what == "folder":
        path.mkdir()
    else:
        db = sqlite3.connect(path)
        if what == "foreign-sqlite":
            db.executescript("PRAGMA application_id = 4660; CREATE TABLE requests (a); CREATE TABLE services (a); "
                             "CREATE TABLE missions (a); CREATE TABLE meta (key, value);")
        elif what == "sqlite-no-tables":
            db.execute("PRAGMA user_version = 0")
            db.execute("VACUUM")  # writes the header: a valid, empty database
        else:
            db.executescript("CREATE TABLE photos (a); CREATE TABLE requests (a);")
        db.commit()
        db.close()
    before = None if what == "folder" else digest(path)
    with pytest.raises(JournalError) as refused:
        Journal(path)
    assert expected in str(refused.value), str(refused.value)
    assert str(path) in str(refused.value)
    if before is not None:
        assert digest(path) == before  # never written, never taken as fresh
    assert not (tmp_path / "j.sqlite-wal").exists()


def test_a_journal_from_before_the_application_id_is_stamped(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path)
    fill(j, 3)
    j.close()
    db = sqlite3.connect(path)
    db.execute("PRAGMA application_id = 0")  # as every journal written before it was
    db.commit()
    db.close()
    again = Journal(path)
    assert [r.request_id for r in again.pending()] == [1, 2, 3]
    again.close()
    assert rows(path, "PRAGMA application_id") == [(APPLICATION_ID,)]


# --- writes that fail ---------------------------------------------------------------------------
def test_a_full_database_fails_loud_and_stays_consistent(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path)
    fill(j, 3)
    (pages,) = j._db.execute("PRAGMA page_count").fetchone()
    j._db.execute(f"PRAGMA max_page_count = {pages}")  # SQLITE_FULL, as a full disk gives it
    acked = 3
    with pytest.raises(JournalError) as full:
        for i in range(3, 500):
            j.accept(f"u{i}", 10.0, 20.0, 0.0, 5, None, 200.0 + i)
            acked += 1
    message = str(full.value)
    assert ROLLBACK_NOISE not in message
    assert message.startswith("accept: the journal ") and "the disk (or the database's size limit) is full" in message
    assert "SQLITE_FULL" in message and "was rolled back" in message
    assert j.failed is not None and "is full" in j.failed
    with pytest.raises(JournalError, match="the journal failed and takes no more writes: the journal .* is full"):
        j.record_mission(1, [], [], "accepted", 300.0)
    assert len(j.pending()) == acked  # reads still answer
    j.close()
    again = Journal(path)
    assert [r.request_id for r in again.pending()] == list(range(1, acked + 1))
    assert again._db.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    again.close()


CHILD = """
import json, os, resource, signal, sys, time
from planner_service.service.journal import Journal
from planner_service.service.errors import JournalError
path, how = sys.argv[1], sys.argv[2]
out = {{}}
j = Journal(path)
for i in range(5):
    j.accept(f"u{{i}}", 10.0, 20.0, 0.0, 5, None, 100.0 + i)
if how == "fsize":
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # the write fails with EFBIG instead of killing us
    resource.setrlimit(resource.RLIMIT_FSIZE, (1, resource.RLIM_INFINITY))
else:  # fill the file system
    with open(os.path.join(os.path.dirname(path), "filler"), "wb", buffering=0) as f:
        try:
            while True:
                f.write(b"x" * 4096)
        except OSError:  # ENOSPC: the file system is full
            pass
errors = []
for i in range(5, 8):
    try:
        j.accept(f"u{{i}}", 10.0, 20.0, 0.0, 5, None, 100.0 + i)
        errors.append(None)
    except JournalError as err:
        errors.append(str(err))
out["errors"], out["failed"], out["pending"] = errors, j.failed, len(j.pending())
j.close()
if how == "fsize":
    resource.setrlimit(resource.RLIMIT_FSIZE, (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
else:
    os.unlink(os.path.join(os.path.dirname(path), "filler"))
again = Journal(path)  # space again: the journal opens with every acked request
out["after"] = [r.request_id for r in again.pending()]
out["integrity"] = again._db.execute("PRAGMA integrity_check").fetchone()[0]
out["next"] = again.accept("later", 1.0, 1.0, 0.0, 1, None, 200.0)[0]
again.close()
print(json.dumps(out))
"""


def run_child(tmp_path: Path, how: str, prefix: list[str], path: Path) -> dict[str, object]:
    script = tmp_path / "child.py"
    script.write_text(CHILD.format())
    done = subprocess.run([*prefix, sys.executable, str(script), str(path), how], capture_output=True, text=True,
                          timeout=60, env=CHILD_ENV)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def check_child(out: dict[str, object], words: str) -> None:
    errors = out["errors"]
    assert isinstance(errors, list) and None not in errors, out
    first, *later = errors
    assert ROLLBACK_NOISE not in first and words in first and "was rolled back" in first, first
    assert all(e.startswith("the journal failed and takes no more writes") for e in later), later
    assert out["failed"] and words in str(out["failed"]), out
    assert out["pending"] == 5 and out["after"] == [1, 2, 3, 4, 5], out
    assert out["integrity"] == "ok" and out["next"] == 6, out


def test_a_write_the_kernel_refuses_fails_loud(tmp_path: Path) -> None:
    out = run_child(tmp_path, "fsize", [], tmp_path / "j.sqlite")
    print(f"\nRLIMIT_FSIZE: {out['errors'][0]}")
    check_child(out, "an I/O error (SQLITE_IOERR")


def test_a_full_file_system_fails_loud(tmp_path: Path) -> None:
    mount = tmp_path / "tiny"
    mount.mkdir()
    unshare = shutil.which("unshare")
    probe = subprocess.run([unshare or "unshare", "-m", "sh", "-c", f"mount -t tmpfs -o size=1m tmpfs {mount}"],
                           capture_output=True, text=True) if unshare else None
    if probe is None or probe.returncode != 0:
        pytest.skip("cannot mount a tmpfs in a private mount namespace here (needs unshare and CAP_SYS_ADMIN)")
    out = run_child(tmp_path, "fill", ["unshare", "-m", "sh", "-c",
                                       f"mount -t tmpfs -o size=1m tmpfs {mount} && exec \"$@\"", "sh"],
                    mount / "j.sqlite")
    print(f"\n1 MiB tmpfs: {out['errors'][0]}")
    check_child(out, "the disk (or the database's size limit) is full (SQLITE_FULL")


# --- the file deleted or replaced under the service ---------------------------------------------------
@pytest.mark.parametrize("how", ["deleted", "replaced", "wal-deleted"])
def test_a_journal_deleted_or_replaced_while_open_fails_and_is_rescued(tmp_path: Path, how: str) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path)
    fill(j, 3)
    assert j.check() is None and j.failed is None
    other = tmp_path / "other.bin"
    other.write_bytes(b"the operator's backup, or anything")
    if how == "deleted":
        path.unlink()
    elif how == "replaced":
        os.replace(other, path)
    else:
        Path(f"{path}-wal").unlink()
    with pytest.raises(JournalError) as refused:
        fill(j, 1, start=3)  # the write itself notices, before writing anything
    words = {"deleted": "was deleted while the service ran", "replaced": "was replaced by another file while",
             "wal-deleted": "was deleted (its write-ahead log, j.sqlite-wal) while"}[how]
    assert words in str(refused.value) and j.failed is not None and words in j.failed
    assert j.check() == j.failed  # stays failed, the rescue made once
    assert j.rescued is not None and f"its rows were copied to {j.rescued}" in j.failed
    assert [r[0] for r in rows(Path(j.rescued), "SELECT user_id FROM requests ORDER BY request_id")] == ["u0", "u1",
                                                                                                        "u2"]
    assert len(j.pending()) == 3  # reads answer from the open file
    j.close()
    if how == "replaced":
        assert path.read_bytes() == b"the operator's backup, or anything"  # untouched
    if how == "deleted":
        assert not path.exists()  # not brought back behind the operator's back
    rescued = Journal(j.rescued)  # the copy is a journal
    assert [r.request_id for r in rescued.pending()] == [1, 2, 3]
    rescued.close()


def test_close_after_a_failure_does_not_claim_a_flush(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path)
    fill(j, 1)
    path.unlink()
    j.close()  # no exception: the failure is known, nothing is checkpointed into the lost file
    assert j.failed is not None and "was deleted" in j.failed
    j.close()  # twice is harmless
    with pytest.raises(JournalError, match="is closed"):
        fill(j, 1, start=5)
