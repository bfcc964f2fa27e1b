"""The service's events: one type per wire kind, exactly the kinds decoders accept, each
carried to the wire escaped and bounded."""

from __future__ import annotations

from typing import get_args

from planner_service.service import events as ev
from protocol import Event, decode, encode
from protocol.messages import EventKind


def test_every_wire_kind_has_its_type_and_no_more() -> None:
    assert set(ev.KINDS) == set(get_args(EventKind))
    assert all(cls.kind == kind for kind, cls in ev.KINDS.items())


def test_an_event_on_the_wire() -> None:
    wire = ev.to_wire(ev.UserServed("12 tasks\nat point 3\x1b[2J" + "x" * 400, "u-1", 7), 12.5)
    back = decode(encode(wire), Event)
    assert (back.event, back.user_id, back.request_id, back.time_s) == ("user_served", "u-1", 7, 12.5)
    assert "\n" not in back.detail and "\x1b" not in back.detail and len(back.detail) <= 256


def test_each_event_class_is_named_for_its_wire_kind() -> None:
    # the naming rule of docs/DESIGN.md ("Names"): `landed` is `Landed`, and only that
    assert all(cls.__name__ == "".join(w.capitalize() for w in kind.split("_")) for kind, cls in ev.KINDS.items())
