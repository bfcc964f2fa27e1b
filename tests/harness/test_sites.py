"""Sites in network namespaces joined by emulated radio links (planner_service/harness/sites.py,
sim_bridge/wire.py): real TCP between real addresses sees the link's delay, a cut link carries
nothing until restored, and nothing made is left behind. Needs root (skipped, loudly, without)."""

from __future__ import annotations

import json
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pytest

from planner_service.harness.sites import PREFIX, Radio, Sites, can_make_sites

pytestmark = pytest.mark.skipif(can_make_sites() is not None, reason=f"sites: {can_make_sites()}")

ECHO = """
import socket, sys
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind((sys.argv[1], 9000)); s.listen(); print("up", flush=True)
while True:
    c, _ = s.accept()
    while (d := c.recv(100)): c.sendall(d)
    c.close()
"""


def round_trips_ms(address: str, count: int, timeout_s: float = 10.0) -> list[float]:
    conn = socket.create_connection((address, 9000), timeout=timeout_s)
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    out = []
    try:
        for _ in range(count):
            start = time.monotonic()
            conn.sendall(b"x")
            assert conn.recv(10) == b"x"
            out.append((time.monotonic() - start) * 1000)
    finally:
        conn.close()
    return out


def cut_packets(sites: Sites, link: str, timeout_s: float = 10.0) -> int:
    """The packets ``link`` dropped for a cut, toward its site, once the wire's figures
    (written every second) show any."""
    deadline = time.monotonic() + timeout_s
    while True:
        figures = json.loads(sites.stats_path.read_text())["links"][link]
        if figures["b>a"]["cut"] or time.monotonic() > deadline:
            return int(figures["b>a"]["cut"])
        time.sleep(0.2)


def namespaces() -> list[str]:
    return subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout.split()


def test_two_sites_talk_through_their_radios_with_the_links_delay_and_a_cut_holds_everything(tmp_path: Path) -> None:
    sites = Sites(tmp_path)
    sites.add("a", Radio(delay_ms=40.0))
    b = sites.add("b", Radio(delay_ms=10.0), cable=True)
    echo = None
    with sites:
        made = [n for n in namespaces() if n.startswith(sites.tag)]
        assert len(made) == 4, made  # hub, vehicles, a, b
        echo = subprocess.Popen(sites.argv("b", [sys.executable, "-c", ECHO, b.address]), stdout=subprocess.PIPE,
                                text=True)
        assert echo.stdout is not None and echo.stdout.readline().strip() == "up"
        sites.enter("a")
        try:
            rtt = round_trips_ms(b.address, 20)
            # a -> hub 40 ms, hub -> b 10 ms, and back: 100 ms a round trip
            assert 95.0 <= statistics.median(rtt) <= 140.0, rtt
            # the cable is b's, not a's: a cannot reach the vehicles
            with pytest.raises(OSError):
                socket.create_connection((b.vehicle_address, 9), timeout=2.0)
            sites.cut("b")
            with pytest.raises(TimeoutError):  # nothing crosses, silently: not even the handshake
                socket.create_connection((b.address, 9000), timeout=1.5)
            assert cut_packets(sites, "b") > 0
            sites.restore("b")
            assert statistics.median(round_trips_ms(b.address, 5)) >= 95.0
        finally:
            sites.leave()
    if echo is not None:
        echo.kill()
        echo.wait(5)
    assert not [n for n in namespaces() if n.startswith(sites.tag)]


def test_namespaces_left_by_a_killed_maker_are_removed_at_the_next_start(tmp_path: Path) -> None:
    script = (f"import sys, time; sys.path.insert(0, {str(Path.cwd())!r})\n"
              "from pathlib import Path\n"
              "from planner_service.harness.sites import Radio, Sites\n"
              f"s = Sites(Path({str(tmp_path / 'orphan')!r})); s.add('x', Radio()); s.start()\n"
              "print(s.tag, flush=True); time.sleep(60)\n")
    maker = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert maker.stdout is not None
    tag = maker.stdout.readline().strip()
    assert tag.startswith(PREFIX) and [n for n in namespaces() if n.startswith(tag)]
    maker.kill()
    maker.wait(5)
    with Sites(tmp_path / "next") as sites:  # the orphan goes at start
        assert not [n for n in namespaces() if n.startswith(tag + "-")]
    assert not [n for n in namespaces() if n.startswith(sites.tag)]
