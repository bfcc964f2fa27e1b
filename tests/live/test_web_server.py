"""``operator web``'s server over HTTP on loopback (no browser): who may read and command,
and what it serves (the command line's refusals: tests/test_cli_errors.py). A real zenoh session, a real aiohttp
server, urllib as the client."""

from __future__ import annotations

import http.cookiejar
import json
import threading
import urllib.error
import urllib.request
from pathlib import Path
from typing import Any, Iterator

import pytest
import zenoh

from planner_service.harness.processes import free_port
from planner_service.live.feed import LiveFeed
from planner_service.live.picture import FleetPicture
from planner_service.web.server import LiveMapServer, RunningServer
from protocol import GeoOrigin, Status
from protocol.zenoh_config import session_config

@pytest.fixture
def served(tmp_path: Path) -> Iterator[tuple[RunningServer, LiveFeed]]:
    session = zenoh.open(session_config("peer", listen=[f"tcp/127.0.0.1:{free_port()}"]))
    tiles = tmp_path / "tiles"
    (tiles / "17" / "68500").mkdir(parents=True)
    (tiles / "17" / "68500" / "45700.png").write_bytes(b"\x89PNG tile")
    (tmp_path / "secret.png").write_bytes(b"not a tile")
    feed = LiveFeed(session, FleetPicture("uavmec"), threading.Lock(), state_every_s=None)
    feed.start()
    running = RunningServer(LiveMapServer(feed, tiles=tiles)).start()
    try:
        yield running, feed
    finally:
        running.close()
        feed.close()
        session.close()


def fetch(url: str, *, opener: Any = None, data: bytes | None = None,
          headers: dict[str, str] | None = None) -> tuple[int, bytes]:
    request = urllib.request.Request(url, data=data, headers=headers or {})
    try:
        with (opener or urllib.request.build_opener()).open(request, timeout=10) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as err:
        return err.code, err.read()


def logged_in(running: RunningServer) -> Any:
    opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))
    status, _ = fetch(running.login_url, opener=opener)
    assert status == 200  # the 303 to the page, followed
    return opener


def test_nothing_is_read_without_the_login_and_a_wrong_token_logs_nobody_in(
        served: tuple[RunningServer, LiveFeed]) -> None:
    running, _ = served
    for path in ("api/picture", "api/stream", "api/geojson", "tiles/17/68500/45700.png"):
        status, body = fetch(running.url + path)
        assert status == 401 and b"login required" in body, (path, status, body)
    assert fetch(running.url)[0] == 200  # the page itself holds no data
    opener = urllib.request.build_opener(urllib.request.HTTPCookieProcessor(http.cookiejar.CookieJar()))
    assert fetch(running.url + "login?token=wrong", opener=opener)[0] == 401
    assert fetch(running.url + "api/picture", opener=opener)[0] == 401
    status, _ = fetch(running.url + "api/picture", headers={"Authorization": f"Bearer {running.server.token}"})
    assert status == 200


def test_the_picture_stream_and_geojson_after_the_login(served: tuple[RunningServer, LiveFeed]) -> None:
    running, feed = served
    opener = logged_in(running)
    with feed.lock:
        feed.picture.on_status("uav1", Status(vehicle="uav1", x_m=12.0, y_m=34.0, z_m=80.0, position_ok=True), 0.0)
    status, body = fetch(running.url + "api/picture", opener=opener)
    picture = json.loads(body)
    assert status == 200 and [(v["id"], v["x_m"], v["y_m"]) for v in picture["vehicles"]] == [("uav1", 12.0, 34.0)]
    assert picture["tiles"] == {"zoom": 17}
    assert fetch(running.url + "api/geojson", opener=opener)[0] == 409  # no origin: nothing to place on the earth
    feed.picture.origin = GeoOrigin(47.4, 8.5, 400.0)
    status, body = fetch(running.url + "api/geojson", opener=opener)
    assert status == 200 and json.loads(body)["features"][0]["properties"]["id"] == "uav1"
    with opener.open(running.url + "api/stream", timeout=10) as stream:
        assert stream.headers["Content-Type"] == "text/event-stream"
        assert stream.readline() == b"event: picture\n"
        assert json.loads(stream.readline().decode()[len("data: "):])["vehicles"][0]["id"] == "uav1"


def test_a_command_needs_the_login_the_pages_header_and_a_vehicle_id(served: tuple[RunningServer, LiveFeed]) -> None:
    running, _ = served
    post = {"data": b'{"reason": "test"}', "headers": {"Content-Type": "application/json"}}
    assert fetch(running.url + "api/vehicles/uav1/start", **post)[0] == 401  # type: ignore[arg-type]
    opener = logged_in(running)
    status, body = fetch(running.url + "api/vehicles/uav1/start", opener=opener, **post)  # type: ignore[arg-type]
    assert status == 403 and b"X-Requested-With" in body  # what a form on another site could send
    headers = {"Content-Type": "application/json", "X-Requested-With": "uavmec-live-map"}
    status, body = fetch(running.url + "api/vehicles/uav%2A/start", opener=opener, data=b"{}", headers=headers)
    assert status == 400 and b"vehicle" in body
    # no service for uav1: the answer says so (within its timeout), nothing is believed
    status, body = fetch(running.url + "api/vehicles/uav1/hold", opener=opener, data=b"{}", headers=headers)
    assert status == 502 and b"no reply" in body and b"--operator-key" in body


def test_tiles_are_served_from_their_folder_only(served: tuple[RunningServer, LiveFeed]) -> None:
    running, _ = served
    opener = logged_in(running)
    assert fetch(running.url + "tiles/17/68500/45700.png", opener=opener) == (200, b"\x89PNG tile")
    assert fetch(running.url + "tiles/17/68500/1.png", opener=opener)[0] == 404
    for sneaky in ("tiles/../secret.png", "tiles/17/..%2F..%2Fsecret.png", "tiles/17/68500/..%2F..%2F..%2Fsecret.png"):
        assert fetch(running.url + sneaky, opener=opener)[0] == 404, sneaky


def test_a_token_file_others_may_read_or_too_short_is_refused(tmp_path: Path) -> None:
    from planner_service.commands.operator_web import read_token

    token = tmp_path / "token"
    token.write_text("a-token-of-enough-length\n")
    token.chmod(0o644)
    with pytest.raises(ValueError, match="may be read by others"):
        read_token(str(token))
    token.chmod(0o600)
    assert read_token(str(token)) == "a-token-of-enough-length"
    token.write_text("short")
    with pytest.raises(ValueError, match="at least 16"):
        read_token(str(token))
