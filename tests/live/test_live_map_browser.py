"""The live map in a real headless Chromium, over a 3-UAV stub fleet on loopback (three
vehicle stubs and services, two meshed routers, simulated users submitting to the fleet),
served by ``operator web``'s server in this process.

Proves, as the operator sees it: the page reads nothing before its login; each vehicle is
drawn within 5 m of a status it published in the last second; a plan's points in order; a
user at the place it asked from; ``start`` from the page grants the operator's authority
(refused without the login); a forced separation loss shows as an alert. The test's last
screenshot is docs/live-map.png when LIVE_MAP_SCREENSHOT names it."""

from __future__ import annotations

import math
import os
import statistics
import threading
import time
from collections import defaultdict
from pathlib import Path
from typing import Any, Iterator

import pytest
import zenoh

from planner_service.live.feed import LiveFeed
from planner_service.live.picture import FleetPicture
from planner_service.service.fleet.presence import FleetPresence
from planner_service.web.server import LiveMapServer, RunningServer
from protocol import FleetKeys, Plan, Status, decode
from protocol.fleet_signing import FleetSigner, FleetVerifier, load_private_key, read_roster
from protocol.signing import load_key
from protocol.zenoh_config import session_config
from tests.support.browser import SKIP_REASON, chromium, console_errors, executables, wait_for
from tests.support.fleet import member
from tests.support.fleet_stack import FleetStack

pytestmark = [pytest.mark.browser, pytest.mark.timeout(240)]
SPEEDUP = "20"
START = {"mavlink.start_mission": "true", "planner.min_requests": "3"}
PAGE_LAG_S = 3.0
"""How far the page may be behind a vehicle's report: a poll of the roster (0.2 s), a snapshot
at most twice a second, the browser's drawing; nominally under a second, and on a loaded
2-core machine (two test processes, SITLs, Chromium) seen near 2 s once."""


class Heard:
    """Every status and plan the services publish, as a test's own subscriber hears them."""

    def __init__(self, session: Any) -> None:
        self.lock = threading.Lock()
        self.statuses: dict[str, list[tuple[float, Status]]] = defaultdict(list)
        self.plans: dict[str, Plan] = {}
        self.subs = [session.declare_subscriber("uavmec/*/status", self._status),
                     session.declare_subscriber("uavmec/*/plan", self._plan)]

    def _status(self, sample: Any) -> None:
        s = decode(sample.payload.to_bytes(), Status)
        with self.lock:
            self.statuses[s.vehicle].append((time.monotonic(), s))

    def _plan(self, sample: Any) -> None:
        vehicle = str(sample.key_expr).split("/")[1]
        with self.lock:
            self.plans[vehicle] = decode(sample.payload.to_bytes(), Plan)

    def near_time(self, vehicle: str, x: float, y: float, wall_s: float, within_s: float) -> float | None:
        """The least distance from (x, y) of ``vehicle``'s statuses stamped within ``within_s``
        of ``wall_s`` (their own ``time_s``, the service's wall clock)."""
        with self.lock:
            around = [s for _, s in self.statuses[vehicle] if abs(s.time_s - wall_s) <= within_s]
        return min((math.dist((s.x_m, s.y_m), (x, y)) for s in around), default=None)


@pytest.fixture
def browser() -> Iterator[Any]:
    if executables() is None:
        pytest.skip(SKIP_REASON)
    yield from chromium()


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[FleetStack]:
    fleet = FleetStack(tmp_path)
    try:
        yield fleet
    finally:
        fleet.close()


def live_map(stack: FleetStack, session: Any) -> tuple[LiveFeed, RunningServer]:
    keys = {v: load_key(str(uav.folder / "operator.key")) for v, uav in stack.uavs.items()}
    feed = LiveFeed(session, FleetPicture("uavmec"), threading.Lock(), fleet_keys=read_roster(stack.roster),
                    operator_keys=keys)
    feed.start()
    return feed, RunningServer(LiveMapServer(feed)).start()


