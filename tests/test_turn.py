"""The machine's turn for the heavy simulations (``tests/support/turn.py``): a PX4 (or the
fleet's three SITLs) alone; single ArduCopter SITLs side by side, but never beside a PX4.
Another worker is played by a second open file description of the lock (``flock`` locks of
two descriptions conflict, in one process as in two)."""

from __future__ import annotations

import fcntl
from pathlib import Path

import pytest

from tests.support import turn


@pytest.fixture
def lock(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    path = tmp_path / "turn.lock"
    monkeypatch.setattr(turn, "TURN_FILE", path)
    monkeypatch.setattr(turn, "HANDOVER_S", 0.0)
    return path


def other_worker(path: Path, shared: bool) -> object:
    handle = open(path, "a")
    fcntl.flock(handle, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
    return handle


def test_single_arducopters_share_the_turn_and_a_px4_waits_for_them(lock: Path) -> None:
    other = other_worker(lock, shared=True)  # an ArduCopter SITL on the other worker
    with turn.heavy_sitl_turn(wait_s=0.5, shared=True):
        pass  # a second one runs beside it
    with pytest.raises(RuntimeError, match="no turn"):
        with turn.heavy_sitl_turn(wait_s=0.3):  # a PX4 does not
            pass
    other.close()  # type: ignore[attr-defined]
    with turn.heavy_sitl_turn(wait_s=0.5):
        pass


def test_an_arducopter_waits_for_a_px4_and_a_turn_held_is_not_asked_again(lock: Path) -> None:
    other = other_worker(lock, shared=False)  # a PX4 on the other worker
    with pytest.raises(RuntimeError, match="no turn"):
        with turn.heavy_sitl_turn(wait_s=0.3, shared=True):
            pass
    other.close()  # type: ignore[attr-defined]
    with turn.heavy_sitl_turn(wait_s=0.5):  # the fleet's exclusive turn...
        with turn.heavy_sitl_turn(wait_s=0.3, shared=True):  # ...covers the SITLs it starts
            pass
        assert turn._held == [False]
    assert turn._held == []
    with turn.heavy_sitl_turn(wait_s=0.5, shared=True):
        with pytest.raises(RuntimeError, match="cannot become exclusive"):
            with turn.heavy_sitl_turn(wait_s=0.3):
                pass
