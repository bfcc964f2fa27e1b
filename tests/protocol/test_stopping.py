"""A command stops on its first SIGINT or SIGTERM and ignores the rest (protocol/stopping.py):
a harness repeating its SIGINT while the users' process finalised nested the old handler
(``lambda: stop.set()``) until RecursionError, exit status -2, once on CI
(test_users.py::test_a_stop_asked_while_the_users_process_finishes_never_kills_it)."""

from __future__ import annotations

import os
import signal
import threading

from protocol.stopping import SIGNALS, stop_on_signals


def test_the_first_signal_stops_and_the_rest_find_nothing_to_run() -> None:
    before = {sig: signal.getsignal(sig) for sig in SIGNALS}
    stop = threading.Event()
    try:
        stop_on_signals(stop)
        os.kill(os.getpid(), signal.SIGTERM)
        assert stop.wait(5.0)
        assert all(signal.getsignal(sig) == signal.SIG_IGN for sig in SIGNALS)
        for _ in range(100):  # what follows is ignored by the kernel: no Python code runs
            os.kill(os.getpid(), signal.SIGINT)
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
