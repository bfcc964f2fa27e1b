"""The emulated radio's carrying (sim_bridge/wire.py), on datagram socket pairs standing in
for the TUN devices (each read one packet, as a TUN device's): each packet after the delay +- jitter, lost with the loss's probability (seeded), none
while the link is cut; and the command line's link syntax."""

from __future__ import annotations

import asyncio
import os
import random
import socket
import time

import pytest

from sim_bridge.proxy import Impairment
from sim_bridge.wire import End, LinkSpec, WireError, WireLink, parse_link


def packet_pipe() -> tuple[int, int]:
    """(read end, write end), non-blocking, one packet a read."""
    one, other = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    for sock in (one, other):
        sock.setblocking(False)
    return one.detach(), other.detach()


def close(*fds: int) -> None:
    for fd in fds:
        os.close(fd)


def carry(impairment: Impairment, packets: int, cut: bool = False) -> tuple[int, WireLink]:
    """Write ``packets`` packets of 20 bytes into end a, 10 ms apart; the packets end b had
    once the last could have arrived, and the link."""
    a_in, a_out = packet_pipe()  # what end a reads: the packets its namespace sent
    b_in, b_out = packet_pipe()  # what the wire writes to end b
    link = WireLink(LinkSpec("l", End(None, "a"), End(None, "b"), impairment), a_in, b_out, random.Random(7))
    link.is_cut = cut

    async def run() -> int:
        loop = asyncio.get_running_loop()
        loop.add_reader(a_in, link._carry, loop, a_in, b_out, link.directions["a>b"])
        for _ in range(packets):
            os.write(a_out, b"x" * 20)
            await asyncio.sleep(0.01)
        await asyncio.sleep(impairment.delay_ms / 1000.0 + impairment.spread_s + 0.3)
        got = 0
        try:
            while chunk := os.read(b_in, 65536):
                got += len(chunk)
        except BlockingIOError:
            pass
        return got // 20

    try:
        return asyncio.run(run()), link
    finally:
        close(a_in, a_out, b_in, b_out)


def test_every_packet_arrives_after_the_delay_and_the_loss_takes_its_share() -> None:
    received, clean = carry(Impairment(delay_ms=50.0, jitter_ms=10.0), 100)
    d = clean.directions["a>b"]
    assert received == d.packets == 100 and d.dropped == 0 and d.in_flight == 0
    received, lossy = carry(Impairment(drop=0.2, delay_ms=50.0, jitter_ms=10.0), 200)
    d = lossy.directions["a>b"]
    assert d.packets == 200 and 20 <= d.dropped <= 60 and received == 200 - d.dropped, d  # 40 expected


def test_a_packet_waits_the_delay_before_it_is_written() -> None:
    a_in, a_out = packet_pipe()
    b_in, b_out = packet_pipe()
    link = WireLink(LinkSpec("l", End(None, "a"), End(None, "b"), Impairment(delay_ms=80.0, jitter_ms=0.0)), a_in,
                    b_out, random.Random(1))

    async def run() -> float:
        loop = asyncio.get_running_loop()
        loop.add_reader(a_in, link._carry, loop, a_in, b_out, link.directions["a>b"])
        sent = time.monotonic()
        os.write(a_out, b"x" * 20)
        while True:
            try:
                if os.read(b_in, 100):
                    return time.monotonic() - sent
            except BlockingIOError:
                await asyncio.sleep(0.002)

    try:
        waited = asyncio.run(run())
    finally:
        close(a_in, a_out, b_in, b_out)
    assert 0.075 <= waited < 1.0, waited


def test_a_packet_the_wire_could_not_deliver_in_time_is_counted_late() -> None:
    """The radios share the machine's CPU with what they carry: a packet written after its
    delay was up (the loop busy, here for 150 ms) is counted, so the bench can say how far
    the radios were the ones asked for."""
    a_in, a_out = packet_pipe()
    b_in, b_out = packet_pipe()
    link = WireLink(LinkSpec("l", End(None, "a"), End(None, "b"), Impairment(delay_ms=20.0, jitter_ms=0.0)), a_in,
                    b_out, random.Random(1))
    d = link.directions["a>b"]

    async def run() -> None:
        loop = asyncio.get_running_loop()
        loop.add_reader(a_in, link._carry, loop, a_in, b_out, d)
        os.write(a_out, b"x" * 20)
        await asyncio.sleep(0.1)  # delivered in time
        assert d.packets == 1 and d.late == 0, d
        os.write(a_out, b"x" * 20)
        await asyncio.sleep(0.005)  # taken in
        time.sleep(0.15)  # the loop is not given the CPU
        await asyncio.sleep(0.05)

    try:
        asyncio.run(run())
    finally:
        close(a_in, a_out, b_in, b_out)
    assert d.packets == 2 and d.late == 1 and 100.0 <= d.late_ms_max < 1000.0, d
    assert "late" in d.figures() and "in_flight" not in d.figures()


def test_a_cut_link_carries_nothing() -> None:
    received, link = carry(Impairment(delay_ms=5.0, jitter_ms=0.0), 30, cut=True)
    assert received == 0 and link.directions["a>b"].cut == 30


@pytest.mark.parametrize("text, why", [
    ("l=ns1:t0,ns2:t1,100,10,0.05", None),
    ("l=-:t0,ns2:t1,0,0,0", None),
    ("l=ns1:t0,ns2:t1,100,10", "expected NAME="),
    ("l=ns1,ns2:t1,100,10,0.05", "is not NS:DEVICE"),
    ("l=ns1:a-device-name-too-long,ns2:t1,1,1,0", "is not NS:DEVICE"),
    ("l=ns1:t0,ns2:t1,100,10,1.5", "must lie in [0, 1]"),
    ("l=ns1:t0,ns2:t1,fast,10,0", "could not convert"),
])
def test_link_syntax(text: str, why: str | None) -> None:
    if why is None:
        spec = parse_link(text)
        assert spec.name == "l" and spec.b == End("ns2", "t1")
    else:
        with pytest.raises(WireError, match=why.replace("[", r"\[").replace("]", r"\]")):
            parse_link(text)
