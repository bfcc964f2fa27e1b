"""MAVLink over UDP and TCP for the vehicle: several ground stations at once, garbage-proof.

pymavlink's ``mavutil`` connections answer only the last UDP sender and accept a single
TCP client that they never notice leaving; a vehicle must serve a ground station and a
companion computer side by side, so this module keeps its own peers and uses pymavlink
only to pack and parse (one parser per peer, so one peer's stray bytes never corrupt
another's stream).

URLs: ``udpin:HOST:PORT`` (listen; reply to every peer heard from recently),
``udpout:HOST:PORT`` (send to a ground station listening there), ``tcpin:HOST:PORT``
(listen for TCP clients).

Signing (``signer``): every parser and the encoder share one ``protocol.signing.Signer``, so
outgoing messages are signed and an incoming message counts only if correctly signed (or an
unsigned RADIO_STATUS); the shared stream timestamps catch a replay from any address. A
sender whose every message is dropped is not a peer: it is neither greeted nor answered.
"""

from __future__ import annotations

import logging
import selectors
import socket
import time
from dataclasses import dataclass
from typing import Any, Callable, Hashable

from pymavlink.dialects.v20 import common as mavlink

from protocol.signing import Signer

from .errors import VehicleError

log = logging.getLogger(__name__)

UDP_PEER_TIMEOUT_S = 30.0
"""A UDP peer silent this long is forgotten (it left); it is greeted again if it returns."""
MAX_DATAGRAM = 65535
MAX_TCP_CLIENTS = 8
MAX_PARSERS = 64
_QUIET = frozenset({"GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE", "SYS_STATUS", "BATTERY_STATUS",
                    "GPS_RAW_INT", "EXTENDED_SYS_STATE", "HEARTBEAT"})


@dataclass(frozen=True)
class Received:
    """One message from one peer; ``new_peer`` on the first message of a peer."""

    peer: Hashable
    msg: Any
    new_peer: bool


def _parser(system_id: int, component_id: int, signer: Signer | None = None) -> mavlink.MAVLink:
    parser = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    parser.robust_parsing = True
    if signer is not None:
        signer.attach(parser)
    return parser


def _signature_refused(msg: Any) -> bool:
    return msg.get_type() == "BAD_DATA" and getattr(msg, "reason", "") == "Invalid signature"


def parse_url(url: str) -> tuple[str, str, int]:
    """``kind:host:port`` -> (kind, host, port); ``VehicleError`` names what is wrong."""
    parts = url.split(":")
    if len(parts) != 3 or parts[0] not in ("udpin", "udpout", "tcpin"):
        raise VehicleError("mavlink", f"{url!r} is not udpin:HOST:PORT, udpout:HOST:PORT or tcpin:HOST:PORT")
    try:
        port = int(parts[2])
    except ValueError:
        raise VehicleError("mavlink", f"port {parts[2]!r} is not a number") from None
    if not 0 <= port <= 65535:
        raise VehicleError("mavlink", f"port {port} is out of range")
    return parts[0], parts[1], port


