"""The service's UDP server link (``udpin:``) sends while its reader adds new peers
(planner_service/service/link/udp_peers.py): pymavlink iterated the set of peers while the
reader added to it, and a send ended in ``RuntimeError: Set changed size during iteration``
(a clean-clone CI run: the task asking for telemetry died with it, test_signing_warnings.py
saw the traceback). Here new peers arrive as fast as a socket can be made while the link
sends: with a plain set the error comes within milliseconds, with the snapshot set never."""

from __future__ import annotations

import gc
import socket
import threading
import time

from pymavlink import mavutil

from planner_service.harness.processes import free_port
from planner_service.service.link.udp_peers import SnapshotSet, safe_peers


SENDS = 200
NEW_PEERS = 20
"""Sends go on until this many new peers arrived during them (however slow the machine)."""
PEER_EVERY_S = 0.005
"""A new peer at most this often: a send goes to every peer ever heard, and unthrottled on a
busy machine the set reached 15885 peers and 2 s held 35 sends (a clean-clone run)."""


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
            time.sleep(PEER_EVERY_S)  # pymavlink keeps every peer: each send goes to all of them
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
    wait_until_s = time.monotonic() + 30.0
    while len(conn.clients) < 2 and time.monotonic() < wait_until_s:
        time.sleep(0.01)
    peers_before = len(conn.clients)
    try:
        deadline = time.monotonic() + 60.0
        while (sent < SENDS or len(conn.clients) < peers_before + NEW_PEERS) and time.monotonic() < deadline:
            conn.write(b"hello")  # raised RuntimeError with pymavlink's plain set
            sent += 1
    finally:
        stop.set()
        for t in threads:
            t.join(10)
        conn.close()
    # as many sends as asked for, to two peers or more, while new peers kept arriving
    assert sent >= SENDS and peers_before > 1 and len(conn.clients) >= peers_before + NEW_PEERS, (
        sent, peers_before, len(conn.clients))


def test_no_thread_can_add_between_the_copy_and_its_iteration() -> None:
    """The race CI met after the first fix, made certain: a garbage collection at every
    allocation, whose callback (Python code, as a finaliser would be) adds a peer. Copying
    through ``list(iter(...))`` let the add in between and raised; ``set.copy`` does not."""
    peers = SnapshotSet({("127.0.0.1", 1), ("127.0.0.1", 2)})
    added = 0

    def add_a_peer(phase: str, _info: dict) -> None:
        nonlocal added
        if phase == "start":
            added += 1
            set.add(peers, ("127.0.0.1", 1000 + added))

    threshold = gc.get_threshold()
    gc.callbacks.append(add_a_peer)
    gc.set_threshold(1)
    try:
        seen = [sorted(peers) for _ in range(50)]  # raised with the list copy
    finally:
        gc.callbacks.remove(add_a_peer)
        gc.set_threshold(*threshold)
    assert added > 0, "no collection ran: the test proved nothing"
    assert all(len(s) >= 2 for s in seen)
