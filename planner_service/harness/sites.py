"""Sites on one machine as on the field: each UAV's companion computer, each ground router and
the ground station in its own network namespace, joined through a hub namespace (the IP
backbone, forwarding) by emulated radio links (``sim_bridge wire``: delay, jitter, loss and
cuts in user space, since this kernel has no netem). Zenoh runs over real sockets between
real addresses; only the link between a companion computer and its autopilot is a plain
veth "cable" (to one namespace holding the simulated vehicles), as on board.

Addresses: site k is ``10.78.k.2`` (its hub side ``10.78.k.1``); its cable ``10.79.k.2`` to
the vehicles' ``10.79.k.1``. Everything is made by ``start`` and removed by ``close`` (also
when a step fails, and namespaces left by a process that died are removed at the next
start). Needs root and ``ip`` (iproute2); docs/PERFORMANCE.md says more.
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from .processes import REPO, tied_to_parent

PREFIX = "uavmec"
CLONE_NEWNET = 0x40000000


class SitesError(RuntimeError):
    """Sites that cannot be made here (not root, no ``ip``) or a step that failed."""


@dataclass(frozen=True)
class Radio:
    """One site's link to the hub, each way: ``delay_ms`` +- ``jitter_ms`` (uniform), each
    packet lost with probability ``loss``."""

    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    loss: float = 0.0


@dataclass
class Site:
    name: str
    index: int
    radio: Radio
    cable: bool
    """A veth to the vehicles' namespace (a UAV's companion computer to its autopilot)."""

    @property
    def address(self) -> str:
        return f"10.78.{self.index}.2"

    @property
    def vehicle_address(self) -> str:
        """Where this site reaches its vehicle (in the vehicles' namespace)."""
        return f"10.79.{self.index}.1"


def ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise SitesError(f"ip {' '.join(args)}: {done.stderr.strip()}")


def can_make_sites() -> str | None:
    """Why sites cannot be made here, or None."""
    if os.geteuid() != 0:
        return "making network namespaces needs root"
    if subprocess.run(["ip", "netns", "list"], capture_output=True).returncode != 0:
        return "no working `ip netns` (iproute2)"
    if not Path("/dev/net/tun").exists():
        return "no /dev/net/tun"
    return None


def remove_orphans() -> list[str]:
    """Namespaces of ours whose maker is gone (killed before its ``close``); their names."""
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout.split()
    gone = []
    for name in listed:
        if name.startswith(PREFIX) and "-" in name:
            pid = name[len(PREFIX):].split("-", 1)[0]
            if pid.isdigit() and not Path(f"/proc/{pid}").exists():
                subprocess.run(["ip", "netns", "del", name], capture_output=True)
                gone.append(name)
    return gone


def _setns(fd: int, what: str) -> None:
    """Move this thread into the network namespace open as ``fd`` (``what`` names it)."""
    if ctypes.CDLL(None, use_errno=True).setns(fd, CLONE_NEWNET) != 0:
        raise SitesError(f"setns {what}: {os.strerror(ctypes.get_errno())}")


@dataclass
class Sites:
    """The namespaces, their links and the wire carrying them; ``start`` then ``close``."""

    folder: Path
    seed: int = 0
    sites: dict[str, Site] = field(default_factory=dict)
    tag: str = field(default_factory=lambda: f"{PREFIX}{os.getpid()}")
    _made: list[str] = field(default_factory=list)
    wire_nice: int = -10
    """The wire's niceness: ahead of the processes it carries for (the field's radios do not
    wait for the companion computers' CPU; here they share two cores). Its figures count the
    packets it still delivered late (``late``)."""
    _wire: subprocess.Popen | None = None
    _home: int | None = None

    def add(self, name: str, radio: Radio, cable: bool = False) -> Site:
        if len(self.sites) >= 250:
            raise SitesError("at most 250 sites")
        site = Site(name, len(self.sites) + 1, radio, cable)
        self.sites[name] = site
        return site

    def netns(self, name: str) -> str:
        return f"{self.tag}-{name}"

    @property
    def vehicles_netns(self) -> str:
        return self.netns("vehicles")

    def start(self) -> None:
        why = can_make_sites()
        if why:
            raise SitesError(why)
        remove_orphans()
        try:
            self._make("hub")
            subprocess.run(["ip", "netns", "exec", self.netns("hub"), "sysctl", "-qw", "net.ipv4.ip_forward=1"],
                           check=True, capture_output=True)
            self._make("vehicles")
            for site in self.sites.values():
                self._make_site(site)
            if self.sites:
                self._start_wire()
        except BaseException:
            self.close()
            raise

    def _make(self, name: str) -> None:
        ns = self.netns(name)
        ip("netns", "add", ns)
        self._made.append(ns)
        ip("-n", ns, "link", "set", "lo", "up")

    def _make_site(self, site: Site) -> None:
        ns, hub, k = self.netns(site.name), self.netns("hub"), site.index
        self._make(site.name)
        for where, device, local, peer in ((ns, "radio", f"10.78.{k}.2", f"10.78.{k}.1"),
                                           (hub, f"r{k}", f"10.78.{k}.1", f"10.78.{k}.2")):
            ip("-n", where, "tuntap", "add", "dev", device, "mode", "tun")
            ip("-n", where, "addr", "add", local, "peer", peer, "dev", device)
            ip("-n", where, "link", "set", device, "up")
        ip("-n", ns, "route", "add", "10.78.0.0/16", "dev", "radio")
        if site.cable:
            vehicles = self.vehicles_netns
            ip("-n", ns, "link", "add", "cable", "type", "veth", "peer", "name", f"c{k}", "netns", vehicles)
            ip("-n", ns, "addr", "add", f"10.79.{k}.2/30", "dev", "cable")
            ip("-n", ns, "link", "set", "cable", "up")
            ip("-n", vehicles, "addr", "add", f"10.79.{k}.1/30", "dev", f"c{k}")
            ip("-n", vehicles, "link", "set", f"c{k}", "up")

    def _start_wire(self) -> None:
        links = [f"{s.name}={self.netns(s.name)}:radio,{self.netns('hub')}:r{s.index},"
                 f"{s.radio.delay_ms:g},{s.radio.jitter_ms:g},{s.radio.loss:g}" for s in self.sites.values()]
        self.folder.mkdir(parents=True, exist_ok=True)
        log = open(self.folder / "wire.log", "w")
        env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self._wire = subprocess.Popen(
            [sys.executable, "-m", "sim_bridge", "wire", "--seed", str(self.seed), "--stats-file",
             str(self.stats_path), "--nice", str(self.wire_nice), *[a for link in links for a in ("--link", link)]],
            cwd=REPO, env=env, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=log, text=True,
            start_new_session=True, preexec_fn=tied_to_parent())
        log.close()
        deadline = time.monotonic() + 30.0
        while "wire ready" not in (self.folder / "wire.log").read_text():
            if self._wire.poll() is not None or time.monotonic() > deadline:
                raise SitesError(f"the wire did not start:\n{(self.folder / 'wire.log').read_text()[-1500:]}")
            time.sleep(0.05)

    @property
    def stats_path(self) -> Path:
        return self.folder / "wire.json"

    def argv(self, site: str, argv: list[str]) -> list[str]:
        """``argv`` run in ``site``'s namespace (``vehicles``: the vehicles')."""
        return ["ip", "netns", "exec", self.netns(site), *argv]

    def cut(self, site: str) -> None:
        self._tell(f"cut {site}")

    def restore(self, site: str) -> None:
        self._tell(f"restore {site}")

    def _tell(self, line: str) -> None:
        if self._wire is None or self._wire.stdin is None:
            raise SitesError("the wire is not running")
        self._wire.stdin.write(line + "\n")
        self._wire.stdin.flush()

    def enter(self, site: str) -> None:
        """Move this thread (and what it starts from now on: threads, children) into
        ``site``'s namespace; ``leave`` comes back."""
        if self._home is None:
            self._home = os.open("/proc/self/ns/net", os.O_RDONLY)
        path = f"/run/netns/{self.netns(site)}"
        fd = os.open(path, os.O_RDONLY)
        try:
            _setns(fd, path)
        finally:
            os.close(fd)

    def leave(self) -> None:
        if self._home is not None:
            _setns(self._home, "home")
            os.close(self._home)
            self._home = None

    def close(self) -> None:
        """Stop the wire and remove every namespace made (their devices go with them)."""
        self.leave()
        if self._wire is not None:
            if self._wire.poll() is None:
                self._wire.terminate()
                try:
                    self._wire.wait(10)
                except subprocess.TimeoutExpired:
                    self._wire.kill()
                    self._wire.wait(5)
            if self._wire.stdin is not None:
                self._wire.stdin.close()
            self._wire = None
        for ns in reversed(self._made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        self._made.clear()

    def __enter__(self) -> "Sites":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
