"""The sortie logic's view of the journal (``sortie.inputs.JournalView``), and the services the
journal could not record.

A service the journal refuses (its storage failed: the service degrades; or a transient
refusal) was flown all the same: its user was served and told so. If the view forgot it, the
request would still look pending with its whole backlog and no service, and the next point
near that user would bind it again: one request announced ``user_served`` twice, its
tasks counted twice (issue 23, seen in the degraded state). So a refused service is kept
here, in memory, and counted in every answer of the view until the sortie ends, exactly
as the journal counts a recorded one: its tasks taken off the request it names and off
its user's newer count where that count said ``served_seen``, its user's services one
more. (The log line of the refusal carries the service whole: what memory alone holds is
also on record there.)
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import JournalError
from .journal import Journal
from .rows import RequestRow


@dataclass(frozen=True)
class Unrecorded:
    """A service flown that the journal refused."""

    sortie: int
    request_id: int
    user_id: str
    tasks: int


class JournalWorld:
    """The journal's current sortie, with the services it refused counted in."""

    def __init__(self, journal: Journal) -> None:
        self.journal = journal
        self.unrecorded: list[Unrecorded] = []

    def record_service(self, request_id: int, user_id: str, tasks: int, hover_index: int,
                       xyz: tuple[float, float, float], bits: float, reward: float, battery_j: float, now_s: float,
                       bound_tasks: int | None = None) -> None:
        """``Journal.record_service``; if the journal refuses it, the service is kept here
        and the ``JournalError`` raised for the caller to tell (and to degrade on)."""
        try:
            self.journal.record_service(request_id, hover_index, xyz, tasks, bits, reward, battery_j, now_s,
                                        bound_tasks)
        except JournalError:
            self.unrecorded.append(Unrecorded(self.journal.sortie, request_id, user_id, tasks))
            raise

    def _now(self) -> list[Unrecorded]:
        return [u for u in self.unrecorded if u.sortie == self.journal.sortie]

    def _counted(self, row: RequestRow | None) -> RequestRow | None:
        """``row`` with the refused services counted as the journal counts recorded ones;
        None once nothing is left of it (the journal would have closed it ``served``)."""
        return None if row is None else row.with_served(self._now())

    def request_for(self, user_id: str) -> RequestRow | None:
        return self._counted(self.journal.request_in_force(user_id))

    def served_elsewhere(self, user_id: str) -> str | None:
        """A lone UAV serves its users alone: never."""
        return None

    def services_of(self, user_id: str) -> int:
        return self.service_counts().get(user_id, 0)

    def service_counts(self) -> dict[str, int]:
        counts = self.journal.service_counts()
        for u in self._now():
            counts[u.user_id] = counts.get(u.user_id, 0) + 1
        return counts

    def pending_count(self) -> int:
        return len(self.pending()) if self._now() else self.journal.pending_count()

    def pending(self) -> list[RequestRow]:
        rows = [self._counted(r) for r in self.journal.pending()]
        return [r for r in rows if r is not None]


class FleetWorld(JournalWorld):
    """A fleet member's view (docs/OPERATIONS.md, "A fleet"): the journal's, with the other
    members' services counted as its own (``remote``): each takes its tasks off the user's
    request in force here, as a service recorded here would. Who owns which user is not the
    world's: the sortie logic hears it (``inputs.FleetHeard``) and judges by it."""

    def __init__(self, journal: Journal) -> None:
        super().__init__(journal)
        self.remote: list[Unrecorded] = []

    def served_elsewhere(self, user_id: str) -> str | None:
        """Why a hold of this UAV that served ``user_id`` records nothing: the other members'
        services took the whole request in force while this hold lasted."""
        row = self.journal.request_in_force(user_id)
        sortie = self.journal.sortie
        if row is not None and self._counted(row) is None and any(u.user_id == user_id and u.sortie == sortie
                                                                  for u in self.remote):
            return f"another member served {user_id}'s request meanwhile"
        return None

    def count_remote(self, user_id: str, tasks: int) -> bool:
        """Count another member's service of ``user_id``; False when the user has no request
        in force here (nothing to take it off: its services still count)."""
        row = self.journal.request_in_force(user_id)
        self.remote.append(Unrecorded(self.journal.sortie, row.request_id if row else 0, user_id, tasks))
        return row is not None

    def _now(self) -> list[Unrecorded]:
        return [u for u in (*self.unrecorded, *self.remote) if u.sortie == self.journal.sortie]
