"""Shared fixtures."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Iterator

import pytest

from support.sitl import Sitl, free_instance, sitl_binary, skip_reason

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
def sitl(tmp_path: Path) -> Iterator[Sitl]:
    """A fresh ArduCopter SITL (support/sitl.py), running but not yet with a position;
    skipped where the binary is missing."""
    binary = sitl_binary()
    if binary is None:
        pytest.skip(skip_reason())
    folder = tmp_path / "sitl"
    folder.mkdir()
    s = Sitl(binary, folder, free_instance())
    try:
        s.start()
        yield s
    finally:
        s.stop()


@pytest.fixture
def sitl_ready(sitl: Sitl) -> Sitl:
    """``sitl`` once its EKF uses the GPS (it can arm and fly AUTO)."""
    sitl.wait_ready()
    return sitl
