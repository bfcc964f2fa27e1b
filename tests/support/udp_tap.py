"""A UDP relay on loopback between the service and the vehicle stub, as a radio network both
sit on: the test learns the service's MAVLink address (its ``udpout`` socket) and what the
vehicle streams, so a rogue host can send unsigned datagrams to the service as a second
ground station on the same network could."""

from __future__ import annotations

import os
import socket
import threading
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

M = mavutil.mavlink


class UdpTap:
    """127.0.0.1:``port`` (the service's ``mavlink.url``) relayed to the vehicle's port."""

    def __init__(self, vehicle_port: int) -> None:
        self._front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._front.bind(("127.0.0.1", 0))
        self.port: int = self._front.getsockname()[1]
        self._back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._back.connect(("127.0.0.1", vehicle_port))
        self.service: tuple[str, int] | None = None
        """The service's address, once it sent its first datagram."""
        self.latest: dict[str, Any] = {}
        """The vehicle's latest message of each type, as the service got it."""
        self.packet_seq = 0
        """The MAVLink packet sequence of the vehicle's latest message."""
        self._parser = M.MAVLink(None)
        self._parser.robust_parsing = True
        self._closed = False
        threading.Thread(target=self._up, name="tap-up", daemon=True).start()
        threading.Thread(target=self._down, name="tap-down", daemon=True).start()

    def _up(self) -> None:
        while not self._closed:
            try:
                data, addr = self._front.recvfrom(65536)
                self.service = addr
                self._back.send(data)
            except OSError:
                return

    def _down(self) -> None:
        while not self._closed:
            try:
                data = self._back.recv(65536)
            except OSError:
                if self._closed:
                    return
                continue  # the vehicle not listening yet (ICMP port unreachable)
            for msg in self._parser.parse_buffer(data) or []:
                if msg.get_srcSystem() == 1 and msg.get_srcComponent() == 1:
                    self.latest[msg.get_type()] = msg
                    self.packet_seq = msg.get_seq()
            if self.service is not None:
                try:
                    self._front.sendto(data, self.service)
                except OSError:
                    return

    def forge(self, msg: Any, system: int = 1, component: int = 1) -> None:
        """One unsigned datagram holding ``msg`` from ``system``/``component``, to the service
        from another socket (another host on the network), numbered as the vehicle's next
        packet (so nothing takes it for a datagram sent before the vehicle's latest)."""
        assert self.service is not None, "the service has sent nothing yet"
        rogue = M.MAVLink(None, srcSystem=system, srcComponent=component)
        rogue.seq = (self.packet_seq + 1) % 256
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(msg.pack(rogue), self.service)

    def close(self) -> None:
        self._closed = True
        self._front.close()
        self._back.close()
