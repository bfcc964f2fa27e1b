"""The simulated users as a pure walk with explicit generators (``sim_bridge/users.py``): the
task laws (backlog: arrivals added and capped, served taken off; redraw: the paper's draw
every interval), when a user speaks, what it learns from acks and ``user_place``; then a
whole walk against the real intake and journal (no zenoh), whose counts must agree."""

from __future__ import annotations

import argparse
import re
import threading
import time
from pathlib import Path

import msgspec
import numpy as np
import pytest

from planner_service.model import field, pack, preset
from planner_service.model.mobility import draw_arrivals, draw_tasks, move_users
from planner_service.service.intake import Accepted, Intake, fairness_rule
from planner_service.service.journal import Journal
from protocol import Area, TaskAck, UserPlace, encode
from protocol.client import ClientError
from sim_bridge.users import (TaskParams, WalkParams, Walker, advance_users, arrive, learn_served, new_walkers, on_ack,
                              model_pace, on_place, on_refused, request_of, sent, step, run_users, user_streams, wants_to_send)

SCENARIO = field()
P = pack(SCENARIO)
BUSY = pack(SCENARIO.replace(task_arrival_mean=6.0))
"""Arrivals that keep the users' backlogs busy (about 6 tasks an interval each)."""
WALK = WalkParams(SCENARIO.area_side_m)


def walker() -> Walker:
    return Walker("u", np.array([10.0, 10.0]), np.array([400.0, 10.0]), 1.0, next_draw_s=0.0)


def draws(seed: int, n: int, p: np.ndarray, law: str = "backlog") -> list[int]:
    """The model's first ``n`` draws from ``seed``, one a call, as ``arrive`` makes them:
    ``backlog``, the first backlog (``draw_tasks``) then the arrivals (``draw_arrivals``);
    ``redraw``, ``draw_tasks`` every time."""
    rng, one, out = np.random.default_rng(seed), np.zeros(1, dtype=np.int64), []
    for k in range(n):
        (draw_arrivals if k and law == "backlog" else draw_tasks)(p, one, rng)
        out.append(int(one[0]))
    return out


def test_backlog_law_a_first_draw_then_the_arrivals_capped() -> None:
    busy = pack(preset("field").replace(task_arrival_mean=6.0))  # arrivals that fill the buffer soon
    tp = TaskParams(interval_s=40.0, backlog_max=25)
    w, rng = walker(), np.random.default_rng(7)
    expected, backlog, lost = [], 0, 0
    for d in draws(7, 6, busy):
        kept = min(d, 25 - backlog)
        backlog, lost = backlog + kept, lost + d - kept
        expected.append(backlog)
    seen = []
    for k in range(6):
        arrive(w, 40.0 * k + 39.0, busy, tp, rng)  # one draw per interval, at its start
        seen.append(w.backlog)
    assert seen == expected and w.lost == lost and w.arrived == backlog
    assert w.backlog == 25 and lost > 0  # a first backlog of about 10 and 6 a interval fill 25
    arrive(w, 239.0, busy, tp, rng)  # nothing more is due
    assert w.backlog == 25


def test_redraw_law_replaces_the_count_and_sends_it_once_an_interval() -> None:
    tp = TaskParams(interval_s=40.0, law="redraw")
    w, rng = walker(), np.random.default_rng(3)
    expected = draws(3, 3, P, "redraw")
    for k in range(3):
        arrive(w, 40.0 * k, P, tp, rng)
        assert w.backlog == expected[k] and wants_to_send(w, 40.0 * k, tp)
        sent(w, 40.0 * k)
        learn_served(w, 1, 5 * (k + 1))  # services do not change a redraw
        assert not wants_to_send(w, 40.0 * k + 1.0, tp)
    assert [b for _, b in w.history] == expected


