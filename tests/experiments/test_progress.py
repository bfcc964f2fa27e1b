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


def test_weights_drive_the_fraction_and_the_time_left():
    now = [0.0]
    stream = io.StringIO()
    bar = Progress(4, "w", stream=stream, clock=lambda: now[0], width=4)
    bar.total_weight = 10.0
    now[0] = 8.0
    bar.update(weight=8.0)  # one long item: 1 of 4 items but 80 % of the work
    assert stream.getvalue().splitlines()[-1] == "w [###.] 1/4  80% 0:08, ~0:02 left"
    for _ in range(3):
        bar.update(weight=0.5)
    assert bar.fraction() == 1.0
