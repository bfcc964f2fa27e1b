"""A lossy UDP link between a ground station and a vehicle, for testing protocols' retries.

Every datagram, in each direction, is dropped with probability ``drop``, else sent once
(or twice with probability ``dup``) after ``delay_ms`` +- ``jitter_ms`` (uniform): the
jitter reorders datagrams that follow each other closely. All draws come from one seeded
``random.Random`` so that a run can be repeated. Each ground-station address gets its own
upstream socket, so the vehicle sees distinct peers as it would without the proxy.
"""

from __future__ import annotations

import asyncio
import logging
import random
import socket
from dataclasses import dataclass, field

log = logging.getLogger(__name__)

MAX_PENDING = 2048
"""Datagrams waiting for their delay; beyond this new ones are dropped (bounded memory)."""
MAX_CLIENTS = 16


class ProxyError(ValueError):
    """Bad proxy configuration; ``what`` names the setting."""

    def __init__(self, what: str, message: str) -> None:
        super().__init__(f"{what}: {message}")
        self.what = what


@dataclass(frozen=True)
class Impairment:
    """What the link does to each datagram."""

    drop: float = 0.0
    dup: float = 0.0
    delay_ms: float = 0.0
    jitter_ms: float | None = None
    """Half-width of the uniform delay spread; None means ``delay_ms / 2``."""

    def __post_init__(self) -> None:
        for name in ("drop", "dup"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ProxyError(name, f"must lie in [0, 1], got {value}")
        if self.delay_ms < 0 or (self.jitter_ms is not None and self.jitter_ms < 0):
            raise ProxyError("delay_ms", "delays must not be negative")

    @property
    def spread_s(self) -> float:
        return (self.delay_ms / 2 if self.jitter_ms is None else self.jitter_ms) / 1000.0


@dataclass
class ProxyStats:
    """Datagrams seen, dropped, duplicated, overflowed, per direction."""

    up: dict[str, int] = field(default_factory=lambda: {"in": 0, "dropped": 0, "duplicated": 0, "overflow": 0})
    down: dict[str, int] = field(default_factory=lambda: {"in": 0, "dropped": 0, "duplicated": 0, "overflow": 0})


def parse_address(text: str, what: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise ProxyError(what, f"{text!r} is not HOST:PORT")
    try:
        number = int(port)
    except ValueError:
        raise ProxyError(what, f"port {port!r} is not a number") from None
    if not 0 <= number <= 65535:
        raise ProxyError(what, f"port {number} is out of range")
    return host, number


class LossyProxy:
    """Listens at ``listen`` for ground stations and forwards to ``forward`` (the vehicle)."""

    def __init__(self, listen: tuple[str, int], forward: tuple[str, int], impairment: Impairment,
                 rng: random.Random) -> None:
        self.listen = listen
        self.forward = forward
        self.impairment = impairment
        self.rng = rng
        self.stats = ProxyStats()
        self._pending = 0
        self._front: socket.socket | None = None
        self._upstream: dict[tuple[str, int], socket.socket] = {}
        self._loop: asyncio.AbstractEventLoop | None = None

    @property
    def address(self) -> tuple[str, int]:
        """Where ground stations send (the bound address, useful with port 0)."""
        if self._front is None:
            raise ProxyError("listen", "the proxy is not started")
        return self._front.getsockname()[:2]

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        """Bind and start relaying on ``loop``."""
        self._loop = loop
        try:
            self._front = self._socket(self.listen)
        except OSError as exc:
            raise ProxyError("listen", f"cannot bind {self.listen}: {exc}") from None
        loop.add_reader(self._front, self._read_front)
        log.info("lossy proxy %s:%d -> %s:%d, %s", *self.address, *self.forward, self.impairment)

    def close(self) -> None:
        for sock in [self._front, *self._upstream.values()]:
            if sock is not None:
                if self._loop is not None:
                    self._loop.remove_reader(sock)
                sock.close()
        self._front = None
        self._upstream.clear()

    async def serve(self, stop: asyncio.Event) -> None:
        """Run until ``stop`` is set."""
        self.start(asyncio.get_running_loop())
        try:
            await stop.wait()
        finally:
            self.close()
            log.info("lossy proxy stats: up %s, down %s", self.stats.up, self.stats.down)

    @staticmethod
    def _socket(address: tuple[str, int]) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.setblocking(False)
        sock.bind(address)
        return sock

    def _read_front(self) -> None:
        for data, addr in self._drain(self._front):
            upstream = self._upstream.get(addr)
            if upstream is None:
                if len(self._upstream) >= MAX_CLIENTS or self._loop is None:
                    continue
                upstream = self._socket(("127.0.0.1", 0) if self.forward[0].startswith("127.") else ("", 0))
                self._upstream[addr] = upstream
                self._loop.add_reader(upstream, self._read_upstream, addr)
            self._impair(data, self.stats.up, upstream, self.forward)

    def _read_upstream(self, client: tuple[str, int]) -> None:
        upstream = self._upstream.get(client)
        if upstream is None or self._front is None:
            return
        for data, _ in self._drain(upstream):
            self._impair(data, self.stats.down, self._front, client)

    @staticmethod
    def _drain(sock: socket.socket | None) -> list[tuple[bytes, tuple[str, int]]]:
        out = []
        while sock is not None and len(out) < 256:
            try:
                out.append(sock.recvfrom(65535))
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # ICMP unreachable: the other side is not up yet
                log.debug("udp receive error: %s", exc)
                break
        return out

    def _impair(self, data: bytes, stats: dict[str, int], sock: socket.socket, to: tuple[str, int]) -> None:
        stats["in"] += 1
        imp = self.impairment
        if self.rng.random() < imp.drop:
            stats["dropped"] += 1
            return
        copies = 1
        if self.rng.random() < imp.dup:
            copies = 2
            stats["duplicated"] += 1
        for _ in range(copies):
            if self._pending >= MAX_PENDING or self._loop is None:
                stats["overflow"] += 1
                continue
            delay = max(0.0, imp.delay_ms / 1000.0 + self.rng.uniform(-imp.spread_s, imp.spread_s))
            self._pending += 1
            self._loop.call_later(delay, self._deliver, sock, data, to)

    def _deliver(self, sock: socket.socket, data: bytes, to: tuple[str, int]) -> None:
        self._pending -= 1
        if sock.fileno() < 0:
            return  # closed meanwhile
        try:
            sock.sendto(data, to)
        except OSError as exc:
            log.debug("udp send to %s failed: %s", to, exc)
