"""Fixtures of the service's end-to-end tests (see tests/support/stack.py and, for a fleet,
tests/support/fleet_stack.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

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
