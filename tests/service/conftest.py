"""Fixtures of the service's end-to-end tests (see tests/support/stack.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Iterator

import pytest

from tests.support.stack import Stack


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[Stack]:
    s = Stack(tmp_path)
    try:
        yield s
    finally:
        s.close()