def test_when_a_user_speaks() -> None:
    tp = TaskParams(interval_s=40.0, resend_m=50.0, retry_s=40.0)
    w = walker()
    assert not wants_to_send(w, 0.0, tp)  # nothing to offload, nothing in force
    w.backlog = 12
    assert wants_to_send(w, 0.0, tp)
    on_ack(w, TaskAck(request_id=1, user_id="u", sortie=1, served_tasks=0), request_of(w, 0.0, tp, WALK))
    assert not wants_to_send(w, 39.0, tp)  # the service counts what it has
    w.backlog = 15  # new tasks
    assert wants_to_send(w, 1.0, tp)
    on_ack(w, TaskAck(request_id=2, user_id="u", sortie=1, served_tasks=0), request_of(w, 1.0, tp, WALK))
    step(w, 30.0, WALK, np.random.default_rng(0))  # 30 m at 1 m/s: not far enough
    assert not wants_to_send(w, 31.0, tp)
    step(w, 25.0, WALK, np.random.default_rng(0))
    assert wants_to_send(w, 56.0, tp)  # moved 55 m
    on_ack(w, TaskAck(request_id=3, user_id="u", sortie=1, served_tasks=0), request_of(w, 56.0, tp, WALK))
    assert not wants_to_send(w, 95.0, tp) and wants_to_send(w, 96.0, tp)  # at least once an interval
    on_refused(w, 96.0, tp, "service: busy: ...")
    assert not wants_to_send(w, 135.0, tp) and wants_to_send(w, 136.0, tp)


def test_what_a_user_learns_of_its_services() -> None:
    tp = TaskParams()
    w = walker()
    w.backlog = 20
    first = request_of(w, 0.0, tp, WALK)
    assert first.served_seen is msgspec.UNSET and b"served_seen" not in encode(first)  # it knows no sortie yet
    on_ack(w, TaskAck(request_id=4, user_id="u", sortie=2, served_tasks=8), first)
    assert (w.backlog, w.served, w.sortie, w.view) == (20, 0, 2, 20)  # the first news is the baseline
    # the service served 12 of request 4 and published the place: backlog 8 left, as ours
    on_place(w, UserPlace(user_id="u", sortie=2, request_id=4, backlog=8, served_tasks=20, services=2))
    assert (w.backlog, w.view, w.served) == (8, 8, 12) and not wants_to_send(w, 1.0, tp)
    # a request that crossed a service on the wire: it says it had taken 20 served off its
    # 18; the ack shows 26 served, so the service counted 18 - 6 = 12, as the user does now
    w.backlog += 10
    crossed = request_of(w, 2.0, tp, WALK)
    assert (crossed.tasks, crossed.served_seen, crossed.sortie) == (18, 20, 2)
    on_ack(w, TaskAck(request_id=5, user_id="u", sortie=2, served_tasks=26), crossed)
    assert (w.backlog, w.view, w.served) == (12, 12, 18) and not wants_to_send(w, 2.1, tp)
    # an ack without the counts (an older service's): its count is what was sent; if the
    # user then learns of a service the request crossed, the counts differ: it sends again
    w.backlog += 2
    old = request_of(w, 2.2, tp, WALK)
    on_ack(w, TaskAck(request_id=6, user_id="u"), old)
    assert (w.backlog, w.view) == (14, 14) and not wants_to_send(w, 2.3, tp)
    on_place(w, UserPlace(user_id="u", sortie=2, request_id=6, backlog=14, served_tasks=28))
    assert (w.backlog, w.view) == (12, 14) and wants_to_send(w, 2.4, tp)
    on_ack(w, TaskAck(request_id=7, user_id="u", sortie=2, served_tasks=28), request_of(w, 2.4, tp, WALK))
    assert (w.backlog, w.view) == (12, 12) and not wants_to_send(w, 2.5, tp)
    # stale news changes nothing: an older place, an earlier sortie, a smaller count
    on_place(w, UserPlace(user_id="u", sortie=2, request_id=6, backlog=1, served_tasks=26))
    learn_served(w, 1, 99)
    learn_served(w, 2, 20)
    assert (w.backlog, w.view, w.served) == (12, 12, 20)
    # everything served: the service's count is 0 too, nothing to say
    on_place(w, UserPlace(user_id="u", sortie=2, request_id=7, backlog=0, served_tasks=40))
    assert (w.backlog, w.view) == (0, 0) and not wants_to_send(w, 100.0, tp)
    # a new sortie counts from zero; nothing of ours is in force in it
    on_place(w, UserPlace(user_id="u", sortie=3, request_id=None, served_tasks=0))
    assert (w.sortie, w.served_seen, w.view) == (3, 0, None)


