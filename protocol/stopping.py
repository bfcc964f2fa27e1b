"""Stopping a command on SIGINT or SIGTERM, once: the first signal sets the command's stop
event and the rest are ignored. A handler that sets a ``threading.Event`` runs Python code
between any two bytecodes of the main thread; signals arriving faster than it ran (a harness
repeating its SIGINT while the process finalises, as ``test_users.py`` does every 2 ms on a
loaded machine) nested it until ``RecursionError`` and exit status -2."""

from __future__ import annotations

import signal
import threading
from types import FrameType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


def stop_on_signals(stop: threading.Event) -> None:
    """Set ``stop`` on the first SIGINT or SIGTERM; ignore those that follow."""

    def handler(_signum: int, _frame: FrameType | None) -> None:
        for sig in SIGNALS:  # first, so that a signal arriving now finds nothing to nest
            signal.signal(sig, signal.SIG_IGN)
        stop.set()

    for sig in SIGNALS:
        signal.signal(sig, handler)
