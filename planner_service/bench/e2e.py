"""End-to-end latency on loopback: a task request submitted over zenoh until the mission
that includes it is accepted by the vehicle stub (MISSION_ACK), seen by the client as the
service's ``mission_uploaded`` event. The planner's own time (reported in that event) is
subtracted, so the figure is what the I/O path costs: zenoh query, validation, the SQLite
journal (synchronous FULL), the hand-over to the planner thread and back, mission encoding
and validation, the MAVLink upload handshake, the event publication.

Real processes: ``sim_bridge vehicle`` (udpin) and ``planner_service serve`` with
``planner.replan_min_interval_s = 0`` (every request re-plans) and the vehicle on the
ground (``start_mission`` off), so every request produces one upload."""

from __future__ import annotations

import http.cookiejar
import secrets
import shutil
import socket
import statistics
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any, Callable

from protocol import Event
from protocol.client import PlannerClient

from ..service.config import build_config, to_toml
from ..harness.processes import Child, ProgramChild, free_port, start_vehicle_and_service


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    k = min(len(ordered) - 1, max(0, int(round(q / 100.0 * (len(ordered) - 1)))))
    return ordered[k]


def run_e2e(requests: int = 200, budget_ms: float = 20.0, users: int = 10,
            progress: Callable[[str], None] | None = None, page: bool = False) -> dict[str, Any]:
    """The figures of ``requests`` requests; with ``page`` the live map (``operator web``, its
    own process) is open on the service in a headless Chromium (or, without one, read by a
    stream reader) while they are timed."""
    with tempfile.TemporaryDirectory(prefix="uav-e2e-") as tmp:
        return _run(Path(tmp), requests, budget_ms, users, progress or (lambda _: None), page)


def run_e2e_with_page(requests: int = 200, budget_ms: float = 20.0, rounds: int = 8,
                      progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """``bench --e2e --web``: the same figures without and with the live map open, in
    alternating rounds (without, with, without, ...) of ``requests / (2 rounds)`` each, in
    one run: the machine's drift falls on both alike. The ratio is with / without."""
    say = progress or (lambda _: None)
    per = max(requests // (2 * rounds), 1)
    without: list[dict[str, Any]] = []
    with_page: list[dict[str, Any]] = []
    for r in range(rounds):
        say(f"e2e --web: round {r + 1}/{rounds} without the page")
        without.append(run_e2e(per, budget_ms, progress=progress))
        say(f"e2e --web: round {r + 1}/{rounds} with the page open")
        with_page.append(run_e2e(per, budget_ms, progress=progress, page=True))
    a, b = _pool(without), _pool(with_page)
    return {"requests_each": per * rounds, "rounds": rounds, "budget_ms": budget_ms, "without": a, "with_page": b,
            "page": with_page[0]["page"],
            "p99_ratio": b["e2e_ms_p99"] / a["e2e_ms_p99"], "median_ratio": b["e2e_ms_median"] / a["e2e_ms_median"]}


def _pool(runs: list[dict[str, Any]]) -> dict[str, Any]:
    e2e = [x for r in runs for x in r["e2e_samples"]]
    ack = [x for r in runs for x in r["ack_samples"]]
    return {"e2e_ms_median": statistics.median(e2e), "e2e_ms_p99": percentile(e2e, 99), "e2e_ms_max": max(e2e),
            "ack_ms_median": statistics.median(ack), "ack_ms_p99": percentile(ack, 99)}


def _run(tmp: Path, requests: int, budget_ms: float, users: int, progress: Callable[[str], None],
         page: bool = False) -> dict[str, Any]:
    mav_port, zenoh_port = free_port(socket.SOCK_DGRAM), free_port()
    endpoint = f"tcp/127.0.0.1:{zenoh_port}"
    config = build_config({}, {"zenoh.listen": endpoint, "mavlink.url": f"udpout:127.0.0.1:{mav_port}",
                               "planner.budget_ms": str(budget_ms), "planner.replan_min_interval_s": "0",
                               "journal.path": str(tmp / "journal.sqlite")})
    (tmp / "planner.toml").write_text(to_toml(config))
    children: list[Child] = []
    events: list[tuple[float, Event]] = []
    cond = threading.Condition()

    def on_event(ev: Event) -> None:
        if ev.event == "mission_uploaded":
            with cond:
                events.append((time.perf_counter(), ev))
                cond.notify_all()

    try:
        # A position from the start: the bench times requests to missions, not the
        # autopilot's start-up (docs/VEHICLE.md, --gps-delay-s).
        start_vehicle_and_service(tmp, ["--mavlink", f"udpin:127.0.0.1:{mav_port}", "--gps-delay-s", "0"], children)
        with PlannerClient([endpoint], config.keys()) as client:
            if not client.wait_for_service(20.0):
                raise RuntimeError("the service never appeared")
            client.follow_events(on_event)
            shown = open_page(tmp, endpoint, children) if page else "none"
            time.sleep(1.0)  # the vehicle link and the planner's warm-up
            e2e_ms, ack_ms, planner_ms, total_ms = [], [], [], []
            warm = 5
            for i in range(requests + warm):
                x, y = 50.0 + (37.0 * i) % 400.0, 50.0 + (53.0 * i) % 400.0
                t0 = time.perf_counter()
                ack = client.submit(f"user-{i % users}", x, y, 5 + i % 10)
                t_ack = time.perf_counter()
                found = _wait_for(cond, events, ack.request_id, 10.0)
                if found is None:
                    raise RuntimeError(f"no mission for request {ack.request_id}; see {tmp}/service.log")
                t1, ev = found
                plan = float(ev.detail.split("planner_ms=")[1].split()[0])
                if i >= warm:
                    ack_ms.append((t_ack - t0) * 1e3)
                    total_ms.append((t1 - t0) * 1e3)
                    planner_ms.append(plan)
                    e2e_ms.append((t1 - t0) * 1e3 - plan)
                if i % 50 == 0:
                    progress(f"e2e: {i}/{requests + warm} requests")
    finally:
        for child in reversed(children):
            child.stop()
    return {
        "requests": requests, "budget_ms": budget_ms, "page": shown, "e2e_samples": e2e_ms, "ack_samples": ack_ms,
        "e2e_ms_median": statistics.median(e2e_ms), "e2e_ms_p99": percentile(e2e_ms, 99),
        "e2e_ms_max": max(e2e_ms),
        "ack_ms_median": statistics.median(ack_ms), "ack_ms_p99": percentile(ack_ms, 99),
        "planner_ms_median": statistics.median(planner_ms),
        "total_ms_median": statistics.median(total_ms), "total_ms_p99": percentile(total_ms, 99),
    }


PAGE_SETTLE_S = 3.0
"""After the page opened its stream: its first drawing and Chromium's start-up work end."""


def open_page(tmp: Path, endpoint: str, children: list[Child]) -> str:
    """The live map on the service: ``operator web`` in its own process with the service's
    operator key, and the page open in a headless Chromium (what an operator has open);
    without Chromium, a reader of the page's event stream. Returns which."""
    port = free_port()
    token = tmp / "web.token"
    token.write_text(secrets.token_urlsafe(16))
    token.chmod(0o600)
    web = Child("planner_service", ["operator", "web", "--connect", endpoint, "--listen", f"127.0.0.1:{port}",
                                    "--token-file", str(token), "--operator-key", str(tmp / "operator.key")],
                tmp / "web.log")
    children.append(web)
    url = f"http://127.0.0.1:{port}/"
    deadline = time.monotonic() + 30.0
    while not _answers(url):
        if time.monotonic() > deadline or web.proc.poll() is not None:
            raise RuntimeError(f"operator web did not serve {url}: {web.log()[-800:]}")
        time.sleep(0.1)
    login = f"{url}login?token={token.read_text()}"
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is not None:
        profile = tmp / "chromium"
        children.append(ProgramChild([browser, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
                                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                                 f"--user-data-dir={profile}", "--remote-debugging-port=0", login], tmp / "chromium.log"))
        # timed once the page is open and drawn: a browser starting up is not what an open page costs
        web.wait_ready("a page follows the picture", 60.0)
        time.sleep(PAGE_SETTLE_S)
        return "chromium"
    reader = threading.Thread(target=_read_stream, args=(login,), daemon=True)
    reader.start()
    return "stream reader"


def _answers(url: str) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=1.0):
            return True
    except OSError:
        return False


def _read_stream(login: str) -> None:
    """The page's traffic without a browser: log in, then read the event stream until the end."""
    opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))
    try:
        opener.open(login, timeout=5.0).read()
        with opener.open(login.split("login?")[0] + "api/stream", timeout=30.0) as stream:
            while stream.readline():
                pass
    except OSError:
        pass  # the server stopped: the bench is over


