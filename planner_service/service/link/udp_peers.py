"""pymavlink's UDP server (``udpin:``) keeps the addresses it heard from in a set that its
``write`` iterates, sending to each, while ``recv`` adds to it. The service reads in one
thread and sends from another: a datagram from a new address during a send to two or more
ended the send with ``RuntimeError: Set changed size during iteration`` (and the task that
asked for telemetry with it, on a clean-clone CI run). ``SnapshotSet`` iterates over a copy,
taken in one C call under the GIL, so the reader may add while a send goes on."""

from __future__ import annotations

from typing import Any, Iterator


class SnapshotSet(set):  # type: ignore[type-arg]
    """A set whose iteration is over a copy of it taken at once."""

    def __iter__(self) -> Iterator[Any]:
        return iter(list(set.__iter__(self)))


def safe_peers(conn: Any) -> None:
    """Make ``conn``'s set of UDP peers safe to add to while it sends (a no-op elsewhere)."""
    if isinstance(getattr(conn, "clients", None), set) and not isinstance(conn.clients, SnapshotSet):
        conn.clients = SnapshotSet(conn.clients)
