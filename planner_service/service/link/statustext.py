"""STATUSTEXT chunks joined into the autopilot's sentence (pure; the link feeds it).

A STATUSTEXT carries 50 characters. A longer text goes as chunks sharing a non-zero ``id``,
numbered by ``chunk_seq`` from 0; the chunk with fewer than 50 characters (a NUL in the
field) is the last (MAVLink common.xml, STATUSTEXT). PX4 splits its longer texts so
(``RTL: start return at 588 m (100 m above destinatio`` + ``n)``, seen on PX4 SITL), and ends
the texts it also sends as events with a tab, which ground stations do not show.
PX4 numbers every text, chunked or not, from 0 at its boot (``STATUSTEXT.hpp``'s counter):
the first text of a boot has id 0 and, when long, chunks 0, 1... of id 0 (seen on PX4 SITL
1.18: ``Arming denied: Resolve system health failures firs`` + ``t``). With
``id_zero_chunks`` (the autopilot's ``text_ids_from_zero``) a full id-0 chunk waits for
its continuation as any other; ArduPilot's id 0 is a text of one message, given out at once.
A text whose last chunk never comes is given out as far as it got once the next text
begins or ``STALE_S`` passed, marked as cut: nothing the autopilot said is dropped.
"""

from __future__ import annotations

from dataclasses import dataclass, field

CHUNK_CHARS = 50
"""STATUSTEXT.text's length: a shorter chunk is the last."""
STALE_S = 2.0
"""Wall seconds a text waits for its next chunk."""
CUT = " [...]"
"""Appended where chunks of a text were lost."""


@dataclass
class _Partial:
    id: int
    severity: int
    started: float
    chunks: dict[int, str] = field(default_factory=dict)

    def text(self) -> str:
        expected = range(max(self.chunks) + 1)
        joined = "".join(self.chunks.get(i, CUT) for i in expected)
        return joined.rstrip("\t")


@dataclass
class StatusTexts:
    """Joins STATUSTEXT chunks; ``feed`` returns the texts completed by one message."""

    partial: _Partial | None = None
    id_zero_chunks: bool = False
    """Id 0 may be a chunked text's (PX4's first text of a boot); False: id 0 is one message."""

    def feed(self, text: str, severity: int, text_id: int, chunk_seq: int, now: float) -> list[tuple[str, int]]:
        """``text`` as decoded (no NULs); ``text_id`` 0: a text of one chunk."""
        done = self.flush(now)
        complete = len(text) < CHUNK_CHARS
        if text_id == 0 and not (self.id_zero_chunks and (not complete or chunk_seq > 0)):
            return done + [(text.rstrip("\t"), severity)]
        p = self.partial
        if p is not None and p.id != text_id:
            done.append((p.text() + CUT, p.severity))
            p = None
        if p is None:
            p = _Partial(text_id, severity, now)
        p.chunks[chunk_seq] = text
        self.partial = p
        if complete:
            self.partial = None
            cut = len(p.chunks) != max(p.chunks) + 1
            done.append((p.text() + (CUT if cut else ""), p.severity))
        return done

    def flush(self, now: float) -> list[tuple[str, int]]:
        """The text waiting longer than ``STALE_S`` for its last chunk, as far as it got."""
        p = self.partial
        if p is None or now - p.started < STALE_S:
            return []
        self.partial = None
        return [(p.text() + CUT, p.severity)]
