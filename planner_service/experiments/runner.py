"""Fan jobs out to worker processes, with a progress bar, and keep every result.

``spawn`` workers (a clean interpreter each, nothing inherited from the parent's numba or
matplotlib state) that each warm up once (``jobs.warm_up``) before their first timed
sortie. Results are cached by job, so experiments run together (``all``) fly each shared
sortie once.
"""

from __future__ import annotations

import multiprocessing
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, Callable, Iterable

from .errors import ExperimentError
from .jobs import Record, run_job, warm_up
from .progress import Progress


def run_jobs(jobs: Iterable[Any], workers: int, cache: dict[Any, Record] | None = None,
             progress: Progress | None = None, run: Callable[[Any], Record] = run_job,
             warm: Callable[[], None] = warm_up) -> dict[Any, Record]:
    """Run every job not yet in ``cache`` and return the cache (job -> record).

    A job is a ``Job`` flown by ``run_job`` unless ``run`` says otherwise (the fleet's jobs:
    any hashable, picklable value with ``describe()`` and ``cost_estimate_s()``, and a
    top-level ``run`` so that it pickles to a worker); ``warm`` runs once per worker.

    ``workers`` <= 1 runs in this process (no pool); otherwise that many processes.
    The longest jobs start first; jobs of equal cost keep their given order, so that
    the runs whose wall times are compared (``mcts-paper`` and ``ts-mcts`` at one n and
    seed) run close together in time, under the same load.
    """
    cache = {} if cache is None else cache
    todo = list(dict.fromkeys(j for j in jobs if j not in cache))
    todo.sort(key=lambda j: -j.cost_estimate_s())
    if progress is not None:
        progress.total = len(todo)
        progress.total_weight = sum(j.cost_estimate_s() for j in todo)
    if not todo:
        return cache
    if workers <= 1:
        warm()
        for job in todo:
            cache[job] = _run(run, job)
            if progress is not None:
                progress.update(weight=job.cost_estimate_s())
        return cache
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=warm) as pool:
        # Keep only a few jobs queued per worker so the order above is the order they run.
        pending: dict = {}
        queue = iter(todo)
        for job in queue:
            pending[pool.submit(_run, run, job)] = job
            if len(pending) >= 2 * workers:
                break
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                job = pending.pop(fut)
                cache[job] = fut.result()
                if progress is not None:
                    progress.update(weight=job.cost_estimate_s())
                nxt = next(queue, None)
                if nxt is not None:
                    pending[pool.submit(_run, run, nxt)] = nxt
    return cache


def _run(run: Callable[[Any], Record], job: Any) -> Record:
    try:
        return run(job)
    except Exception as err:  # name the sortie that failed; the pool would only say "error"
        raise ExperimentError(f"{job.describe()}: {type(err).__name__}: {err}") from err


__all__ = ["run_jobs"]
