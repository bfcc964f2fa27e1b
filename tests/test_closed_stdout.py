"""A command whose reader goes away (``python -m planner_service plan --json | head -1``)
ends quietly: exit status 141, nothing on stderr, no BrokenPipeError traceback. Real pipes:
the reader reads one line and closes its end while the command still has more to write
(the pipe shrunk to one page, so that the command surely waits on it), or closes it before
the command writes at all. ``operator status`` against a service: tests/service/test_operator_cli.py."""

from __future__ import annotations

import fcntl
import os
import subprocess
import sys
from pathlib import Path

import pytest

from protocol.closed_stdout import CLOSED_STDOUT, quiet_on_closed_stdout

REPO = Path(__file__).resolve().parents[1]
PLAN = ("-m", "planner_service", "plan", "--algo", "greedy", "--json", "--set", "max_intervals=0")
"""About 6 KB of JSON: more than the one page the pipe holds after its first line."""


def one_page_pipe() -> tuple[int, int]:
    """A pipe that holds one page: a writer with more to say than that waits on its reader."""
    read, write = os.pipe()
    fcntl.fcntl(write, fcntl.F_SETPIPE_SZ, 4096)
    return read, write


def head_1(args: tuple[str, ...], env: dict[str, str]) -> tuple[bytes, int, str]:
    """What ``python ARGS | head -1`` sees: (its one line, the command's exit status, its stderr)."""
    read, write = one_page_pipe()
    proc = subprocess.Popen([sys.executable, *args], cwd=REPO, env=env, stdout=write, stderr=subprocess.PIPE)
    os.close(write)
    line = b""
    while not line.endswith(b"\n"):  # byte by byte: the page stays full until the reader closes
        byte = os.read(read, 1)
        if not byte:
            break
        line += byte
    os.close(read)
    _, err = proc.communicate(timeout=120)
    return line, proc.returncode, err.decode()


def closed_before(args: tuple[str, ...], env: dict[str, str]) -> tuple[int, str]:
    """The command run with a stdout whose reader has already gone: (exit status, stderr)."""
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, *args], cwd=REPO, env=env, stdout=write, stderr=subprocess.PIPE,
                              timeout=120)
    finally:
        os.close(write)
    return done.returncode, done.stderr.decode()


@pytest.mark.parametrize("unbuffered", ["1", ""])
def test_plan_json_into_head_1_ends_quietly(python_env: dict[str, str], unbuffered: str) -> None:
    # Was: BrokenPipeError traceback from json.dump (written a chunk at a time with
    # PYTHONUNBUFFERED), or "Exception ignored ... BrokenPipeError" and status 120 from the
    # interpreter's last flush (buffered).
    line, status, err = head_1(PLAN, {**python_env, "PYTHONUNBUFFERED": unbuffered})
    assert line == b"{\n"
    assert (status, err) == (CLOSED_STDOUT, "")


@pytest.mark.parametrize("module", ["planner_service", "sim_bridge"])
def test_help_into_a_closed_pipe_ends_quietly(python_env: dict[str, str], module: str) -> None:
    # argparse prints the help and exits (SystemExit): the flush of what it printed comes
    # before the exit. Unbuffered, argparse's own write meets the closed pipe and argparse
    # drops the error itself (it ignores OSError on its messages): its status 0 stands.
    assert closed_before(("-m", module, "--help"), {**python_env, "PYTHONUNBUFFERED": ""}) == (CLOSED_STDOUT, "")
    assert closed_before(("-m", module, "--help"), {**python_env, "PYTHONUNBUFFERED": "1"}) == (0, "")


def test_operator_status_without_a_service_prints_its_error_whatever_stdout_is(python_env: dict[str, str]) -> None:
    # Nothing goes to stdout: the error line on stderr and status 1, as with an open pipe.
    status, err = closed_before(("-m", "planner_service", "operator", "status", "--timeout", "0.5",
                                 "--connect", "tcp/127.0.0.1:9"), python_env)
    assert status == 1 and err.startswith("error: service: cannot open a zenoh session to ['tcp/127.0.0.1:9']"), err
    assert "Traceback" not in err


def test_a_broken_pipe_that_is_not_stdout_s_is_raised() -> None:
    # A BrokenPipeError of a socket or a child's pipe is a failure of the command, not the
    # reader of its output leaving: it must not end quietly.
    def main() -> int:
        raise BrokenPipeError(32, "a socket's")

    with pytest.raises(BrokenPipeError, match="a socket's"):
        quiet_on_closed_stdout(main)
    assert quiet_on_closed_stdout(lambda: 3) == 3
