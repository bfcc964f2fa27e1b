"""Supervision of the service's background tasks (asyncio only: no zenoh, no MAVLink).

A task of ``asyncio.create_task`` that raises keeps its exception to itself until someone
awaits it; the service awaited its loops only at shutdown, so a loop that died (a journal
write error in the status loop) took the status, the battery guard and the plans with it,
silently, while the intake went on acking. Under a ``Supervisor`` every task is watched
from the moment it ends:

- a task that raises anything but ``CancelledError`` is logged with its traceback and
  reported once to ``on_failure(name, exc)``, which the service uses to degrade (stop the
  intake, publish why, withdraw its liveliness);
- a task started with ``forever=True`` (a loop meant to run for the service's life) that
  returns on its own is a failure too (``TaskEnded``), unless the service is stopping;
- a task cancelled (by ``stop`` or by anyone) is not a failure.

``stop(grace_s, cancel_wait_s)`` is the one shutdown path, bounded: the ``stopping`` event
is set, tasks get ``grace_s`` to end by themselves, the rest are cancelled and get
``cancel_wait_s`` more; a task that survives even that is reported ``stuck`` and left
behind (logged), never waited for without bound. Failures while stopping are logged and
recorded but not reported to ``on_failure``: the service is going down already.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass
from typing import Any, Callable, Coroutine

from .errors import ServiceError

log = logging.getLogger("planner_service.supervisor")

FailureHandler = Callable[[str, BaseException], None]


class SupervisorError(ServiceError):
    """A task could not be started (a duplicate name, or the supervisor is stopping)."""


class TaskEnded(ServiceError):
    """A task meant to run until the service stops returned on its own."""


@dataclass(frozen=True)
class Failure:
    """A supervised task that failed: its name and what it raised."""

    name: str
    error: BaseException
    while_stopping: bool


@dataclass(frozen=True)
class StopReport:
    """What ``stop`` found: tasks that ended within the grace, tasks it cancelled, and
    tasks still running after their cancellation (left behind)."""

    ended: tuple[str, ...]
    cancelled: tuple[str, ...]
    stuck: tuple[str, ...]


class Supervisor:
    """Runs named coroutines as tasks on the running loop and reports their failures."""

    def __init__(self, on_failure: FailureHandler, stopping: asyncio.Event | None = None,
                 logger: logging.Logger = log) -> None:
        """``stopping``: the service's own stop event, if it has one (a task may end
        quietly once it is set); ``stop`` sets it."""
        self.on_failure = on_failure
        self.stopping = stopping if stopping is not None else asyncio.Event()
        self.failures: list[Failure] = []
        """Every failure, in order (also those while stopping)."""
        self._log = logger
        self._tasks: dict[str, asyncio.Task[Any]] = {}
        self._forever: set[str] = set()

    @property
    def running(self) -> list[str]:
        """Names of the tasks not yet ended, in start order."""
        return [name for name, task in self._tasks.items() if not task.done()]

    def start(self, name: str, coro: Coroutine[Any, Any, Any], *, forever: bool = False) -> asyncio.Task[Any]:
        """Run ``coro`` as the task ``name``. ``forever``: returning before ``stopping`` is
        set is a failure (``TaskEnded``)."""
        if self.stopping.is_set() or name in self.running:
            coro.close()  # never awaited: close it so that Python does not warn
            why = "the service is stopping" if self.stopping.is_set() else "a task of that name is running"
            raise SupervisorError(f"cannot start the task {name!r}: {why}")
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._tasks[name] = task
        if forever:
            self._forever.add(name)
        else:
            self._forever.discard(name)
        task.add_done_callback(self._ended)
        return task

    def _ended(self, task: asyncio.Task[Any]) -> None:
        name = task.get_name()
        if task.cancelled():
            self._log.debug("task %s cancelled", name)
            return
        error = task.exception()
        if error is None:
            if name not in self._forever or self.stopping.is_set():
                self._log.debug("task %s ended", name)
                return
            error = TaskEnded(f"the {name} task ended on its own; it should run until the service stops")
        stopping = self.stopping.is_set()
        self.failures.append(Failure(name, error, stopping))
        self._log.error("task %s failed%s: %s: %s", name, " while stopping" if stopping else "",
                        type(error).__name__, error, exc_info=(type(error), error, error.__traceback__))
        if stopping:
            return
        try:
            self.on_failure(name, error)
        except Exception:  # the handler's own bug must not hide the next failure
            self._log.exception("the failure handler raised for task %s", name)

    async def stop(self, grace_s: float, cancel_wait_s: float = 1.0) -> StopReport:
        """Set ``stopping``, give the tasks ``grace_s`` to end, cancel the rest and give
        them ``cancel_wait_s``; returns within about ``grace_s + cancel_wait_s``."""
        self.stopping.set()
        pending = {task for task in self._tasks.values() if not task.done()}
        ended: list[str] = []
        if pending and grace_s > 0:
            done, pending = await asyncio.wait(pending, timeout=grace_s)
            ended = [t.get_name() for t in done]
        for task in pending:
            task.cancel()
        stuck: set[asyncio.Task[Any]] = set()
        if pending:
            _, stuck = await asyncio.wait(pending, timeout=cancel_wait_s)
        for task in stuck:
            self._log.warning("task %s still runs %.1f s after its cancellation: left behind", task.get_name(),
                              cancel_wait_s)
        order = list(self._tasks)
        return StopReport(
            ended=tuple(sorted(ended, key=order.index)),
            cancelled=tuple(sorted((t.get_name() for t in pending - stuck), key=order.index)),
            stuck=tuple(sorted((t.get_name() for t in stuck), key=order.index)),
        )
