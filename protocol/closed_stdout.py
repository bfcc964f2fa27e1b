"""A command line whose reader went away (``python -m planner_service operator status |
head -1``) ends quietly, as ``cat`` or ``yes`` would, instead of with a BrokenPipeError
traceback. Shared by ``python -m planner_service`` and ``python -m sim_bridge``.

Python ignores SIGPIPE, so a write to a pipe with no reader raises BrokenPipeError, and what
is still buffered fails again when the interpreter flushes stdout at exit ("Exception
ignored ..."). The recipe of Python's documentation (signal module, "Note on SIGPIPE"):
catch the error at the top, point stdout at /dev/null so that no later flush fails, exit.
Restoring SIGPIPE's default action instead would kill ``serve`` or ``demo`` wherever the
write happened, between two journal writes or with children left running.
"""

from __future__ import annotations

import os
import select
import sys
from typing import Callable

CLOSED_STDOUT = 141
"""Exit status when the reader of stdout went away: 128 + SIGPIPE, what a shell reports for
a command SIGPIPE ended (``cat``, ``yes``), so that ``set -o pipefail`` and ``PIPESTATUS``
read it as theirs; apart from 1 (a command failed, or was refused) and 2 (a usage error),
which would say something about the command that is not so."""


def quiet_on_closed_stdout(main: Callable[[], int]) -> int:
    """``main()``'s exit status, or ``CLOSED_STDOUT`` if it (or argparse's ``--help``) wrote
    to a stdout whose reader had gone. A BrokenPipeError from anything else (a socket, a
    child's pipe) is not stdout's, and is raised as it came."""
    try:
        try:
            status = main()
        except SystemExit:  # argparse's --help and usage errors exit: flush what they printed here
            _flush_stdout()
            raise
        _flush_stdout()  # what is still buffered fails here, not at the interpreter's exit
        return status
    except BrokenPipeError:
        if not _stdout_reader_gone():
            raise
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the buffer's rest goes nowhere at exit
        os.close(devnull)
        return CLOSED_STDOUT


def _flush_stdout() -> None:
    if sys.stdout is not None:
        sys.stdout.flush()


def _stdout_reader_gone() -> bool:
    """Is stdout a pipe (or socket) with no reader left? The write end of such a pipe polls
    POLLERR."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # no stdout, or one without a descriptor
        return False
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & (select.POLLERR | select.POLLHUP) for _, events in poller.poll(0))
