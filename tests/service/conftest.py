"""Fixtures of the service's end-to-end tests (see stack.py)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Iterator

import pytest
from stack import Stack

# The hostile-payload strategies live beside the protocol tests; the service's fuzz tests
# draw from the same ones.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "protocol"))


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[Stack]:
    s = Stack(tmp_path)
    try:
        yield s
    finally:
        s.close()
