"""Shared fixtures."""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path
from typing import Any, Callable, Iterator

import pytest

from tests.support import px4 as px4_support
from tests.support.px4 import Px4
from tests.support.sitl import Sitl, free_instance, sitl_binary, skip_reason
from tests.support.turn import heavy_sitl_turn

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def python_env() -> dict[str, str]:
    """Environment for subprocesses running this checkout's packages."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.fixture
def python() -> str:
    return sys.executable


@pytest.fixture
def make_sitl(tmp_path: Path) -> Iterator[Callable[..., Sitl]]:
    """A factory of ArduCopter SITLs (tests/support/sitl.py; keyword arguments go to ``Sitl``, e.g.
    ``serials``), each started in its own folder and instance and stopped at the end, beside
    no PX4 (the machine's turn, shared: ``tests/support/turn.py``); skipped where the binary
    is missing."""
    binary = sitl_binary()
    if binary is None:
        pytest.skip(skip_reason())
    started: list[Sitl] = []
    turn = contextlib.ExitStack()

    def make(**options: Any) -> Sitl:
        if not started:
            turn.enter_context(heavy_sitl_turn(shared=True))
        folder = tmp_path / f"sitl-{len(started)}"
        folder.mkdir()
        s = Sitl(binary, folder, options.pop("instance", None) or free_instance(), **options)
        started.append(s)
        s.start()
        return s

    try:
        yield make
    finally:
        for s in started:
            s.stop()
        turn.close()


@pytest.fixture
def sitl(make_sitl: Callable[..., Sitl]) -> Sitl:
    """A fresh ArduCopter SITL, running but not yet with a position."""
    return make_sitl()


@pytest.fixture
def sitl_ready(sitl: Sitl) -> Sitl:
    """``sitl`` once its EKF uses the GPS (it can arm and fly AUTO)."""
    sitl.wait_ready()
    return sitl


@pytest.fixture
def make_px4(tmp_path: Path) -> Iterator[Callable[..., Px4]]:
    """A factory of PX4 SITLs (tests/support/px4.py; keyword arguments go to ``Px4``, e.g.
    ``params``; ``start=False``: not started yet, for a test that listens before PX4's
    first second), each in its own folder and instance and stopped at the end, one test
    process's PX4s at a time on the machine, beside no other heavy simulation
    (``tests/support/turn.py``); skipped where PX4 SITL is missing."""
    root = px4_support.px4_root()
    if root is None:
        pytest.skip(px4_support.skip_reason())
    started: list[Px4] = []
    turn = contextlib.ExitStack()

    def make(**options: Any) -> Px4:
        if not started:
            turn.enter_context(heavy_sitl_turn())
        folder = tmp_path / f"px4-{len(started)}"
        folder.mkdir()
        start = options.pop("start", True)
        p = Px4(root, folder, options.pop("instance", None) or px4_support.free_instance(), **options)
        started.append(p)
        if start:
            p.start()
        return p

    try:
        yield make
    finally:
        for p in started:
            p.stop()
        turn.close()


@pytest.fixture
def heavy_turn() -> Iterator[None]:
    """This test's turn with the machine among the heavy simulations (``tests/support/turn.py``):
    for a test that starts several SITLs at once, before it starts them."""
    with heavy_sitl_turn():
        yield


@pytest.fixture
def px4(make_px4: Callable[..., Px4]) -> Px4:
    """A fresh PX4 SITL, running but not yet ready to arm."""
    return make_px4()


@pytest.fixture
def px4_ready(px4: Px4) -> Px4:
    """``px4`` once its pre-arm checks pass (it can arm and fly a mission)."""
    px4.wait_ready()
    return px4


def pytest_terminal_summary(terminalreporter: Any) -> None:
    """Skipped browser tests are said loudly at the end of the run (as a missing SITL would
    leave its tests unproved): the one command that installs what they need."""
    from tests.support.browser import SKIP_REASON

    skipped = [r for r in terminalreporter.stats.get("skipped", []) if SKIP_REASON in str(r.longrepr)]
    if skipped:
        terminalreporter.write_sep("!", f"{len(skipped)} LIVE MAP BROWSER TESTS SKIPPED", red=True, bold=True)
        terminalreporter.write_line(SKIP_REASON, red=True)
