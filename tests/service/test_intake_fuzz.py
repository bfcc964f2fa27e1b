"""What the service receives over zenoh, hostile: at least 10 000 generated payloads on each
queryable.

Task requests into ``Intake.handle`` with a real journal: each gets an ack exactly when an
independent oracle (tests/support/hostile_payloads.py) says it is a valid request, otherwise
an ``ErrorReply`` naming a field that a client can decode; nothing raises, and a refused
payload leaves the journal unchanged (SQLite's ``data_version``, read on a second
connection, moves on any commit; the tables are compared with the oracle's at the end).

State queries into the service's state handler: whatever the query carries, the same
State (the payload is ignored) and no journal change.
"""

from __future__ import annotations

from dataclasses import replace

import json
import sqlite3
import time
from pathlib import Path
from typing import Any

import zenoh
from hypothesis import HealthCheck, given, settings

from planner_service.service.app import Service, build_parts
from planner_service.service.config import IntakeConfig, build_config
from planner_service.service.intake import Accepted, Intake, Rejected
from planner_service.service.journal import Journal
from protocol import Area, ErrorReply, State, TaskAck, decode, decode_reply, encode
from tests.support.hostile_payloads import REQUEST_FIELDS, Case, batches, field_root, valid_request

NOW = 1_732_312_000.5
AREA = Area(500.0, 120.0, 10.0)
PAYLOADS = 10_000
BATCH = 10
FUZZ = settings(max_examples=PAYLOADS // BATCH, deadline=None, database=None, derandomize=True,
                suppress_health_check=list(HealthCheck))
"""derandomize: the same payloads on every run (a CI failure reproduces); no example database."""


def _printable(text: str) -> str:
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def top_level_keys(payload: bytes) -> set[str]:
    """The keys of the payload's top-level object, as an error reply would write them."""
    try:
        data = json.loads(payload)
    except (ValueError, RecursionError):
        return set()
    return {_printable(k) for k in data} if isinstance(data, dict) else set()


def check_refusal(case: Case, reply: Any) -> None:
    """A refusal is an ErrorReply a client decodes as is, naming a field of the payload."""
    assert isinstance(reply, ErrorReply), (case, reply)
    wire = encode(reply)
    assert len(wire) <= 4096 and decode_reply(wire) == reply, (case, reply)
    assert reply.field and reply.message, (case, reply)
    allowed = {"payload"} | REQUEST_FIELDS | top_level_keys(case.payload)
    # A field's own name may hold "." or "[": then it is named whole.
    assert reply.field in allowed or field_root(reply.field) in allowed, (case, reply)
    if case.field is not None and len(case.payload) <= 4096:
        assert _printable(case.field) in (reply.field, field_root(reply.field)), (case, reply)


def test_hostile_requests_are_refused_naming_a_field_and_change_nothing(tmp_path: Path) -> None:
    journal = Journal(tmp_path / "journal.sqlite")
    # Bounds off: with the clock pinned, the rate limit would refuse valid requests, and the
    # oracle judges payloads, not load (tests/service/test_intake.py covers the bounds).
    unbounded = IntakeConfig(max_pending_requests=10 ** 9, max_users=10 ** 9, max_requests_per_s=1e12)
    intake = Intake(journal, AREA, clock=lambda: NOW, limits=unbounded)
    watcher = sqlite3.connect(tmp_path / "journal.sqlite")
    expected: list[dict[str, Any]] = []
    seen = {"payloads": 0, "accepted": 0, "served_seen": 0}

    def version() -> int:
        return int(watcher.execute("PRAGMA data_version").fetchone()[0])

    @FUZZ
    @given(batches("task_request", BATCH))
    def check(cases: list[Case]) -> None:
        for case in cases:
            seen["payloads"] += 1
            before = version()
            outcome = intake.handle(case.payload)
            changed = version() != before
            valid = valid_request(case.payload, AREA.side_m, AREA.max_altitude_m)
            if valid is None:
                assert isinstance(outcome, Rejected), (case, outcome)
                assert not changed, (case, "a refused request changed the journal")
                check_refusal(case, outcome.reply)
            else:
                assert isinstance(outcome, Accepted), (case, valid, outcome)
                assert changed
                ack = outcome.reply
                assert isinstance(ack, TaskAck) and decode_reply(encode(ack)) == ack
                assert (ack.user_id, ack.client_ref, ack.accepted_at_s) == (valid["user_id"], valid["client_ref"], NOW)
                # what the journal keeps of served_seen: as said if it counts in this sortie
                # (1, or not said), 0 if in another (none of this sortie's services known)
                said, sortie = valid["served_seen"], valid["sortie"]
                expected.append({**valid, "seen": None if said is None else said if sortie in (None, 1) else 0})
                seen["accepted"] += 1
                seen["served_seen"] += said is not None

    t0 = time.perf_counter()
    check()
    elapsed = time.perf_counter() - t0
    print(f"\nintake: {seen['payloads']} payloads ({seen['accepted']} valid, {seen['served_seen']} of them with "
          f"served_seen) in {elapsed:.1f} s")
    assert seen["payloads"] >= PAYLOADS
    assert seen["accepted"] >= 100, "the strategies should also produce valid requests"
    assert seen["served_seen"] >= 20, "and valid requests that say served_seen"
    # The journal holds exactly the oracle's valid requests, each user's newest pending
    # (closed at once if it has no tasks: nothing is waiting), the older ones replaced.
    rows = journal.requests()
    assert [(r.user_id, r.x_m, r.y_m, r.z_m, r.tasks, r.client_ref, r.served_seen) for r in rows] == \
        [(e["user_id"], e["x_m"], e["y_m"], e["z_m"], e["tasks"], e["client_ref"], e["seen"]) for e in expected]
    newest = {r.user_id: r.request_id for r in rows}
    assert all(r.status == ("not_served" if r.tasks == 0 else "pending" if newest[r.user_id] == r.request_id
                            else "replaced") for r in rows)
    assert journal.services() == [] and journal.missions() == []
    watcher.close()
    journal.close()


