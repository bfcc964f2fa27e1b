"""The supervisor of the service's background tasks, in milliseconds: a task that raises is
reported once with its traceback logged, while the others run on; a loop meant to run for
the service's life that returns is a failure; cancellation is not; the stop is bounded even
for a task that ignores its cancellation."""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Any

import pytest

from planner_service.service.supervisor import StopReport, Supervisor, SupervisorError, TaskEnded


def run(coro: Any) -> Any:
    return asyncio.run(asyncio.wait_for(coro, 5.0))


class Recorder:
    def __init__(self) -> None:
        self.calls: list[tuple[str, BaseException]] = []

    def __call__(self, name: str, exc: BaseException) -> None:
        self.calls.append((name, exc))


async def tick(stopping: asyncio.Event, counter: list[int]) -> None:
    while not stopping.is_set():
        counter[0] += 1
        await asyncio.sleep(0.001)


async def fail_after(delay_s: float, error: BaseException) -> None:
    await asyncio.sleep(delay_s)
    raise error


def test_a_task_that_raises_is_reported_once_with_its_traceback(caplog: pytest.LogCaptureFixture) -> None:
    failures = Recorder()
    error = OSError(28, "No space left on device")

    async def scenario() -> tuple[int, StopReport]:
        sup = Supervisor(failures)
        counter = [0]
        sup.start("status", tick(sup.stopping, counter), forever=True)
        sup.start("planning", fail_after(0.005, error), forever=True)
        await asyncio.sleep(0.03)
        assert sup.running == ["status"]  # the others run on
        seen = counter[0]
        await asyncio.sleep(0.01)
        assert counter[0] > seen
        return counter[0], await sup.stop(grace_s=0.1)

    with caplog.at_level(logging.ERROR, logger="planner_service.supervisor"):
        t0 = time.perf_counter()
        _, report = run(scenario())
        elapsed = time.perf_counter() - t0
    assert failures.calls == [("planning", error)]
    assert report == StopReport(ended=("status",), cancelled=(), stuck=())
    [record] = [r for r in caplog.records if r.levelno == logging.ERROR]
    assert "task planning failed: OSError: [Errno 28] No space left on device" in record.getMessage()
    assert record.exc_info is not None and record.exc_info[1] is error
    assert "fail_after" in caplog.text  # the traceback names the coroutine that raised
    assert elapsed < 2.0


def test_a_loop_that_returns_on_its_own_is_a_failure_a_one_shot_is_not() -> None:
    failures = Recorder()

    async def scenario() -> None:
        sup = Supervisor(failures)
        sup.start("warm-up", asyncio.sleep(0.001))  # a one-shot task: done is done
        sup.start("status", asyncio.sleep(0.002), forever=True)
        await asyncio.sleep(0.02)
        await sup.stop(grace_s=0.01)

    run(scenario())
    assert [name for name, _ in failures.calls] == ["status"]
    assert isinstance(failures.calls[0][1], TaskEnded)
    assert "the status task ended on its own" in str(failures.calls[0][1])


def test_cancellation_is_not_a_failure() -> None:
    failures = Recorder()

    async def scenario() -> StopReport:
        sup = Supervisor(failures)
        task = sup.start("connect", asyncio.sleep(10), forever=True)
        await asyncio.sleep(0.001)
        task.cancel()  # cancelled from outside
        sup.start("planning", asyncio.sleep(10), forever=True)
        await asyncio.sleep(0.005)
        return await sup.stop(grace_s=0.005)  # cancelled by the stop

    report = run(scenario())
    assert failures.calls == []
    assert report.cancelled == ("planning",)


def test_the_stop_is_bounded_even_for_a_task_that_ignores_cancellation() -> None:
    failures = Recorder()

    async def stubborn(release: asyncio.Event, cancels: list[int]) -> None:
        while True:
            try:
                await release.wait()
                return
            except asyncio.CancelledError:
                cancels[0] += 1  # swallowed: a bug the stop must survive

    async def scenario() -> tuple[StopReport, float, int]:
        sup = Supervisor(failures)
        release, cancels = asyncio.Event(), [0]
        counter = [0]
        sup.start("status", tick(sup.stopping, counter), forever=True)
        sup.start("upload", asyncio.sleep(10))
        sup.start("stubborn", stubborn(release, cancels), forever=True)
        await asyncio.sleep(0.005)
        t0 = time.perf_counter()
        report = await sup.stop(grace_s=0.02, cancel_wait_s=0.02)
        elapsed = time.perf_counter() - t0
        release.set()  # let it go, so that the loop can close
        await asyncio.sleep(0.001)
        return report, elapsed, cancels[0]

    report, elapsed, cancels = run(scenario())
    assert report == StopReport(ended=("status",), cancelled=("upload",), stuck=("stubborn",))
    assert cancels == 1
    assert 0.04 <= elapsed < 1.0  # bounded: grace + cancel wait, not the 10 s sleep or for ever
    assert failures.calls == []  # a task that ends while stopping is not a failure


def test_a_failing_handler_does_not_hide_the_next_failure(caplog: pytest.LogCaptureFixture) -> None:
    seen: list[str] = []

    def handler(name: str, exc: BaseException) -> None:
        seen.append(name)
        raise RuntimeError("the handler's own bug")

    async def scenario() -> None:
        sup = Supervisor(handler)
        sup.start("a", fail_after(0.001, ValueError("a")))
        sup.start("b", fail_after(0.003, KeyError("b")))
        await asyncio.sleep(0.02)
        await sup.stop(0.01)

    with caplog.at_level(logging.ERROR, logger="planner_service.supervisor"):
        run(scenario())
    assert seen == ["a", "b"]
    assert caplog.text.count("the failure handler raised") == 2


def test_failures_while_stopping_are_recorded_not_reported() -> None:
    failures = Recorder()

    async def cleanup_fails() -> None:
        try:
            await asyncio.sleep(10)
        finally:
            raise OSError("close failed")

    async def scenario() -> Supervisor:
        sup = Supervisor(failures)
        sup.start("link", cleanup_fails(), forever=True)
        await asyncio.sleep(0.001)
        await sup.stop(grace_s=0.0)
        return sup

    sup = run(scenario())
    assert failures.calls == []
    assert [(f.name, str(f.error), f.while_stopping) for f in sup.failures] == [("link", "close failed", True)]


def test_the_service_stop_event_is_shared_and_late_starts_are_refused() -> None:
    async def scenario() -> None:
        stopping = asyncio.Event()
        sup = Supervisor(Recorder(), stopping)
        sup.start("status", asyncio.sleep(1), forever=True)
        with pytest.raises(SupervisorError, match="a task of that name is running"):
            sup.start("status", asyncio.sleep(1))
        await sup.stop(0.0, 0.01)
        assert stopping.is_set()
        with pytest.raises(SupervisorError, match="the service is stopping"):
            sup.start("late", asyncio.sleep(1))

    run(scenario())
