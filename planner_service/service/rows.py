"""The journal's rows as the rest of the service reads them: plain frozen records, apart
from the SQLite journal that writes them, so that the pure sortie logic and the planner
depend on the records and not on the database."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Iterable, Protocol


@dataclass(frozen=True)
class RequestRow:
    """One request as the user sent it (``tasks``: its backlog then; ``served_seen``: the
    tasks of the user served in the sortie that this count had taken off, None if it did
    not say) and what became of it: ``served_tasks`` of it were served (by services naming
    it), ``user_served`` to its user in its sortie (by any request), ``backlog`` are left.
    The served counts are as of the reading (``Journal.request_in_force``: as of a moment)."""

    request_id: int
    user_id: str
    x_m: float
    y_m: float
    z_m: float
    tasks: int
    client_ref: str | None
    accepted_at_s: float
    status: str
    reason: str
    served_tasks: int = 0
    served_seen: int | None = None
    user_served: int = 0

    @property
    def served_unseen(self) -> int:
        """Tasks served to the user in the sortie that this count had not taken off: all
        beyond ``served_seen`` (0 when it did not say: an older client's count is taken as
        it is)."""
        return 0 if self.served_seen is None else max(self.user_served - self.served_seen, 0)

    @property
    def backlog(self) -> int:
        """Tasks of this request not yet served: its count less what was served that the
        count did not know of (at least the services naming it: a stale or false
        ``served_seen`` gives nothing back)."""
        return max(self.tasks - max(self.served_tasks, self.served_unseen), 0)

    def with_served(self, services: Iterable[Served]) -> RequestRow | None:
        """This request with ``services`` not in the journal counted as the journal counts
        recorded ones: their tasks taken off the request each names and off its user's
        count; None once nothing is left of it (the journal would have closed it ``served``)."""
        services = list(services)
        own = sum(s.tasks for s in services if s.request_id == self.request_id)
        user = sum(s.tasks for s in services if s.user_id == self.user_id)
        if not own and not user:
            return self
        row = replace(self, served_tasks=self.served_tasks + own, user_served=self.user_served + user)
        return row if row.backlog > 0 else None


class Served(Protocol):
    """A service as ``RequestRow.with_served`` counts it."""

    @property
    def request_id(self) -> int: ...

    @property
    def user_id(self) -> str: ...

    @property
    def tasks(self) -> int: ...


@dataclass(frozen=True)
class UserBacklog:
    """A user of the current sortie as the service counts it: its request in force (its
    newest), the backlog left on it (0 once it is served or closed), its services and the
    tasks they served in the sortie."""

    user_id: str
    request_id: int
    backlog: int
    services: int
    served_tasks: int


@dataclass(frozen=True)
class UserRow:
    """A user the service has heard from: where it last said it was, how often served."""

    user_id: str
    x_m: float
    y_m: float
    z_m: float
    services: int


@dataclass(frozen=True)
class ServiceRow:
    service_id: int
    request_id: int
    user_id: str
    tasks: int
    bits: float
    hover_index: int
    x_m: float
    y_m: float
    z_m: float
    reward: float
    battery_j: float
    time_s: float
    bound_tasks: int | None = None
    """The user's backlog when the hold was bound to its request: the u_i(t) of the
    fairness rule (3). ``tasks`` is what the hold carried, less when it was cut short (the
    battery's reserve, a hold seen only in part); None in rows written before it was kept."""

    @property
    def bound(self) -> int:
        """The backlog the service was bound to (the tasks served where it was not kept)."""
        return self.tasks if self.bound_tasks is None else self.bound_tasks


@dataclass(frozen=True)
class MissionRow:
    mission_id: int
    plan_id: int
    time_s: float
    result: str
    items: list[dict[str, Any]]
    points: list[dict[str, Any]]


@dataclass(frozen=True)
class SortieRow:
    """One sortie: ``ended_at_s`` is None while it runs; ``why`` says how it ended."""

    number: int
    started_at_s: float
    ended_at_s: float | None
    why: str

    @property
    def over(self) -> bool:
        return self.ended_at_s is not None
