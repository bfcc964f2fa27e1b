"""The journal: requests, replacement, services, missions, sorties, resuming from the file, and
migrating a file of the one-sortie layout."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from planner_service.service.errors import JournalError
from planner_service.model import preset
from planner_service.harness.report import sortie_summary
from planner_service.service.journal import Journal
from planner_service.service.rows import SortieRow


def test_newer_request_replaces_older(tmp_path: Path) -> None:
    j = Journal(tmp_path / "j.sqlite")
    a, replaced = j.accept("u1", 10.0, 20.0, 0.0, 5, "r1", 100.0)
    b, _ = j.accept("u2", 30.0, 40.0, 0.0, 7, None, 101.0)
    c, replaced_c = j.accept("u1", 11.0, 21.0, 0.0, 9, "r2", 102.0)
    assert (a, b, c) == (1, 2, 3) and replaced == [] and replaced_c == [1]
    assert [(r.request_id, r.user_id, r.tasks) for r in j.pending()] == [(2, "u2", 7), (3, "u1", 9)]
    old = j.request(1)
    assert old is not None and old.status == "replaced" and old.reason == "replaced by request 3"
    # users in order of first request, positions from the latest
    assert [(u.user_id, u.x_m, u.services) for u in j.users()] == [("u1", 11.0, 0), ("u2", 30.0, 0)]


def test_service_and_not_served_and_resume(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path)
    j.accept("u1", 10.0, 20.0, 0.0, 5, None, 1.0)
    j.accept("u2", 30.0, 40.0, 0.0, 7, None, 2.0)
    j.record_service(1, 4, (20.0, 20.0, 100.0), 5, 5e5, 0.25, 90_000.0, 3.0)
    with pytest.raises(JournalError, match="not pending"):
        j.record_service(1, 4, (20.0, 20.0, 100.0), 5, 5e5, 0.25, 90_000.0, 3.5)
    j.record_mission(1, [{"seq": 0}], [{"hover_index": 4}], "accepted", 2.5)
    j.close()

    again = Journal(path)  # a restart
    assert [r.request_id for r in again.pending()] == [2]
    assert [(s.request_id, s.user_id, s.tasks, s.hover_index) for s in again.services()] == [(1, "u1", 5, 4)]
    assert [u.services for u in again.users()] == [1, 0]
    mission = again.last_mission()
    assert mission is not None and mission.plan_id == 1 and mission.points == [{"hover_index": 4}]
    nxt, _ = again.accept("u3", 1.0, 1.0, 0.0, 3, None, 4.0)
    assert nxt == 3  # ids continue after a restart
    again.close_pending({2: "fairness: test"}, 5.0)
    closed = again.request(2)
    assert closed is not None and closed.status == "not_served" and closed.reason == "fairness: test"


def test_sorties_keep_their_rows_apart(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path, now_s=10.0)
    assert j.sortie == 1 and j.current_sortie() == SortieRow(1, 10.0, None, "")
    j.accept("u1", 10.0, 20.0, 0.0, 5, None, 11.0)
    j.accept("u2", 30.0, 40.0, 0.0, 7, None, 12.0)
    j.record_service(1, 4, (20.0, 20.0, 100.0), 5, 5e5, 0.25, 90_000.0, 13.0)
    j.record_mission(1, [{"seq": 0}], [{"hover_index": 4}], "accepted", 12.5)
    with pytest.raises(JournalError, match="has not ended"):
        j.begin_sortie(14.0)
    j.end_sortie("the vehicle landed", {2: "sortie ended before its turn"}, 20.0)
    assert j.current_sortie() == SortieRow(1, 10.0, 20.0, "the vehicle landed")
    with pytest.raises(JournalError, match="sortie 1 is over"):
        j.accept("u3", 1.0, 1.0, 0.0, 3, None, 21.0)

    assert j.begin_sortie(30.0) == 2
    # a new sortie: nothing pending, nobody served, no mission held; ids run on
    assert (j.pending(), j.services(), j.users(), j.missions(), j.last_mission()) == ([], [], [], [], None)
    assert j.last_plan_id() == 1
    rid, _ = j.accept("u1", 50.0, 60.0, 0.0, 9, None, 31.0)
    assert rid == 3
    assert [(u.user_id, u.x_m, u.services) for u in j.users()] == [("u1", 50.0, 0)]  # fairness counts restart
    j.record_service(3, 2, (50.0, 60.0, 100.0), 9, 9e5, 0.3, 80_000.0, 32.0)
    assert [(u.user_id, u.services) for u in j.users()] == [("u1", 1)]
    # the earlier sortie is still there to read
    assert [r.status for r in j.requests(1)] == ["served", "not_served"]
    assert [(u.user_id, u.services) for u in j.users(1)] == [("u1", 1), ("u2", 0)]
    assert [s.request_id for s in j.services(1)] == [1] and [s.request_id for s in j.services()] == [3]
    j.close()

    again = Journal(path)  # a restart resumes the running sortie 2
    assert again.sortie == 2 and not again.current_sortie().over
    assert [s.request_id for s in again.services()] == [3]
    assert [r.number for r in again.sorties()] == [1, 2]
    again.end_sortie("the vehicle landed", {}, 40.0)
    again.close()
    assert Journal(path).current_sortie().over  # and a restart between sorties knows it


# The layout before sorties (schema version 1), as the previous service wrote it.
V1_SCHEMA = """
CREATE TABLE requests (request_id INTEGER PRIMARY KEY AUTOINCREMENT, user_id TEXT NOT NULL,
    x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL, tasks INTEGER NOT NULL, client_ref TEXT,
    accepted_at_s REAL NOT NULL, status TEXT NOT NULL DEFAULT 'pending'
        CHECK (status IN ('pending', 'served', 'replaced', 'not_served')),
    reason TEXT NOT NULL DEFAULT '', closed_at_s REAL);