def test_a_user_whose_backlog_is_all_served_during_its_request_says_it_is_done() -> None:
    w = walker()
    w.backlog = 6
    on_ack(w, TaskAck(request_id=1, user_id="u", sortie=1, served_tasks=0), request_of(w, 0.0, TaskParams(), WALK))
    w.backlog = 0  # it uploaded everything itself (a real user knows)
    assert wants_to_send(w, 1.0, TaskParams())  # tasks 0: nothing more, the wait ends


def test_a_whole_walk_against_the_intake_and_journal_keeps_the_counts_right(tmp_path: Path) -> None:
    """Ten users for 60 intervals against the real intake: a stand-in for the vehicle serves
    a pending user now and then (part of its backlog, bound to its request in force) and
    publishes the places now and then. A user's backlog is its arrivals less what it learnt
    was served; the service's count of it is the truth (arrivals less everything served)
    whenever the user has nothing more to say; users learn nearly every service."""
    journal = Journal(tmp_path / "j.sqlite", now_s=0.0)
    clock = {"t": 0.0}
    intake = Intake(journal, Area(SCENARIO.area_side_m, 120.0, 10.0), lambda: clock["t"], monotonic=lambda: clock["t"],
                    unservable=fairness_rule(SCENARIO))
    tp = TaskParams(interval_s=40.0, backlog_max=SCENARIO.task_max)
    rng, serve_rng = np.random.default_rng(11), np.random.default_rng(12)
    walkers = new_walkers(10, SCENARIO, WALK, rng, 10.0)
    served_total = dict.fromkeys((w.user_id for w in walkers), 0)
    crossed = 0
    for tick in range(1, 60 * 8 + 1):
        now = tick * 5.0
        clock["t"] = now
        for w in walkers:
            step(w, 5.0, WALK, rng)
            arrive(w, now, BUSY, tp, rng)
            if wants_to_send(w, now, tp):
                request = request_of(w, now, tp, WALK)  # what the simulated user sends
                x, y = request.x_m, request.y_m
                out = intake.handle(encode(request))
                assert isinstance(out, Accepted), out
                seen = request.seen_in(1)
                crossed += seen is not None and out.reply.served_tasks is not None and out.reply.served_tasks > seen
                on_ack(w, out.reply, request)
        # A user's backlog is its arrivals less what it learnt was served; what it has not
        # learnt yet is all that separates it from the truth. Unless it is about to send
        # again (new tasks, or a service it learnt of since), the service counts the truth,
        # even after a request that crossed a service (``served_seen``).
        counts = {b.user_id: b.backlog for b in journal.user_backlogs()}
        for w in walkers:
            truth = w.arrived - served_total[w.user_id]
            assert w.backlog == w.arrived - w.served and w.backlog - truth == served_total[w.user_id] - w.served
            if w.view is not None and not wants_to_send(w, now, tp):
                assert counts.get(w.user_id, 0) == truth, (tick, w.user_id, counts.get(w.user_id), truth)
        if tick % 4 == 0:  # a hold ends: serve part of a pending user's backlog
            pending = journal.pending()
            if pending:
                row = pending[int(serve_rng.integers(len(pending)))]
                bound = journal.request_in_force(row.user_id, now)
                assert bound is not None and bound.request_id == row.request_id
                n = int(serve_rng.integers(1, bound.backlog + 1))
                journal.record_service(bound.request_id, 0, (x, y, 100.0), n, n * 1e5, 0.1, 9e4, now)
                served_total[row.user_id] += n
                if tick % 8 == 0:  # a re-plan publishes the places
                    for b in journal.user_backlogs():
                        on_place(next(w for w in walkers if w.user_id == b.user_id), UserPlace(
                            user_id=b.user_id, sortie=1, request_id=b.request_id, backlog=b.backlog,
                            served_tasks=b.served_tasks, services=b.services))
    assert sum(served_total.values()) > 100 and sum(w.arrived for w in walkers) > 1000
    for w in walkers:  # each learnt what was served, up to the last service after its last ack
        assert w.served <= served_total[w.user_id]
        assert w.served_seen == w.served
    learnt = sum(w.served for w in walkers)
    print(f"\n{sum(w.submitted for w in walkers)} requests ({crossed} crossed a service they had not heard of), "
          f"{learnt} of {sum(served_total.values())} served tasks learnt")
    assert learnt >= 0.9 * sum(served_total.values())
    assert crossed > 0  # the race this walk is about happened, and was counted right


