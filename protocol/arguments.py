"""The command lines' edges, shared by ``python -m planner_service`` and ``python -m
sim_bridge``: a parser whose every error is one line naming the option (exit status 2, no
usage block, no traceback), and option types that check a value when it is parsed, so that
a bad endpoint, number or file is refused before anything starts.

Kept free of zenoh and the service, so that building a parser (and ``--help``) stays fast.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import NoReturn

from .keys import _CHUNK
from .zenoh_config import endpoint_problem

USAGE_ERROR = 2
"""Exit status of a command-line error (argparse's, and every command's own)."""


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line: ``PROG: error: MESSAGE (see
    --help)``, exit status 2. Its subparsers are of the same class."""

    def error(self, message: str) -> NoReturn:
        self.exit(USAGE_ERROR, f"{self.prog}: error: {message} (see --help)\n")


def zenoh_endpoint(text: str) -> str:
    """A zenoh endpoint (``tcp/HOST:PORT``, ``tls/HOST:PORT``, ...), checked as parsed."""
    why = endpoint_problem(text)
    if why is not None:
        raise argparse.ArgumentTypeError(why)
    return text


def existing_file(text: str) -> str:
    """The path of a file that exists (and is a file), checked as parsed."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{text}: no such file")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"{text}: not a file")
    return text


def key_chunk(text: str) -> str:
    """A key expression chunk (prefix, vehicle id): 1-64 of A-Z a-z 0-9 _ . -"""
    if not _CHUNK.fullmatch(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not a key chunk (1-64 of A-Z a-z 0-9 _ . -)")
    return text


def _number(text: str, kind: type) -> float:
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def positive_float(text: str) -> float:
    value = _number(text, float)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text} is not positive")
    return value


def non_negative_float(text: str) -> float:
    value = _number(text, float)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} is negative")
    return value


def finite_float(text: str) -> float:
    return _number(text, float)


def probability(text: str) -> float:
    value = _number(text, float)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"{text} is not a probability in [0, 1]")
    return value


def positive_int(text: str) -> int:
    value = int(_number(text, int))
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} is not at least 1")
    return value


def non_negative_int(text: str) -> int:
    value = int(_number(text, int))
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} is negative")
    return value
