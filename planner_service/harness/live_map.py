"""The live map beside a demo: the fleet picture fed from the demo's zenoh endpoints and the
web server on 127.0.0.1 (a free port), so the first thing a newcomer sees is the sortie on a
map. The address (with its login token) is printed; ``linger`` keeps the page open after the
sortie until Ctrl-C (``demo --web``)."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any, Callable

import zenoh

from protocol.zenoh_config import session_config
from protocol.fleet_signing import read_roster
from protocol.signing import load_key

from ..live.feed import LiveFeed
from ..live.picture import FleetPicture
from ..web.server import LiveMapServer, RunningServer


class LiveMap:
    """The demo's live map: ``open`` it once the services are up, ``close`` at the end."""

    def __init__(self, connect: list[str], prefix: str, *, echo: Callable[[str], None] = print,
                 roster: Path | None = None) -> None:
        self.connect, self.prefix, self.echo = connect, prefix, echo
        self.roster = roster
        self.session: Any = None
        self.feed: LiveFeed | None = None
        self.running: RunningServer | None = None

    def open(self, operator_keys: dict[str, Path]) -> str:
        """Start reading the fleet and serving the page; returns (and prints) the address to open."""
        keys = {vehicle: load_key(str(path)) for vehicle, path in operator_keys.items() if path.exists()}
        self.session = zenoh.open(session_config("client", connect=self.connect))
        self.feed = LiveFeed(self.session, FleetPicture(self.prefix), threading.Lock(),
                             fleet_keys=read_roster(self.roster) if self.roster is not None else None,
                             operator_keys=keys)
        self.feed.start()
        self.running = RunningServer(LiveMapServer(self.feed)).start()
        self.echo(f"live map: {self.running.login_url}  (open it in a browser)")
        return self.running.login_url

    def linger(self) -> None:
        """Keep the page served until Ctrl-C."""
        if self.running is None:
            return
        self.echo(f"the live map stays open at {self.running.url}: Ctrl-C to end")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            self.echo("live map closed")

    def close(self) -> None:
        if self.running is not None:
            self.running.close()
        if self.feed is not None:
            self.feed.close()
        if self.session is not None:
            self.session.close()
        self.running = self.feed = self.session = None