def drawn(driver: Any, selector: str) -> list[dict[str, Any]]:
    """The page's elements matching ``selector``: their data attributes and classes."""
    return driver.execute_script(
        "return [...document.querySelectorAll(arguments[0])].map(e => ({...e.dataset, cls: e.getAttribute('class')}))",
        selector)


def test_the_operator_watches_and_starts_the_fleet_from_the_browser(stack: FleetStack, browser: Any) -> None:
    stack.uav("uav1", 80.0, SPEEDUP, **{"planner.min_requests": "3"})  # waits for the operator's start
    stack.uav("uav2", 100.0, SPEEDUP, home_east_m=40.0, **START)
    stack.uav("uav3", 120.0, SPEEDUP, home_east_m=80.0, **START)
    session = zenoh.open(session_config("client", connect=stack.endpoints))
    heard = Heard(session)
    feed, server = live_map(stack, session)
    try:
        stack.users("--count", "9", "--speedup", SPEEDUP, "--seed", "3")
        watch_login_start_and_alert(stack, browser, server, heard, session)
    finally:
        server.close()
        feed.close()
        session.close()


def watch_login_start_and_alert(stack: FleetStack, driver: Any, server: RunningServer, heard: Heard,
                                session: Any) -> None:
    # without the login the page reads nothing: the login form, no vehicle, the API refuses
    driver.get(server.url)
    wait_for(lambda: driver.find_element("id", "login").is_displayed(), 10.0, "the login form")
    assert drawn(driver, ".vehicle") == [] and driver.execute_script("return window.livePicture") is None
    refused = driver.execute_script(
        "return fetch('/api/vehicles/uav1/start', {method: 'POST', headers: {'X-Requested-With': 'uavmec-live-map',"
        "'Content-Type': 'application/json'}, body: '{}'}).then(r => r.status)")
    assert refused == 401
    assert stack.uavs["uav1"].service.log().count("operator: start") == 0

    # logged in with the printed address: the token leaves the address bar
    driver.get(server.login_url)
    wait_for(lambda: len(drawn(driver, ".vehicle")) == 3, 30.0, lambda: f"three vehicles drawn: {drawn(driver, '.vehicle')}")
    assert "token" not in driver.current_url

    # start uav1 from its card: the service's authority becomes the operator's
    driver.find_element("css selector", ".vehicle-card[data-vehicle='uav1'] button.start").click()
    card_answer = ".vehicle-card[data-vehicle='uav1'] .answer"
    answer = wait_for(lambda: "pending" not in driver.find_element("css selector", card_answer).get_attribute("class")
                      and driver.find_element("css selector", card_answer).text, 15.0, "the start's answer on the page")
    assert answer.startswith("accepted"), answer
    wait_for(lambda: any(s.authority == "operator" for _, s in heard.statuses["uav1"][-3:]), 10.0,
             "uav1's own status saying the operator's authority")

    # Each vehicle drawn where the picture the page holds puts it, and that where the vehicle
    # reported being (within 5 m of its status of that moment), while they fly; the page's lag
    # behind the reports bounded apart. (Judged on "a status of the last second", a loaded CI
    # machine failed it once: uav2 206 m off at x20, 200 m a second: a picture 2 s behind.)
    wait_for(lambda: all(any(s.armed for _, s in heard.statuses[v][-3:]) for v in ("uav1", "uav2", "uav3")), 60.0,
             "all three flying")
    checked, lags = 0, []
    deadline = time.monotonic() + 60.0
    while checked < 30 and time.monotonic() < deadline:
        time.sleep(0.5)
        page = driver.execute_script(
            "return {drawn: [...document.querySelectorAll('.vehicle')].map(e => ({...e.dataset})),"
            " version: document.body.dataset.version, picture: window.livePicture}")
        if page["picture"] is None or str(page["picture"]["version"]) != page["version"]:
            continue  # a picture received, its drawing not yet done
        now = time.time()
        pictured = {v["id"]: v for v in page["picture"]["vehicles"]}
        for v in page["drawn"]:
            p = pictured[v["vehicle"]]
            assert math.dist((float(v["x"]), float(v["y"])), (p["x_m"], p["y_m"])) < 0.01, (v, p)
            reported = page["picture"]["time_s"] - p["status_age_s"]  # when the status shown arrived
            off = heard.near_time(v["vehicle"], p["x_m"], p["y_m"], reported, 1.0)
            assert off is not None and off <= 5.0, f"{v['vehicle']} drawn {off} m from its statuses of that moment"
            lags.append(now - reported)
            checked += 1
    assert checked >= 30, checked
    print(f"\nthe page behind the vehicles' reports: median {statistics.median(lags):.2f} s, max {max(lags):.2f} s")
    assert max(lags) <= PAGE_LAG_S, lags

    # a plan's points in order, and the users where they asked from
    def plan_shown() -> bool:
        with heard.lock:
            plans = dict(heard.plans)
        for vehicle, plan in plans.items():
            points = sorted(drawn(driver, f".plan-point[data-vehicle='{vehicle}']"), key=lambda p: int(p["order"]))
            if points and [(round(float(p["x"])), round(float(p["y"]))) for p in points] == \
                    [(round(q.x_m), round(q.y_m)) for q in plan.points]:
                return True
        return False
    wait_for(plan_shown, 10.0, "a vehicle's plan drawn point by point in its order")
    picture = driver.execute_script("return window.livePicture")
    placed = [u for u in picture["users"] if u["x_m"] is not None]
    assert placed, f"no user placed: {picture['users']}"
    users = {u["user"]: u for u in drawn(driver, ".user")}
    for u in placed:
        assert (float(users[u["id"]]["x"]), float(users[u["id"]]["y"])) == (u["x_m"], u["y_m"])

    # a forced separation loss: an enrolled member reports itself where uav1 flies
    intruder = Intruder(stack, session, heard)
    try:
        def state() -> str:
            with heard.lock:
                armed = [v for v in ("uav1", "uav2", "uav3") if heard.statuses[v][-1][1].armed]
            separation = driver.execute_script("return window.livePicture && window.livePicture.separation")
            return f"a SEPARATION LOST alert on the page (armed now: {armed}; the page's separation {separation})"
        alert = wait_for(lambda: [a.text for a in driver.find_elements("css selector", "#alerts .alert-error")
                                  if "SEPARATION LOST" in a.text], 15.0, state)
        assert "uav4" in alert[0], alert
        assert driver.find_element("id", "separation").get_attribute("data-state") == "lost"
        shot = os.environ.get("LIVE_MAP_SCREENSHOT")
        if shot:
            driver.save_screenshot(shot)
    finally:
        intruder.close()
    assert not console_errors(driver), console_errors(driver)