CREATE INDEX requests_by_user ON requests (user_id, status);
CREATE TABLE services (service_id INTEGER PRIMARY KEY AUTOINCREMENT,
    request_id INTEGER NOT NULL REFERENCES requests (request_id), user_id TEXT NOT NULL, tasks INTEGER NOT NULL,
    bits REAL NOT NULL, hover_index INTEGER NOT NULL, x_m REAL NOT NULL, y_m REAL NOT NULL, z_m REAL NOT NULL,
    reward REAL NOT NULL, battery_j REAL NOT NULL, time_s REAL NOT NULL);
CREATE TABLE missions (mission_id INTEGER PRIMARY KEY AUTOINCREMENT, plan_id INTEGER NOT NULL,
    time_s REAL NOT NULL, result TEXT NOT NULL, items TEXT NOT NULL, points TEXT NOT NULL);
CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
INSERT INTO requests (user_id, x_m, y_m, z_m, tasks, accepted_at_s, status, closed_at_s)
    VALUES ('u1', 1, 2, 0, 5, 100.0, 'served', 110.0), ('u2', 3, 4, 0, 6, 101.0, 'pending', NULL);
INSERT INTO services (request_id, user_id, tasks, bits, hover_index, x_m, y_m, z_m, reward, battery_j, time_s)
    VALUES (1, 'u1', 5, 5e5, 3, 1, 2, 100, 0.2, 90000, 110.0);
INSERT INTO missions (plan_id, time_s, result, items, points) VALUES (7, 105.0, 'accepted', '[]', '[]');
"""


@pytest.mark.parametrize("landed", [False, True])
def test_a_version_1_journal_is_migrated(tmp_path: Path, landed: bool) -> None:
    path = tmp_path / "v1.sqlite"
    db = sqlite3.connect(path)
    db.executescript(V1_SCHEMA + ("INSERT INTO meta VALUES ('sortie_over', 'the vehicle landed');" if landed else ""))
    db.close()
    j = Journal(path, now_s=500.0)
    assert j.get_meta("schema_version") == "4" and j.get_meta("sortie_over") is None
    assert j.sortie == 1
    if landed:  # ended when its last request was closed, for the reason it gave
        assert j.current_sortie() == SortieRow(1, 100.0, 110.0, "the vehicle landed")
    else:
        assert j.current_sortie() == SortieRow(1, 100.0, None, "")
    assert [(r.request_id, r.served_seen, r.backlog) for r in j.pending()] == [(2, None, 6)]
    assert [(u.user_id, u.services) for u in j.users()] == [("u1", 1), ("u2", 0)]
    last = j.last_mission()
    assert last is not None and last.plan_id == 7 and j.last_plan_id() == 7
    j.close()
    assert Journal(path).get_meta("schema_version") == "4"  # opening again changes nothing


# Version 2 (sorties, before ``requests.served_seen``), as the previous service wrote it.
V2_SCHEMA = V1_SCHEMA + """
ALTER TABLE requests ADD COLUMN sortie INTEGER NOT NULL DEFAULT 1;
ALTER TABLE services ADD COLUMN sortie INTEGER NOT NULL DEFAULT 1;
ALTER TABLE missions ADD COLUMN sortie INTEGER NOT NULL DEFAULT 1;
CREATE TABLE sorties (number INTEGER PRIMARY KEY, started_at_s REAL NOT NULL, ended_at_s REAL,
    why TEXT NOT NULL DEFAULT '');
