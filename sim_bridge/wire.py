"""Emulated radio links between network namespaces: netem's job, done in user space.

This kernel has no ``netem`` qdisc (and cannot load it), so a link is a pair of TUN devices,
one in each namespace, and this process carries every IP packet from one to the other after
the link's delay +- jitter, dropping it with the link's loss (``proxy.Impairment``, the
lossy UDP proxy's model, drawn from one seeded ``random.Random``). Packets are delayed one by
one, as netem does: the kernels' TCP (zenoh's transport) sees real delay, reordering and
loss, and retransmits as it would over a radio; nothing above IP is touched. A link can be
cut (every packet dropped, silently, as a radio out of range) and restored while it runs.

The TUN devices are made beforehand (``ip -n NS tuntap add dev NAME mode tun``: persistent,
no packet information header) and attached here by entering each namespace in turn
(``setns``), before any thread starts.
"""

from __future__ import annotations

import asyncio
import ctypes
import fcntl
import logging
import os
import random
import socket
import struct
from dataclasses import dataclass, field

from .proxy import Impairment

log = logging.getLogger(__name__)

TUNSETIFF = 0x400454CA
IFF_TUN = 0x0001
IFF_NO_PI = 0x1000
CLONE_NEWNET = 0x40000000
MAX_PACKET = 65535
LATE_MS = 20.0
"""A packet delivered later than its delay by more than this is counted ``late``."""
MAX_IN_FLIGHT = 4096
"""Packets waiting for their delay on one direction of a link; beyond this they are dropped
(a radio's queue is finite too; counted as ``overflow``)."""


class WireError(ValueError):
    """A link that cannot be made or attached; the message names it."""


@dataclass(frozen=True)
class End:
    """One end of a link: a TUN device in a network namespace (None: this process's own)."""

    netns: str | None
    device: str


@dataclass(frozen=True)
class LinkSpec:
    name: str
    a: End
    b: End
    impairment: Impairment


@dataclass
class Direction:
    """What one direction of a link carried."""

    packets: int = 0
    bytes: int = 0
    dropped: int = 0
    cut: int = 0
    overflow: int = 0
    late: int = 0
    """Packets delivered more than ``LATE_MS`` after their delay was up (this process was
    not given the CPU in time: the radio was slower than the one asked for)."""
    late_ms_max: float = 0.0
    in_flight: int = field(default=0, repr=False)

    def figures(self) -> dict[str, float]:
        return {k: v for k, v in vars(self).items() if k != "in_flight"}


def parse_link(text: str) -> LinkSpec:
    """``NAME=NS_A:DEV_A,NS_B:DEV_B,DELAY_MS,JITTER_MS,LOSS`` (a namespace ``-``: this
    process's own)."""
    name, sep, rest = text.partition("=")
    parts = rest.split(",")
    if not sep or not name or len(parts) != 5:
        raise WireError(f"--link {text!r}: expected NAME=NS_A:DEV_A,NS_B:DEV_B,DELAY_MS,JITTER_MS,LOSS")
    ends = []
    for part in parts[:2]:
        netns, colon, device = part.partition(":")
        if not colon or not device or len(device) > 15:
            raise WireError(f"--link {text!r}: {part!r} is not NS:DEVICE (a device name of 1-15 characters)")
        ends.append(End(None if netns == "-" else netns, device))
    try:
        delay, jitter, loss = (float(p) for p in parts[2:])
        impairment = Impairment(drop=loss, delay_ms=delay, jitter_ms=jitter)
    except ValueError as err:
        raise WireError(f"--link {text!r}: {err}") from None
    return LinkSpec(name, ends[0], ends[1], impairment)


def _setns(fd: int) -> None:
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.setns(fd, CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise WireError(f"setns: {os.strerror(err)}")


def attach_tun(end: End) -> int:
    """A file descriptor on ``end``'s TUN device, entered in its namespace (and back)."""
    home = os.open("/proc/self/ns/net", os.O_RDONLY)
    try:
        if end.netns is not None:
            try:
                target = os.open(f"/run/netns/{end.netns}", os.O_RDONLY)
            except OSError as err:
                raise WireError(f"network namespace {end.netns!r}: {err.strerror}") from None
            try:
                _setns(target)
            finally:
                os.close(target)
        try:  # attaching by name would make the device if it were missing: a typo must not
            socket.if_nametoindex(end.device)
        except OSError:
            raise WireError(f"TUN device {end.device!r} in {end.netns or 'this namespace'}: no such device "
                            f"(make it first: ip tuntap add dev NAME mode tun)") from None
        try:
            fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK)
            fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH", end.device.encode(), IFF_TUN | IFF_NO_PI))
        except OSError as err:
            raise WireError(f"TUN device {end.device!r} in {end.netns or 'this namespace'}: {err.strerror}") from None
        return fd
    finally:
        if end.netns is not None:
            _setns(home)
        os.close(home)


class WireLink:
    """Carries packets both ways between two attached TUN devices."""

    def __init__(self, spec: LinkSpec, fd_a: int, fd_b: int, rng: random.Random) -> None:
        self.spec = spec
        self.impairment = spec.impairment
        self.rng = rng
        self.is_cut = False
        self.fds = (fd_a, fd_b)
        self.directions = {"a>b": Direction(), "b>a": Direction()}

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        fd_a, fd_b = self.fds
        loop.add_reader(fd_a, self._carry, loop, fd_a, fd_b, self.directions["a>b"])
        loop.add_reader(fd_b, self._carry, loop, fd_b, fd_a, self.directions["b>a"])

    def _carry(self, loop: asyncio.AbstractEventLoop, src: int, dst: int, d: Direction) -> None:
        try:
            packet = os.read(src, MAX_PACKET)
        except (BlockingIOError, InterruptedError):
            return
        d.packets += 1
        d.bytes += len(packet)
        if self.is_cut:
            d.cut += 1
            return
        if self.rng.random() < self.impairment.drop:
            d.dropped += 1
            return
        if d.in_flight >= MAX_IN_FLIGHT:
            d.overflow += 1
            return
        spread = self.impairment.spread_s
        delay_s = max(0.0, self.impairment.delay_ms / 1000.0 + self.rng.uniform(-spread, spread))
        d.in_flight += 1
        loop.call_later(delay_s, self._deliver, loop, dst, packet, d, loop.time() + delay_s)

    @staticmethod
    def _deliver(loop: asyncio.AbstractEventLoop, dst: int, packet: bytes, d: Direction, due: float) -> None:
        d.in_flight -= 1
        late_ms = (loop.time() - due) * 1000.0
        if late_ms > LATE_MS:
            d.late += 1
            d.late_ms_max = max(d.late_ms_max, round(late_ms, 1))
        try:
            os.write(dst, packet)
        except OSError:  # the device went down: the packet is lost, as on a radio
            d.overflow += 1

    def figures(self) -> dict[str, object]:
        return {"cut": self.is_cut, **{k: d.figures() for k, d in self.directions.items()}}