class Intruder:
    """uav4 (enrolled) joins in a layer of its own and reports its vehicle armed where uav1 is
    (or another vehicle still armed), every 0.3 s until closed."""

    def __init__(self, stack: FleetStack, session: Any, heard: Heard) -> None:
        signer = FleetSigner("uav4", load_private_key(stack.keys / "uav4.key"))
        self.presence = FleetPresence(FleetKeys("uavmec"), member("uav4", 140.0), signer,
                                      FleetVerifier(read_roster(stack.roster)))
        self.presence.join(session, 1.0)
        self.heard = heard
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._report, daemon=True)
        self.thread.start()

    def _report(self) -> None:
        while not self.stop.wait(0.3):
            with self.heard.lock:  # where a vehicle still flies (on a loaded machine uav1 may have landed)
                lasts = [self.heard.statuses[v][-1][1] for v in ("uav1", "uav2", "uav3") if self.heard.statuses[v]]
            last = next((s for s in lasts if s.armed), lasts[0])
            self.presence.publish_position(Status(vehicle="uav4", time_s=time.time(), phase="flying", armed=True,
                                                  mode="AUTO", x_m=last.x_m, y_m=last.y_m, z_m=last.z_m,
                                                  position_ok=True))

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5.0)
        self.presence.leave()