@pytest.mark.parametrize("law", ["backlog", "redraw"])
def test_the_same_seed_walks_the_same(law: str) -> None:
    def run(seed: int) -> list[tuple[float, int]]:
        tp = TaskParams(law=law)  # type: ignore[arg-type]
        rng = np.random.default_rng(seed)
        ws = new_walkers(3, SCENARIO, WALK, rng, 5.0)
        for k in range(200):
            for w in ws:
                step(w, 1.0, WALK, rng)
                arrive(w, float(k), P, tp, rng)
                if wants_to_send(w, float(k), tp):
                    on_ack(w, TaskAck(request_id=k + 1, user_id=w.user_id, sortie=1, served_tasks=0),
                           request_of(w, float(k), tp, WALK))
        return [h for w in ws for h in w.history]
    assert run(5) == run(5) and run(5) != run(6)


def test_one_seed_gives_the_same_users_whatever_the_ticks_and_the_services() -> None:
    """``run_users``'s walk: each user's position and task draws at a simulated time depend
    on the seed and that time only. Cut into regular ticks, or into ragged ones with a
    service to user 0 on the way, the users are the same (user 0's backlog aside); so two
    flights of one seed meet the same users whatever their planners did."""
    tp = TaskParams(interval_s=40.0)
    checkpoints = [50.0 * k for k in range(1, 9)]

    def walk(ticks: np.random.Generator | None, serve_at: float | None) -> list[list[tuple]]:
        setup, streams = user_streams(5, 4)
        ws = new_walkers(4, SCENARIO, WALK, setup, 10.0)
        now, seen = 0.0, []
        for mark in checkpoints:
            while now < mark:
                dt = 1.0 if ticks is None else float(ticks.uniform(0.01, 7.0))
                dt = min(dt, mark - now)
                now += dt
                advance_users(ws, streams, dt, now, WALK, BUSY, tp)
                if serve_at is not None and now >= serve_at:
                    ws[0].backlog, serve_at = 0, None  # a service takes user 0's whole backlog
            seen.append([(*w.xy, w.draws, w.arrived + w.lost, w.backlog) for w in ws])
        return seen

    regular, ragged = walk(None, None), walk(np.random.default_rng(1), 120.0)
    for at_regular, at_ragged in zip(regular, ragged):
        for user, (a, b) in enumerate(zip(at_regular, at_ragged)):
            assert np.allclose(a[:2], b[:2], atol=1e-6) and a[2:4] == b[2:4], (user, a, b)
            assert user == 0 or a[4] == b[4], (user, a, b)
    assert regular[2][0][4] != ragged[2][0][4]  # at 150 s, the service had changed user 0's backlog
    other = user_streams(6, 4)[1][0][0].uniform(0.0, 1.0)
    assert other != user_streams(5, 4)[1][0][0].uniform(0.0, 1.0)  # another seed, other users


def test_users_at_the_model_pace_move_an_interval_as_far_as_the_model_moves_them() -> None:
    """``model_pace``: over an interval a walking user goes, on average, as far as the
    model's own move (``mobility.move_users``) takes a user in one."""
    interval = 55.0
    walk = WalkParams(SCENARIO.area_side_m, *model_pace(SCENARIO, interval))
    setup, streams = user_streams(3, 50)
    ws = new_walkers(50, SCENARIO, walk, setup)
    walked = []
    for _ in range(40):
        before = [w.xy.copy() for w in ws]
        for w, (rng, _tasks) in zip(ws, streams):
            step(w, interval, walk, rng)
        walked += [float(np.hypot(*(w.xy - b))) for w, b in zip(ws, before)]
    users = np.zeros((2000, 3))
    users[:, :2] = SCENARIO.area_side_m / 2
    moved = users.copy()
    move_users(P, moved, np.random.default_rng(4))
    model = float(np.hypot(*(moved - users)[:, :2].T).mean())
    assert model == pytest.approx(8.1, abs=0.3)  # epsilon = 10 m: uniform whole-metre moves on each axis
    assert np.mean(walked) == pytest.approx(model, rel=0.1)