def _wait_for(cond: threading.Condition, events: list[tuple[float, Event]], request_id: int,
              timeout_s: float) -> tuple[float, Event] | None:
    deadline = time.monotonic() + timeout_s
    with cond:
        while True:
            for t, ev in events:
                newest = int(ev.detail.split("newest_request=")[1].split(";")[0].split()[0])
                if newest >= request_id:
                    return t, ev
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            cond.wait(left)


def format_e2e_with_page(r: dict[str, Any]) -> str:
    a, b = r["without"], r["with_page"]
    return (f"end-to-end on loopback without and with the live map open ({r['page']}), {r['requests_each']} requests "
            f"each in {r['rounds']} alternating rounds, planner budget {r['budget_ms']:g} ms excluded:\n"
            f"  without the page: median {a['e2e_ms_median']:.1f} ms, p99 {a['e2e_ms_p99']:.1f} ms, "
            f"max {a['e2e_ms_max']:.1f} ms\n"
            f"  with the page:    median {b['e2e_ms_median']:.1f} ms, p99 {b['e2e_ms_p99']:.1f} ms, "
            f"max {b['e2e_ms_max']:.1f} ms\n"
            f"  with / without:   median x{r['median_ratio']:.2f}, p99 x{r['p99_ratio']:.2f}")


def format_e2e(r: dict[str, Any]) -> str:
    return (f"end-to-end on loopback ({r['requests']} requests, planner budget {r['budget_ms']:g} ms excluded):\n"
            f"  request -> mission accepted by the stub: median {r['e2e_ms_median']:.1f} ms, "
            f"p99 {r['e2e_ms_p99']:.1f} ms, max {r['e2e_ms_max']:.1f} ms\n"
            f"  request -> ack:                          median {r['ack_ms_median']:.1f} ms, p99 {r['ack_ms_p99']:.1f} ms\n"
            f"  planner (excluded):                      median {r['planner_ms_median']:.1f} ms; "
            f"total median {r['total_ms_median']:.1f} ms, p99 {r['total_ms_p99']:.1f} ms")
