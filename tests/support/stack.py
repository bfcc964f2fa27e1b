"""Real processes on loopback for the end-to-end tests (the ``stack`` fixture of
tests/service/conftest.py): the vehicle stub, the service and the simulated users, each on
free ports, zenoh with multicast scouting off and explicit tcp/127.0.0.1 endpoints; every
process is stopped when the test ends."""

from __future__ import annotations

import socket
import sqlite3
import threading
import time
from pathlib import Path
from typing import Any, Callable

from planner_service.service.config import OPERATOR_KEY_NAME, build_config, to_toml
from planner_service.harness.processes import Child, free_port
from protocol import Event, OperatorReply, State
from protocol.client import PlannerClient
from protocol.signing import load_key


class Stack:
    """A vehicle stub and a service wired together; ``client`` follows the events."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.children: list[Child] = []
        self.mav_port = free_port(socket.SOCK_DGRAM)
        self.zenoh_port = free_port()
        self.endpoint = f"tcp/127.0.0.1:{self.zenoh_port}"
        self.journal_path = tmp / "journal.sqlite"
        self.track = tmp / "track.csv"
        """The vehicle's own flight (``sim_bridge vehicle --track``): what it really flew."""
        self.events: list[Event] = []
        self.client: PlannerClient | None = None
        self._lock = threading.Lock()

    def vehicle(self, *extra: str) -> Child:
        """The vehicle stub, its own flight logged to ``track`` (appended across restarts)."""
        if "--gps-delay-s" not in extra:
            # Like ArduCopter the stub has no position for its first 40 simulated seconds
            # (40 s of wall time at --speedup 1); tests that are not about that start-up
            # give it a position after 2 s.
            extra = ("--gps-delay-s", "2", *extra)
        if "--disarm-delay-s" not in extra:
            # ArduCopter disarms 10 s after arming if it does not take off: 0.25 s of wall time
            # at x40, less than a start's four commands take over a lossy link. Off here;
            # tests/sim_bridge check the disarm itself.
            extra = ("--disarm-delay-s", "0", *extra)
        child = Child("sim_bridge", ["vehicle", "--mavlink", f"udpin:127.0.0.1:{self.mav_port}",
                                     "--track", str(self.track), *extra],
                      self.tmp / f"vehicle-{len(self.children)}.log")
        self.children.append(child)
        child.wait_ready("listening")
        return child

    def service(self, **overrides: str) -> Child:
        settings = {"zenoh.listen": self.endpoint, "mavlink.url": f"udpout:127.0.0.1:{self.mav_port}",
                    "journal.path": str(self.journal_path), "planner.budget_ms": "100", **overrides}
        config = build_config({}, {k.replace("__", "."): v for k, v in settings.items()})
        path = self.tmp / "planner.toml"
        path.write_text(to_toml(config))
        child = Child("planner_service", ["serve", "--config", str(path)], self.tmp / f"service-{len(self.children)}.log")
        self.children.append(child)
        child.wait_ready("ready:", 60.0)
        if self.client is None:
            self.client = PlannerClient([self.endpoint])
            self.client.follow_events(self._on_event)
        assert self.client.wait_for_service(20.0), "the service's liveliness token never appeared"
        return child

    def proxy(self, *impairment: str) -> int:
        """A lossy UDP proxy (``sim_bridge lossy-proxy``) in front of the vehicle; the port
        the service should send to instead of the vehicle's."""
        port = free_port(socket.SOCK_DGRAM)
        child = Child("sim_bridge", ["lossy-proxy", "--listen", f"127.0.0.1:{port}", "--forward",
                                     f"127.0.0.1:{self.mav_port}", *impairment], self.tmp / "proxy.log")
        self.children.append(child)
        child.wait_ready("lossy proxy")
        return port

    def users(self, *extra: str) -> Child:
        child = Child("sim_bridge", ["users", "--connect", self.endpoint, *extra], self.tmp / "users.log")
        self.children.append(child)
        return child

    @property
    def operator_key_path(self) -> Path:
        """Where the service makes its operator key (``operator.key`` beside the journal)."""
        return self.journal_path.parent / OPERATOR_KEY_NAME

    def operator_key(self) -> bytes:
        """The service's operator key (made by the service at its first start)."""
        return load_key(self.operator_key_path)

    def operator(self, command: str, reason: str = "", timeout_s: float = 10.0) -> OperatorReply:
        """The operator's ``command``, with the proof of the service's key."""
        assert self.client is not None
        return self.client.operator(command, reason, timeout_s, key=self.operator_key())

    def fleet(self, timeout_s: float = 10.0) -> State:
        """The fleet-wide state (every pending request): the operator's ``status``."""
        state = self.operator("status", timeout_s=timeout_s).state
        assert state is not None, "the operator's status came without the fleet-wide state"
        return state

    def _on_event(self, ev: Event) -> None:
        with self._lock:
            self.events.append(ev)

    def wait_event(self, predicate: Callable[[Event], bool], timeout_s: float, what: str) -> Event:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                for ev in self.events:
                    if predicate(ev):
                        return ev
            time.sleep(0.05)
        logs = "\n".join(f"--- {c.name}\n{c.log()[-3000:]}" for c in self.children)
        raise AssertionError(f"no {what} within {timeout_s} s\n{logs}")

    def wait_log(self, child: Child, text: str | tuple[str, ...], timeout_s: float) -> str:
        """Wait for ``text`` (or the first of several) in a child's log (its events can be
        missed by a subscriber in the first moments after the child started); the one found."""
        texts = (text,) if isinstance(text, str) else text
        deadline = time.monotonic() + timeout_s
        while True:
            log = child.log()  # once a round, whatever the number of texts
            if found := [t for t in texts if t in log]:
                return found[0]
            if time.monotonic() > deadline:
                raise AssertionError(f"none of {texts!r} in {child.name}'s log within {timeout_s} s\n"
                                     f"{log[-3000:]}")
            time.sleep(0.05)

    def wait_disarmed(self, timeout_s: float) -> None:
        """Wait until the service's status shows the vehicle disarmed (the autopilot's own
        disarming after a landing comes a moment after the landing)."""
        assert self.client is not None
        deadline = time.monotonic() + timeout_s
        while self.client.state().status.armed:
            if time.monotonic() > deadline:
                raise AssertionError(f"the vehicle still armed {timeout_s} s later")
            time.sleep(0.1)

    def rows(self, sql: str) -> list[tuple[Any, ...]]:
        """Read the journal as another process would (read-only, beside the WAL writer)."""
        db = sqlite3.connect(f"file:{self.journal_path}?mode=ro", uri=True)
        try:
            return db.execute(sql).fetchall()
        finally:
            db.close()

    def close(self) -> None:
        if self.client is not None:
            self.client.close()
        for child in reversed(self.children):
            child.stop()


