"""The service's UDP server link (``udpin:``) sends while its reader adds new peers
(planner_service/service/link/udp_peers.py): pymavlink iterated the set of peers while the
reader added to it, and a send ended in ``RuntimeError: Set changed size during iteration``
(a clean-clone CI run: the task asking for telemetry died with it, test_signing_warnings.py
saw the traceback). Here new peers arrive as fast as a socket can be made while the link
sends: with a plain set the error comes within milliseconds, with the snapshot set never."""

from __future__ import annotations

import socket
import threading
import time

from pymavlink import mavutil

from planner_service.harness.processes import free_port
from planner_service.service.link.udp_peers import SnapshotSet, safe_peers


def test_sends_go_on_while_new_peers_arrive() -> None:
    port = free_port(socket.SOCK_DGRAM)
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}")
    safe_peers(conn)
    assert isinstance(conn.clients, SnapshotSet)
    conn.port.setblocking(False)
    stop = threading.Event()

    def read() -> None:
        while not stop.is_set():
            try:
                conn.recv()
            except OSError:
                pass

    def new_peers() -> None:
        made: list[socket.socket] = []
        while not stop.is_set():
            peer = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            peer.sendto(b"x", ("127.0.0.1", port))
            made.append(peer)
            if len(made) > 200:
                for p in made:
                    p.close()
                made.clear()
        for p in made:
            p.close()

    threads = [threading.Thread(target=read), threading.Thread(target=new_peers)]
    for t in threads:
        t.start()
    sent = 0
    try:
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            conn.write(b"hello")  # raised RuntimeError with pymavlink's plain set
            sent += 1
    finally:
        stop.set()
        for t in threads:
            t.join(10)
        conn.close()
    assert sent > 100 and len(conn.clients) > 1, (sent, len(conn.clients))
