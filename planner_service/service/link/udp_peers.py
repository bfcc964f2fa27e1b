"""pymavlink's UDP server (``udpin:``) keeps the addresses it heard from in a set that its
``write`` iterates, sending to each, while ``recv`` adds to it. The service reads in one
thread and sends from another: a datagram from a new address during a send to two or more
ended the send with ``RuntimeError: Set changed size during iteration`` (and the task that
asked for telemetry with it, on a clean-clone CI run). ``SnapshotSet`` iterates over a copy,
so the reader may add while a send goes on.

The copy is ``set.copy``: it allocates the new set first and then copies the table without
running Python code, so no other thread can run in between. ``list(iter(s))``, tried first,
is not: allocating the list may start a garbage collection, which may run Python code (a
finaliser, a gc callback), which lets the reader thread add after the iterator was made; a
later clean-clone CI run failed just so.)"""

from __future__ import annotations

from typing import Any, Iterator


class SnapshotSet(set):  # type: ignore[type-arg]
    """A set whose iteration is over a copy of it taken at once."""

    def __iter__(self) -> Iterator[Any]:
        return iter(set.copy(self))


def safe_peers(conn: Any) -> None:
    """Make ``conn``'s set of UDP peers safe to add to while it sends (a no-op elsewhere)."""
    if isinstance(getattr(conn, "clients", None), set) and not isinstance(conn.clients, SnapshotSet):
        conn.clients = SnapshotSet(conn.clients)