@pytest.mark.parametrize("text, why", [("0.1,0.2", None), ("0.2,0.2", None), ("0.2,0.1", "'0.2,0.1': LO is above HI"),
                                       ("0,1", "0 is not positive"), ("1", "'1' is not LO,HI"),
                                       ("a,b", "'a' is not a number"), ("nan,1", "'nan' is not a finite number"),
                                       ("1,inf", "'inf' is not a finite number")])
def test_walk_speeds_are_checked_as_parsed(text: str, why: str | None) -> None:
    from sim_bridge.commands.users import walk_speeds

    if why is None:
        assert walk_speeds(text) == tuple(float(v) for v in text.split(","))
    else:
        with pytest.raises(argparse.ArgumentTypeError, match=re.escape(why)):  # the message names the value
            walk_speeds(text)


def test_a_stop_asked_while_the_users_process_finishes_never_kills_it(python_env: dict[str, str], python: str) -> None:
    # test_sortie_px4's whole MAVSDK sortie: the users stopped by themselves (the sortie was
    # over) and the harness's SIGINT came while the interpreter finalised: exit status -2.
    import signal
    import subprocess
    import time

    from planner_service.harness.processes import free_port

    endpoint = f"tcp/127.0.0.1:{free_port()}"  # nobody there: the users wait until stopped
    for _ in range(3):
        proc = subprocess.Popen([python, "-m", "sim_bridge", "users", "--count", "1", "--connect", endpoint],
                                env=python_env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        assert proc.stderr is not None
        # "1 users waiting for the service": its handlers are installed. Not any first line: a
        # line written before them (a library's warning at import) would let the SIGINT meet
        # Python's default handler (once on CI: -2 with a traceback)
        said = [proc.stderr.readline().decode(errors="replace")]
        while said[-1] and "users waiting for the service" not in said[-1]:
            said.append(proc.stderr.readline().decode(errors="replace"))
        assert said[-1], f"the users exited before waiting: {said}"
        deadline = time.monotonic() + 30.0
        while proc.poll() is None and time.monotonic() < deadline:
            proc.send_signal(signal.SIGINT)  # the first stops it; the rest land while it exits
            time.sleep(0.002)
        code = proc.wait(5.0)
        assert code == 0, (code, said, proc.stderr.read().decode(errors="replace")[-3000:])


class SlowService:
    """A service a slow radio away: each request takes ``answer_s`` to be refused; a stop is
    asked during the first."""

    def __init__(self, stop: threading.Event, answer_s: float) -> None:
        self.stop, self.answer_s, self.asked = stop, answer_s, 0

    def follow_places(self, _callback: object) -> None:
        pass

    def submit_request(self, request: object) -> None:
        self.asked += 1
        self.stop.set()
        time.sleep(self.answer_s)
        raise ClientError("service", "busy")


def test_users_stop_within_one_request_when_each_request_takes_a_slow_round_trip() -> None:
    """Over emulated radios (bench --fleet --scale, 100 ms each way) 20 users' requests in one
    round took longer than the 10 s a stop waits: the users went on submitting after the stop,
    one after another, and were killed. A stop ends the round at the request under way."""
    stop = threading.Event()
    service = SlowService(stop, answer_s=0.5)
    started = time.monotonic()
    run_users(service, SCENARIO, 20, TaskParams(interval_s=1.0, backlog_max=SCENARIO.task_max), 10.0, 1, stop)  # type: ignore[arg-type]
    assert service.asked == 1 and time.monotonic() - started < 5.0, service.asked