INSERT INTO sorties (number, started_at_s) VALUES (1, 100.0);
INSERT INTO meta VALUES ('schema_version', '2');
PRAGMA application_id = 1969321578;
"""


def test_a_version_2_journal_is_migrated_its_requests_taken_as_they_are(tmp_path: Path) -> None:
    path = tmp_path / "v2.sqlite"
    db = sqlite3.connect(path)
    db.executescript(V2_SCHEMA)
    db.close()
    j = Journal(path, now_s=500.0)
    assert j.get_meta("schema_version") == "4" and j.sortie == 1
    assert [(r.request_id, r.status, r.served_seen, r.backlog) for r in j.requests()] == [
        (1, "served", None, 0), (2, "pending", None, 6)]
    # an old request said nothing of what its user knew: it is taken as it is, whatever was served
    j.record_service(2, 4, (1.0, 2.0, 100.0), 2, 2e5, 0.1, 9e4, 120.0)
    # an old service did not say the backlog it was bound to: the tasks it carried
    assert [(s.tasks, s.bound_tasks, s.bound) for s in j.services()] == [(5, None, 5), (2, 2, 2)]
    assert [(b.user_id, b.backlog) for b in j.user_backlogs()] == [("u1", 0), ("u2", 4)]
    rid, _ = j.accept("u2", 3.0, 4.0, 0.0, 6, None, 130.0, served_seen=0)  # a new one does say
    assert j.request(rid) is not None and j.request(rid).backlog == 4  # type: ignore[union-attr]
    j.close()


def test_the_fairness_audit_judges_the_backlog_each_hold_was_bound_to(tmp_path: Path) -> None:
    # A CI run: user-0's second service was bound to 16 tasks (more than beta = 15, so
    # allowed by (3)); the battery's reserve cut the hold to 1 task. Judged on the tasks
    # carried, the audit called that a violation; (3) is on the user's tasks, u_i(t).
    scenario = preset("field")
    beta = scenario.fairness_threshold_tasks
    j = Journal(tmp_path / "j.sqlite", now_s=1.0)
    first, _ = j.accept("user-0", 100.0, 100.0, 0.0, 11, None, 2.0)
    j.record_service(first, 2, (50.0, 250.0, 100.0), 2, 2e5, 0.1, 6e4, 3.0, bound_tasks=11)
    second, _ = j.accept("user-0", 100.0, 100.0, 0.0, beta + 1, None, 4.0, served_seen=2)
    j.record_service(second, 7, (200.0, 200.0, 100.0), 1, 1e5, 0.1, 3e4, 5.0, bound_tasks=beta + 1)
    assert [(s.tasks, s.bound) for s in j.services()] == [(2, 11), (1, beta + 1)]
    assert sortie_summary(j, scenario, None)["fairness_violations"] == 0
    third, _ = j.accept("user-1", 100.0, 100.0, 0.0, beta, None, 6.0)  # a real violation still counts:
    j.record_service(third, 7, (200.0, 200.0, 100.0), 1, 1e5, 0.1, 3e4, 7.0, bound_tasks=beta)
    fourth, _ = j.accept("user-1", 100.0, 100.0, 0.0, beta, None, 8.0, served_seen=1)  # a repeat of beta
    j.record_service(fourth, 7, (200.0, 200.0, 100.0), 1, 1e5, 0.1, 3e4, 9.0, bound_tasks=beta)
    assert sortie_summary(j, scenario, None)["fairness_violations"] == 1
    with pytest.raises(JournalError, match="1 tasks served of a hold bound to 0"):
        j.record_service(fourth, 7, (200.0, 200.0, 100.0), 1, 1e5, 0.1, 3e4, 9.0, bound_tasks=0)
    j.close()


def test_a_newer_or_foreign_journal_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "j.sqlite"
    j = Journal(path)
    j.set_meta("schema_version", "5")
    j.close()
    with pytest.raises(JournalError, match="schema version 5; this service reads versions up to 4"):
        Journal(path)
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"not a database at all" * 100)
    with pytest.raises(JournalError, match="is not a journal: not an SQLite database"):
        Journal(junk)
