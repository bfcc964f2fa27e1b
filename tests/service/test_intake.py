"""Intake with a pinned clock: a good request is journalled then acked; each bad one is
refused naming its field and changes nothing."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from planner_service.service.intake import Accepted, Intake, Rejected
from planner_service.service.journal import Journal
from protocol import Area

NOW = 1_732_312_000.5


def make(tmp_path: Path) -> tuple[Intake, Journal]:
    journal = Journal(tmp_path / "j.sqlite")
    return Intake(journal, Area(500.0, 120.0, 10.0), clock=lambda: NOW), journal


def request(**fields: object) -> bytes:
    base = {"kind": "task_request", "schema": 1, "user_id": "u-7", "x_m": 120.5, "y_m": 30.0, "tasks": 12,
            "client_ref": "my-42"}
    base.update(fields)
    return json.dumps({k: v for k, v in base.items() if v is not None}).encode()


def test_accept_then_ack(tmp_path: Path) -> None:
    intake, journal = make(tmp_path)
    out = intake.handle(request())
    assert isinstance(out, Accepted)
    assert (out.reply.request_id, out.reply.accepted_at_s, out.reply.queue_position, out.reply.client_ref) == \
        (1, NOW, 1, "my-42")
    row = journal.request(1)
    assert row is not None and (row.user_id, row.x_m, row.tasks, row.accepted_at_s) == ("u-7", 120.5, 12, NOW)
    again = intake.handle(request(tasks=3, client_ref="my-43"))
    assert isinstance(again, Accepted) and again.replaced == (1,) and again.reply.queue_position == 1


@pytest.mark.parametrize("payload, field", [
    (b"not json", "payload"),
    (request(x_m=900.0), "x_m"),
    (request(tasks=-1), "tasks"),
    (request(tasks=5000), "tasks"),
    (request(user_id="a/b"), "user_id"),
    (request(extra=1), "extra"),
    (request(schema=2), "schema"),
    (request(user_id=None), "user_id"),
    (b'{"kind": "task_request", "user_id": "u", "x_m": NaN, "y_m": 1, "tasks": 1}', "x_m"),
    (b"{" + b" " * 5000 + b"}", "payload"),
    (None, "payload"),
])
def test_bad_requests_change_nothing(tmp_path: Path, payload: bytes | None, field: str) -> None:
    intake, journal = make(tmp_path)
    intake.handle(request())
    before = journal.requests()
    out = intake.handle(payload)
    assert isinstance(out, Rejected) and out.reply.field == field, out
    assert out.reply.message
    assert journal.requests() == before


def test_closed_intake_refuses_with_the_reason(tmp_path: Path) -> None:
    intake, journal = make(tmp_path)
    intake.closed_reason = "the service is shutting down"
    out = intake.handle(request())
    assert isinstance(out, Rejected) and out.reply.field == "service"
    assert out.reply.message == "the service is shutting down" and out.reply.client_ref == "my-42"
    assert journal.requests() == []
