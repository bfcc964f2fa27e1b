"""What a ``dec-mcts`` UAV tells the others: a compact probability distribution over its own
next action sequences (Best et al., Dec-MCTS, IJRR 2019, Section 4: the robots exchange
such distributions, not their trees), and its encoding as a small byte string.

Layout (little-endian, ``struct``): a 10-byte header ``<BHhhBBB`` (sender, the sender's
interval count when it sent, the point it holds now, the user it serves now, k sequences,
their length d, a format version), then k records of d ``int16`` points (``AT_BASE``, -1,
pads a line that ends early) and one ``uint16`` probability in 1/65535. Size
10 + k (2 d + 2) bytes: 42 for k = 4, d = 3, whatever the number of users or points (up to
32767 of each)."""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from ..model.interval import AT_BASE

VERSION = 1
_HEADER = struct.Struct("<BHhhBBB")
_LIMIT = 32767
"""Largest point or user index an int16 holds."""


class MessageError(ValueError):
    """A plan message that cannot be encoded or decoded; ``field`` names what is wrong."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field


@dataclass(frozen=True)
class PlanMessage:
    """One UAV's published plan: ``point`` and ``user`` it holds and serves now (``AT_BASE``
    / ``NO_USER``: none), and ``sequences`` (k, d) int: its k likeliest next action
    sequences of d points (padded with ``AT_BASE``), with ``probs`` (k,) summing to 1."""

    sender: int
    interval: int
    point: int
    user: int
    sequences: np.ndarray
    probs: np.ndarray

    def encode(self) -> bytes:
        seqs = np.asarray(self.sequences, dtype=np.int64)
        probs = np.asarray(self.probs, dtype=np.float64)
        if seqs.ndim != 2 or len(probs) != len(seqs):
            raise MessageError("sequences", f"sequences (k, d) and probs (k,) disagree: {seqs.shape}, {probs.shape}")
        k, d = seqs.shape
        if not (0 <= self.sender < 256 and 0 <= self.interval < 65536 and k < 256 and d < 256):
            raise MessageError("header", f"sender {self.sender}, interval {self.interval}, k {k}, d {d} out of range")
        for name, value in (("point", self.point), ("user", self.user)):
            if not -1 <= value <= _LIMIT:
                raise MessageError(name, f"{name} {value} outside [-1, {_LIMIT}]")
        if k and (seqs.min() < AT_BASE or seqs.max() > _LIMIT):
            raise MessageError("sequences", f"points must lie in [-1, {_LIMIT}]")
        if k and (probs.min() < 0 or not np.isclose(probs.sum(), 1.0)):
            raise MessageError("probs", f"probabilities must be non-negative and sum to 1, got {probs.tolist()}")
        body = b"".join(struct.pack(f"<{d}hH", *row.tolist(), int(round(p * 65535))) for row, p in zip(seqs, probs))
        return _HEADER.pack(self.sender, self.interval, self.point, self.user, k, d, VERSION) + body


def decode(data: bytes) -> PlanMessage:
    """The message ``data`` holds; ``MessageError`` names the field that is wrong."""
    if len(data) < _HEADER.size:
        raise MessageError("header", f"{len(data)} bytes, fewer than the {_HEADER.size}-byte header")
    sender, interval, point, user, k, d, version = _HEADER.unpack_from(data)
    if version != VERSION:
        raise MessageError("version", f"version {version}, expected {VERSION}")
    record = struct.Struct(f"<{d}hH")
    if len(data) != _HEADER.size + k * record.size:
        raise MessageError("length", f"{len(data)} bytes for k = {k}, d = {d}: expected "
                                     f"{_HEADER.size + k * record.size}")
    rows = [record.unpack_from(data, _HEADER.size + i * record.size) for i in range(k)]
    seqs = np.array([r[:d] for r in rows], dtype=np.int64).reshape(k, d)
    weights = np.array([r[d] for r in rows], dtype=np.float64)
    if k and weights.sum() <= 0:
        raise MessageError("probs", "every probability is zero")
    probs = weights / weights.sum() if k else weights  # undo the rounding's drift
    return PlanMessage(sender, interval, point, user, seqs, probs)


__all__ = ["MessageError", "PlanMessage", "VERSION", "decode"]
