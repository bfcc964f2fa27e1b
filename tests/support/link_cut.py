"""A TCP link on loopback that a test can cut and heal, as a radio link between two parts of
a network fails and comes back: ``LinkCut(target_port)`` listens on ``port`` and forwards
every connection to 127.0.0.1:``target_port``, byte for byte.

Cut, it forwards nothing and answers nothing, and the connections stay open: a silent
partition, which each side learns of only when its lease expires, as over a real link that
fades (a closed socket would tell it at once). Healed, the connections of before are closed
(their byte streams have holes) and every connection from then on forwards again.
"""

from __future__ import annotations

import socket
import threading


class LinkCut:
    """127.0.0.1:``port`` forwarded to 127.0.0.1:``target_port`` until ``cut``."""

    def __init__(self, target_port: int) -> None:
        self.target_port = target_port
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port: int = self._listener.getsockname()[1]
        self._lock = threading.Lock()
        self._generation = 0
        """Bumped by ``cut`` and ``heal``: a connection forwards only in the generation it was
        made in, and only while the link is not cut."""
        self._cut = False
        self._sockets: list[tuple[int, socket.socket]] = []
        self._closed = False
        threading.Thread(target=self._accept, name="link-cut", daemon=True).start()

    def cut(self) -> None:
        with self._lock:
            self._cut = True
            self._generation += 1

    def heal(self) -> None:
        with self._lock:
            self._cut = False
            self._generation += 1
            stale = [s for g, s in self._sockets if g < self._generation]
            self._sockets = [(g, s) for g, s in self._sockets if g == self._generation]
        for s in stale:
            _close(s)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            sockets = [s for _, s in self._sockets]
            self._sockets.clear()
        _close(self._listener)
        for s in sockets:
            _close(s)

    def _forwarding(self, generation: int) -> bool:
        with self._lock:
            return not self._cut and generation == self._generation

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self._listener.accept()
            except OSError:
                return  # closed
            try:
                upstream = socket.create_connection(("127.0.0.1", self.target_port), timeout=2.0)
                upstream.settimeout(None)
            except OSError:
                conn.close()
                continue
            with self._lock:
                if self._closed:
                    _close(conn)
                    _close(upstream)
                    return
                generation = self._generation
                self._sockets += [(generation, conn), (generation, upstream)]
            for src, dst in ((conn, upstream), (upstream, conn)):
                threading.Thread(target=self._pump, args=(src, dst, generation), daemon=True).start()

    def _pump(self, src: socket.socket, dst: socket.socket, generation: int) -> None:
        while True:
            try:
                data = src.recv(65536)
            except OSError:
                break
            if not data:
                break
            if not self._forwarding(generation):
                continue  # cut: the bytes are lost, and nobody is told
            try:
                dst.sendall(data)
            except OSError:
                break
        _close(src)
        _close(dst)


def _close(s: socket.socket) -> None:
    try:
        s.shutdown(socket.SHUT_RDWR)  # wakes a thread blocked in recv on it
    except OSError:
        pass
    s.close()