class Link:
    """Sockets of one MAVLink endpoint; ``poll`` reads, ``send`` writes."""

    def __init__(self, url: str, system_id: int = 1, component_id: int = 1,
                 clock: Callable[[], float] = time.monotonic, signer: Signer | None = None) -> None:
        self.kind, host, port = parse_url(url)
        self.url = url
        self._clock = clock
        self._ids = (system_id, component_id)
        self.signer = signer
        self.encoder = _parser(system_id, component_id, signer)
        self.selector = selectors.DefaultSelector()
        self._peers: dict[Hashable, float] = {}
        """Peers that sent valid MAVLink, with the time they are forgotten."""
        self._parsers: dict[Hashable, mavlink.MAVLink] = {}
        self._heard: dict[Hashable, float] = {}
        self._tcp: dict[Hashable, socket.socket] = {}
        self._fixed_peer: tuple[str, int] | None = None
        self.bad_bytes = 0
        try:
            if self.kind == "tcpin":
                self._sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self._sock.bind((host, port))
                self._sock.listen(MAX_TCP_CLIENTS)
            else:
                self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                if self.kind == "udpin":
                    self._sock.bind((host, port))
                else:
                    self._fixed_peer = (host, port)
                    self._sock.bind(("127.0.0.1" if host.startswith("127.") else "", 0))
        except OSError as exc:
            raise VehicleError("mavlink", f"cannot open {url}: {exc}") from None
        self._sock.setblocking(False)
        self.selector.register(self._sock, selectors.EVENT_READ, None)
        if self._fixed_peer is not None:
            self._peers[self._fixed_peer] = float("inf")

    @property
    def address(self) -> tuple[str, int]:
        """The local address (useful when port 0 was asked for)."""
        return self._sock.getsockname()

    @property
    def peers(self) -> list[Hashable]:
        return list(self._peers)

    def wait(self, timeout_s: float) -> list[Received]:
        """Wait up to ``timeout_s`` for input and return every message that arrived."""
        received: list[Received] = []
        for key, _ in self.selector.select(max(0.0, timeout_s)):
            if key.data is None and self.kind == "tcpin":
                self._accept()
            elif key.data is None:
                self._read_udp(received)
            else:
                self._read_tcp(key.data, received)
        self._expire()
        return received

    def send(self, msg: Any, peer: Hashable | None = None) -> None:
        """Send to ``peer``, or to every peer when None. Never raises for a dead peer."""
        try:
            buf = msg.pack(self.encoder)
        except Exception as exc:  # a message we built wrongly must not stop the vehicle
            log.error("cannot pack %s: %s", msg.get_type(), exc)
            return
        self.encoder.seq = (self.encoder.seq + 1) % 256
        if log.isEnabledFor(logging.DEBUG) and msg.get_type() not in _QUIET:
            log.debug("send %s to %s", msg, peer or "all")
        targets = list(self._peers) if peer is None else [peer]
        for target in targets:
            self._write(target, buf)

    def close(self) -> None:
        for sock in list(self._tcp.values()):
            self._drop_tcp(sock)
        try:
            self.selector.unregister(self._sock)
        except (KeyError, ValueError):
            pass
        self._sock.close()
        self.selector.close()

    # --- internals ---------------------------------------------------------------------------
    def _write(self, peer: Hashable, buf: bytes) -> None:
        try:
            if self.kind == "tcpin":
                sock = self._tcp.get(peer)
                if sock is not None:
                    sock.sendall(buf)
            else:
                self._sock.sendto(buf, peer)  # type: ignore[arg-type]
        except (BlockingIOError, InterruptedError):
            log.debug("send buffer full for %s: message dropped", peer)
        except OSError as exc:
            log.debug("send to %s failed: %s", peer, exc)
            if self.kind == "tcpin" and peer in self._tcp:
                self._drop_tcp(self._tcp[peer])

    def _parse(self, peer: Hashable, data: bytes, received: list[Received]) -> None:
        now = self._clock()
        parser = self._parsers.get(peer)
        if parser is None:
            if len(self._parsers) >= MAX_PARSERS:
                self._parsers.pop(next(iter(self._parsers)))
            parser = self._parsers[peer] = _parser(*self._ids, self.signer)
        self._heard[peer] = now
        dropped = self.signer.stats.dropped_total if self.signer is not None else 0
        try:
            messages = parser.parse_buffer(data) or []
        except Exception as exc:  # robust parsing should not raise; a vehicle must not die if it does
            log.debug("unparseable bytes from %s: %s", peer, exc)
            self._parsers[peer] = _parser(*self._ids, self.signer)
            messages = []
        if self.signer is not None and self.signer.stats.dropped_total > dropped:
            # Dropped for their signature (they come back as BAD_DATA): counted, never obeyed.
            log.debug("dropped %d message(s) from %s, the last %s", self.signer.stats.dropped_total - dropped, peer,
                      self.signer.last_drop)
            messages = [m for m in messages if not _signature_refused(m)]
        # A frame with a message id the dialect does not know cannot have its CRC checked
        # (the CRC seed is per message), so pymavlink passes it on as MAVLink_unknown: one
        # byte edited in a frame's id is enough. It is noise, like BAD_DATA.
        good = [m for m in messages if m.get_type() != "BAD_DATA" and not isinstance(m, mavlink.MAVLink_unknown)]
        self.bad_bytes += sum(len(m.get_msgbuf()) for m in messages if m.get_type() == "BAD_DATA"
                              or isinstance(m, mavlink.MAVLink_unknown))
        if not good:
            return  # noise is not a peer: it is neither greeted nor sent telemetry
        new = peer not in self._peers
        if self.kind == "udpin":
            self._peers[peer] = now + UDP_PEER_TIMEOUT_S
        else:
            self._peers[peer] = float("inf")
        for i, msg in enumerate(good):
            received.append(Received(peer, msg, new and i == 0))

    def _read_udp(self, received: list[Received]) -> None:
        for _ in range(256):
            try:
                data, addr = self._sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:  # ICMP port unreachable from a departed peer
                log.debug("udp receive error: %s", exc)
                continue
            self._parse(addr, data, received)

    def _accept(self) -> None:
        try:
            sock, addr = self._sock.accept()
        except (BlockingIOError, InterruptedError):
            return
        if len(self._tcp) >= MAX_TCP_CLIENTS:
            sock.close()
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._tcp[addr] = sock
        self.selector.register(sock, selectors.EVENT_READ, addr)
        log.info("tcp client %s:%d connected", *addr)

    def _read_tcp(self, addr: Hashable, received: list[Received]) -> None:
        sock = self._tcp.get(addr)
        if sock is None:
            return
        try:
            data = sock.recv(MAX_DATAGRAM)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self._drop_tcp(sock)
            return
        self._parse(addr, data, received)

    def _drop_tcp(self, sock: socket.socket) -> None:
        for addr, known in list(self._tcp.items()):
            if known is sock:
                del self._tcp[addr]
                self._peers.pop(addr, None)
                self._parsers.pop(addr, None)
                log.info("tcp client %s disconnected", addr)
        try:
            self.selector.unregister(sock)
        except (KeyError, ValueError):
            pass
        sock.close()

    def _expire(self) -> None:
        now = self._clock()
        for peer, until in list(self._peers.items()):
            if until < now:
                del self._peers[peer]
        for peer, heard in list(self._heard.items()):
            if heard + UDP_PEER_TIMEOUT_S < now and peer not in self._peers:
                del self._heard[peer]
                self._parsers.pop(peer, None)
