"""Where a fleet's processes run and how they reach each other: all on loopback (the demo's,
the tests'), or each in its own site of emulated links (``sites.Sites``: the scale bench)."""

from __future__ import annotations

import socket
import sys
from dataclasses import dataclass
from typing import Protocol

from .processes import free_port
from .sites import Sites

ZENOH_PORT = 7447
MAVLINK_PORT = 14550


class Placement(Protocol):
    def router_site(self, index: int) -> str | None:
        """The site of router ``index`` (0-based); None: this process's own place."""

    def router_endpoint(self, index: int) -> str: ...

    def service_site(self, vehicle: str) -> str | None: ...

    def stub_site(self) -> str | None:
        """Where the vehicle stubs run."""

    def service_endpoint(self, vehicle: str) -> str: ...

    stubs_in_one_process: bool
    """All the vehicle stubs in one process (``vehicle --count N`` on ``stubs_url``)."""

    def stubs_url(self) -> str:
        """The first stub's URL when all are in one process (vehicle j on its port + j)."""

    def vehicle_urls(self, vehicle: str, index: int) -> tuple[str, str]:
        """(the stub's own MAVLink URL, the service's URL to it) of vehicle ``index``."""

    def program(self, site: str | None, module: str, args: list[str]) -> list[str] | None:
        """The argv of ``python -m MODULE ARGS`` in ``site`` (None: the default, here)."""


class Loopback:
    """Everything on 127.0.0.1 of this namespace, on free ports."""

    stubs_in_one_process = False

    def __init__(self) -> None:
        self._routers: dict[int, str] = {}

    def stubs_url(self) -> str:
        raise NotImplementedError("one process per stub on loopback")

    def router_site(self, index: int) -> str | None:
        return None

    def router_endpoint(self, index: int) -> str:
        return self._routers.setdefault(index, f"tcp/127.0.0.1:{free_port()}")

    def service_site(self, vehicle: str) -> str | None:
        return None

    def stub_site(self) -> str | None:
        return None

    def service_endpoint(self, vehicle: str) -> str:
        return f"tcp/127.0.0.1:{free_port()}"

    def vehicle_urls(self, vehicle: str, index: int) -> tuple[str, str]:
        port = free_port(socket.SOCK_DGRAM)
        return f"udpin:127.0.0.1:{port}", f"udpout:127.0.0.1:{port}"

    def program(self, site: str | None, module: str, args: list[str]) -> list[str] | None:
        return None


@dataclass
class SitePlacement:
    """Router ``i`` in site ``router{i+1}``, each UAV's service in the site named as the
    vehicle, its stub in the vehicles' namespace at the far end of the UAV's cable (all the
    stubs in one process by default); the caller (users, watch, live map) in whichever site
    it entered (``Sites.enter``)."""

    sites: Sites
    stubs_in_one_process: bool = True

    def router_site(self, index: int) -> str | None:
        return f"router{index + 1}"

    def router_endpoint(self, index: int) -> str:
        return f"tcp/{self.sites.sites[f'router{index + 1}'].address}:{ZENOH_PORT}"

    def service_site(self, vehicle: str) -> str | None:
        return vehicle

    def stub_site(self) -> str | None:
        return "vehicles"

    def service_endpoint(self, vehicle: str) -> str:
        return f"tcp/{self.sites.sites[vehicle].address}:{ZENOH_PORT}"

    def stubs_url(self) -> str:
        # every cable's far end is an address of the vehicles' namespace: one socket per
        # vehicle on all of them, vehicle j on the port + j
        return f"udpin:0.0.0.0:{MAVLINK_PORT}"

    def vehicle_urls(self, vehicle: str, index: int) -> tuple[str, str]:
        address = self.sites.sites[vehicle].vehicle_address
        port = MAVLINK_PORT + index if self.stubs_in_one_process else MAVLINK_PORT
        return f"udpin:{address}:{port}", f"udpout:{address}:{port}"

    def program(self, site: str | None, module: str, args: list[str]) -> list[str] | None:
        if site is None:
            return None
        return self.sites.argv(site, [sys.executable, "-m", module, *args])
