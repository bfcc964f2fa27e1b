"""Which mission a progress report (MISSION_CURRENT, MISSION_ITEM_REACHED) is about, as a
state machine with no I/O: it is told the MAVLink packet sequence (mod 256) and the arrival
time of each report and of each message that begins a new mission, and says, for each
report, to pass it on as about the mission held now or the one before, or to drop it.

The MISSION_ACK that accepts an upload begins a new mission. A report the vehicle sent
before that ACK but that arrives after it (a delayed or reordered datagram) is not about
the new one: the packet sequence says which was sent first, within ``reorder_window_s`` of
the ACK. A MISSION_ITEM_REACHED sent before it is about the previous mission (a point
completed just before the new mission replaced it is a service all the same); a
MISSION_CURRENT sent before it is dropped, since an autopilot may announce the new
mission's current item just before acking it (the stub does), and the stream repeats it.
Between our sending an upload's last item and the upload's end the vehicle may already fly
the new mission: reports of that span are held back and sorted by the ACK's sequence number
when it comes (all about the old mission if the upload fails; dropped if only a read-back
could tell).

The caller (``mavlink_link``) owns the generation counter: it applies the decisions in
order, a ``Pass`` with ``before`` about the generation before the one current when it is
applied, a ``Begin`` growing the generation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Generic, TypeVar

REACHED = "MISSION_ITEM_REACHED"
CURRENT = "MISSION_CURRENT"
REORDER_WINDOW_S = 1.0
"""A datagram sent before another arrives after it only within this much wall time."""

R = TypeVar("R")


def sent_before(seq: int, other: int) -> bool:
    """Was packet ``seq`` sent before packet ``other`` (sequence numbers mod 256, the two
    within half the range of each other)?"""
    return 0 < (other - seq) % 256 < 128


@dataclass(frozen=True)
class Pass(Generic[R]):
    """Pass ``report`` on: about the mission held now, or with ``before`` the one before."""

    report: R
    before: bool = False


@dataclass(frozen=True)
class Begin:
    """An accepted upload of ``total`` items begins a new mission here (generation + 1,
    progress at item 0)."""

    total: int


@dataclass
class _Held(Generic[R]):
    report: R
    kind: str
    packet_seq: int


@dataclass
class ReportSequencer(Generic[R]):
    """The sorting of progress reports between missions; ``R`` is whatever the caller
    passes reports as (a pymavlink message)."""

    reorder_window_s: float = REORDER_WINDOW_S
    mark: tuple[int, float] | None = None
    """(packet seq, arrival time) of the message that began the mission held now; None:
    no reordering to fear (none, or longer ago than the window)."""
    commit_possible: bool = False
    """An upload's last item went out: the vehicle may hold either mission until it ends."""
    held: list[_Held[R]] = field(default_factory=list)
    """Reports that came while ``commit_possible``: sorted when the upload ends."""

    def begin(self, packet_seq: int | None, now: float) -> None:
        """A new mission begins with the message of ``packet_seq`` (None: with no message
        of the vehicle's, e.g. a restart: nothing sent earlier can be told apart)."""
        self.mark = (packet_seq, now) if packet_seq is not None else None

    def upload_may_commit(self) -> None:
        """The upload's last item went out: hold reports back until it ends."""
        self.commit_possible = True

    def _fresh(self, packet_seq: int, now: float) -> bool:
        """Was this report sent after the message that began the mission held now?"""
        if self.mark is None:
            return True
        seq, at = self.mark
        if now - at > self.reorder_window_s:
            self.mark = None
            return True
        return sent_before(seq, packet_seq)

    def on_report(self, report: R, kind: str, packet_seq: int, now: float) -> list[Pass[R]]:
        """A report arrived (``kind`` REACHED or CURRENT): what to pass on now."""
        if kind not in (REACHED, CURRENT):
            raise ValueError(f"not a progress report: {kind!r}")
        if self.commit_possible:
            self.held.append(_Held(report, kind, packet_seq))  # about either mission: the ACK will say
            return []
        if self._fresh(packet_seq, now):
            return [Pass(report)]
        if kind == REACHED:
            return [Pass(report, before=True)]
        return []  # a MISSION_CURRENT sent before the ACK: about either mission

    def on_accepted(self, packet_seq: int, now: float, total: int) -> list[Pass[R] | Begin]:
        """The ACK (packet ``packet_seq``) accepted an upload of ``total`` items: the held
        reports sorted around the new mission's beginning. Reports still coming until the
        upload ends (``on_upload_ended``) are held as before and then passed on as about
        the new mission."""
        held, self.held = self.held, []
        before = [sent_before(h.packet_seq, packet_seq) for h in held]
        out: list[Pass[R] | Begin] = [Pass(h.report) for h, b in zip(held, before) if b and h.kind == REACHED]
        out.append(Begin(total))
        self.begin(packet_seq, now)
        out.extend(Pass(h.report) for h, b in zip(held, before) if not b)
        return out

    def on_upload_ended(self) -> list[Pass[R]]:
        """The upload ended without an ACCEPTED (or after one, sorted already): whatever is
        still held is about the mission the vehicle kept."""
        held, self.held = self.held, []
        self.commit_possible = False
        return [Pass(h.report) for h in held]

    def forget(self) -> None:
        """Drop what is held: only a read-back could tell which mission it is about."""
        self.held.clear()
