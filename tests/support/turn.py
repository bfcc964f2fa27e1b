"""The machine's turn for the heavy simulations: one at a time across the test workers.

A PX4 SITL (sped up, with MAVSDK's server beside it) and the fleet of three ArduCopter SITLs
each fill the two cores of the machine the suite runs on. Two of them at once starved both:
MAVSDK's upload of 3 items took 12-28 s and its arming came 50 s after it, so PX4's preflight
disarm came between the start's steps (the start refused, or the vehicle landed at item 0 and
the authority was revoked: the clean clones of 2026-12-06 and -07 and a CI run), and the
fleet's test took 239 s instead of 90. A real autopilot has its computer to itself; each test
alone passed.

A single ArduCopter SITL is lighter: two run side by side, each taking the turn shared
(``shared=True``), but not beside a PX4, which needs the turn alone: a PX4 whole sortie with
MAVSDK beside ArduCopter's SITL killed and restarted mid-flight (the clean clone of
2026-12-07, evening) took 7.3 s to upload 3 items and more than 6 s from the arming to the
mode, and PX4 disarmed on its own ("Disarmed by landing") before the mission began."""

from __future__ import annotations

import contextlib
import fcntl
import tempfile
import time
from pathlib import Path
from typing import Iterator

TURN_FILE = Path(tempfile.gettempdir()) / "uav-planner-heavy-sitl-turn.lock"
TURN_WAIT_S = 600.0
"""How long a test waits for its turn (a test holds it for its own length: the longest, the
fleet's take-over on three SITL copters, about 100 s on a loaded machine; the PX4 files' tests
one after the other take about 6 minutes)."""
POLL_S = 0.05
HANDOVER_S = 0.2
"""How long a test that ends its turn waits before it may take the next: longer than a
waiter's poll, so that a waiter takes the turn: the lock is not fair by itself, and a PX4
file's next test, asking within milliseconds of the last one's end, could keep it for the whole
file."""


_held: list[bool] = []
"""The turns this process holds now, each ``shared`` or not (a test inside another's turn, as
the fleet's three SITLs started under its exclusive one, takes nothing more)."""


@contextlib.contextmanager
def heavy_sitl_turn(wait_s: float = TURN_WAIT_S, shared: bool = False) -> Iterator[None]:
    """This test process's turn with a heavy simulation (a file lock across the workers):
    alone, or ``shared`` with other shared holders (single ArduCopter SITLs)."""
    if _held and not shared and all(_held):
        raise RuntimeError("a shared turn cannot become exclusive: take the exclusive one first")
    with contextlib.ExitStack() as turn:
        if not _held:
            turn.enter_context(_locked(wait_s, shared))
        _held.append(shared)
        try:
            yield
        finally:
            _held.pop()


@contextlib.contextmanager
def _locked(wait_s: float, shared: bool) -> Iterator[None]:
    """The lock file held (shared or alone), waited for at most ``wait_s``."""
    handle = open(TURN_FILE, "w")
    deadline = time.monotonic() + wait_s
    try:
        while True:
            try:
                fcntl.flock(handle, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"no turn with the heavy simulations within {wait_s:g} s: another "
                                       f"test process holds {TURN_FILE}") from None
                time.sleep(POLL_S)
        yield
    finally:
        handle.close()  # (closing releases the lock)
    time.sleep(HANDOVER_S)
