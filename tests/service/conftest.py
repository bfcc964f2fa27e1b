"""Fixtures of the service's end-to-end tests (see tests/support/stack.py and, for a fleet,
tests/support/fleet_stack.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Iterator

import pytest
import zenoh

from planner_service.harness.processes import free_port
from protocol.zenoh_config import session_config
from tests.support.fleet_stack import FleetStack
from tests.support.stack import Stack


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[Stack]:
    s = Stack(tmp_path)
    try:
        yield s
    finally:
        s.close()


@pytest.fixture
def fleet(tmp_path: Path) -> Iterator[FleetStack]:
    """Two meshed routers; UAVs (a stub or an autopilot, and a service each) added by the test."""
    f = FleetStack(tmp_path)
    try:
        yield f
    finally:
        f.close()


@pytest.fixture
def mesh() -> Iterator[Callable[[], Any]]:
    """A router on loopback and a maker of client sessions to it (timestamping on, as a
    fleet member's own session is)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    router = zenoh.open(session_config("router", listen=[endpoint]))
    sessions: list[Any] = []

    def client() -> Any:
        conf = session_config("client", connect=[endpoint])
        conf.insert_json5("timestamping/enabled", "true")
        sessions.append(zenoh.open(conf))
        return sessions[-1]
    try:
        yield client
    finally:
        for s in sessions:
            s.close()
        router.close()
