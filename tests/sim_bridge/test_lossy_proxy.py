"""The lossy proxy, and a mission upload through it completed by the protocol's retries."""

from __future__ import annotations

import asyncio
import random
import socket
import time

import pytest

from planner_service.harness.processes import free_port
from protocol.geodesy import GeoOrigin
from protocol.mission import HoverPoint, encode_path, same_items
from sim_bridge.proxy import Impairment, LossyProxy, ProxyError
from tests.support.gcs import M, GroundStation, as_stored


@pytest.mark.timeout(60)
def test_upload_through_20_percent_loss_each_way(vehicle, spawn) -> None:
    _, vehicle_port = vehicle("--item-timeout", "0.25", "--retries", "20", "--gps-delay-s", "0")
    proxy_port = free_port(socket.SOCK_DGRAM)
    proxy = spawn(["lossy-proxy", "--listen", f"127.0.0.1:{proxy_port}", "--forward", f"127.0.0.1:{vehicle_port}",
                   "--drop", "0.2", "--dup", "0.05", "--delay-ms", "30", "--seed", "11"], "lossy proxy")
    gcs = GroundStation(f"udpout:127.0.0.1:{proxy_port}", timeout_s=0.2, retries=40)
    try:
        gcs.wait_vehicle()
        points = [HoverPoint(20.0 + 45.0 * i, 480.0 - 45.0 * i, 80.0, 5.0) for i in range(10)]
        items = encode_path(points, GeoOrigin(), "ardupilot")
        started = time.monotonic()
        assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED
        elapsed = time.monotonic() - started
        assert same_items(gcs.download(), as_stored(items, "ardupilot"))
    finally:
        gcs.close()
    assert proxy.stop() == 0
    stats = proxy.log()
    assert "'dropped': 0" not in stats, f"the proxy must have dropped datagrams both ways: {stats}"
    print(f"upload of {len(items)} items through 20 % loss each way: {elapsed:.2f} s")


def _relay(impairment: Impairment, seed: int, count: int) -> list[int]:
    """Send ``count`` numbered datagrams through a proxy; the numbers received, in order."""

    async def run() -> list[int]:
        sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sink.bind(("127.0.0.1", 0))
        sink.setblocking(False)
        loop = asyncio.get_running_loop()
        received: list[int] = []

        def read_sink() -> None:
            # Read as datagrams arrive: a socket buffer holds only a few hundred.
            while True:
                try:
                    received.append(int.from_bytes(sink.recv(16), "big"))
                except BlockingIOError:
                    return

        loop.add_reader(sink, read_sink)
        proxy = LossyProxy(("127.0.0.1", 0), sink.getsockname(), impairment, random.Random(seed))
        proxy.start(loop)
        source = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            for i in range(count):
                source.sendto(i.to_bytes(4, "big"), proxy.address)
                if i % 20 == 19:
                    await asyncio.sleep(0.002)
            await asyncio.sleep(0.3)
            return received
        finally:
            loop.remove_reader(sink)
            proxy.close()
            source.close()
            sink.close()

    return asyncio.run(run())


@pytest.mark.timeout(20)
def test_proxy_drops_duplicates_and_reorders_as_asked() -> None:
    got = _relay(Impairment(drop=0.2, dup=0.1, delay_ms=20, jitter_ms=15), seed=3, count=1000)
    distinct = set(got)
    # Binomial(1000, 0.8): mean 800, sd 12.6; 6 sd either side.
    assert 725 <= len(distinct) <= 875
    duplicates = len(got) - len(distinct)
    assert 40 <= duplicates <= 125  # about 0.8 * 0.1 * 1000 = 80
    assert got != sorted(got), "jitter larger than the sending interval must reorder"


@pytest.mark.timeout(20)
def test_proxy_is_deterministic_for_a_seed_and_transparent_without_loss() -> None:
    clean = _relay(Impairment(), seed=1, count=200)
    assert clean == list(range(200))
    lossy = Impairment(drop=0.3)
    assert set(_relay(lossy, seed=5, count=300)) == set(_relay(lossy, seed=5, count=300))


def test_bad_settings_are_named() -> None:
    with pytest.raises(ProxyError) as err:
        Impairment(drop=1.5)
    assert err.value.what == "drop"