class RecordingQuery:
    """What the state queryable's handler is given by zenoh: the query's payload (a real
    ``zenoh.ZBytes``) and ``reply``/``drop``; the reply is kept for the test."""

    def __init__(self, payload: bytes | None) -> None:
        self.payload = zenoh.ZBytes(payload) if payload is not None else None
        self.replies: list[tuple[str, bytes]] = []
        self.dropped = False

    def reply(self, key: str, payload: bytes, attachment: bytes | None = None) -> None:
        self.replies.append((key, bytes(payload)))

    def drop(self) -> None:
        self.dropped = True


def test_a_state_query_answers_the_same_state_whatever_it_carries(tmp_path: Path) -> None:
    config = build_config({}, {"journal.path": str(tmp_path / "journal.sqlite")})
    service = Service(config, replace(build_parts(config), wall=lambda: NOW))
    try:
        accepted = service.intake.handle(b'{"kind": "task_request", "user_id": "u-1", "x_m": 10, "y_m": 20, "tasks": 3}')
        assert isinstance(accepted, Accepted)
        baseline = RecordingQuery(None)
        service._on_state(baseline)
        (key, expected), = baseline.replies
        assert key == service.keys.state and decode(expected, State).status.pending_requests == 1
        watcher = sqlite3.connect(tmp_path / "journal.sqlite")
        before = watcher.execute("PRAGMA data_version").fetchone()[0]
        seen = {"payloads": 0}

        @FUZZ
        @given(batches("state", BATCH // 2), batches("task_request", BATCH // 2))
        def check(first: list[Case], second: list[Case]) -> None:
            for case in first + second:
                seen["payloads"] += 1
                query = RecordingQuery(case.payload)
                service._on_state(query)
                assert query.dropped and query.replies == [(key, expected)], case

        t0 = time.perf_counter()
        check()
        print(f"\nstate query: {seen['payloads']} payloads in {time.perf_counter() - t0:.1f} s")
        assert seen["payloads"] >= PAYLOADS
        assert watcher.execute("PRAGMA data_version").fetchone()[0] == before
        watcher.close()
    finally:
        service.executor.shutdown()
        service.journal.close()


# --- regressions the fuzzing found in intake.py -------------------------------------------------
def test_nesting_deeper_than_the_recursion_limit_is_refused(tmp_path: Path) -> None:
    # Was RecursionError (not a ValueError) from json.loads reading the client_ref.
    journal = Journal(tmp_path / "journal.sqlite")
    out = Intake(journal, AREA, clock=lambda: NOW).handle(b"[" * 2000 + b"]" * 2000)
    assert isinstance(out, Rejected) and out.reply.field == "payload"
    assert journal.requests() == []


def test_a_lone_surrogate_client_ref_is_not_echoed(tmp_path: Path) -> None:
    # The ref was echoed into the ErrorReply, which then could not be encoded: the service's
    # handler raised and the client got no answer.
    intake = Intake(Journal(tmp_path / "journal.sqlite"), AREA, clock=lambda: NOW)
    out = intake.handle(b'{"kind": "task_request", "user_id": "u", "x_m": 1, "y_m": 1, "tasks": 1, '
                        b'"client_ref": "\\ud800"}')
    assert isinstance(out, Rejected) and out.reply.client_ref is None and out.reply.field == "client_ref"
    assert decode_reply(encode(out.reply)) == out.reply
    named = intake.handle(b'{"kind": "task_request", "\\udfff": NaN, "client_ref": "mine"}')
    assert isinstance(named, Rejected) and named.reply.client_ref == "mine"
    assert decode_reply(encode(named.reply)) == named.reply  # the field is sent as an escape
