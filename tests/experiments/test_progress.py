"""The progress bar, written to a non-terminal stream with a pinned clock."""

from __future__ import annotations

import io

from planner_service.experiments.progress import Progress


def test_a_log_gets_a_line_per_tenth_with_counts_and_times():
    now = [100.0]
    stream = io.StringIO()
    bar = Progress(20, "demo", stream=stream, clock=lambda: now[0], width=10)
    for _ in range(20):
        now[0] += 1.0
        bar.update()
    bar.close()
    lines = stream.getvalue().splitlines()
    assert len(lines) == 11  # deciles 0..10, each once
    assert lines[-1] == "demo [##########] 20/20 100% 0:20"
    assert lines[5] == "demo [#####.....] 10/20  50% 0:10, ~0:10 left"
