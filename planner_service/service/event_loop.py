"""The service's event loop, run to its end without waiting for threads that may never end.

``asyncio.run`` ends by joining every thread of the loop's default executor
(``shutdown_default_executor``, with no time limit in Python 3.11). The service hands blocking
library calls to that executor (``zenoh.open``, a zenoh.ext join, a MAVSDK command); one
that never returns (a peer that accepted a connection and went silent, a native call waiting
on a dead vehicle) would keep a stopped service alive after its last line, until SIGKILL. A
service that has stopped has closed what it owns: nothing such a thread could still do is
worth the wait. So the loop here is closed as ``asyncio.run`` closes it (tasks cancelled,
async generators finished), less that join: ``loop.close`` shuts the executor down without
waiting.
"""

from __future__ import annotations

import asyncio
from typing import Any, Coroutine, TypeVar

T = TypeVar("T")


def run_to_end(main: Coroutine[Any, Any, T]) -> T:
    """Run ``main`` on a new event loop and close the loop; the executor's threads are not joined."""
    loop = asyncio.new_event_loop()
    try:
        asyncio.set_event_loop(loop)
        return loop.run_until_complete(main)
    finally:
        try:
            _cancel_all(loop)
            loop.run_until_complete(loop.shutdown_asyncgens())
        finally:
            asyncio.set_event_loop(None)
            loop.close()


def _cancel_all(loop: asyncio.AbstractEventLoop) -> None:
    """Cancel the tasks left, as ``asyncio.run`` does, and let them finish."""
    tasks = asyncio.all_tasks(loop)
    for task in tasks:
        task.cancel()
    if tasks:
        loop.run_until_complete(asyncio.gather(*tasks, return_exceptions=True))
