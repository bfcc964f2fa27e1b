"""The autopilot link: one small interface (``VehicleLink``), two backends (pymavlink by
default, the native mavsdk 4 binding by configuration)."""

from __future__ import annotations

from typing import Callable

from .base import LinkEvent, LinkSettings, Telemetry, VehicleLink, mode_name

__all__ = ["LinkEvent", "LinkSettings", "Telemetry", "VehicleLink", "mode_name", "open_link"]


def open_link(backend: str, settings: LinkSettings, on_event: Callable[[LinkEvent], None]) -> VehicleLink:
    """A link of the named backend (not yet connected)."""
    if backend == "mavsdk":
        from .mavsdk_link import MavsdkLink  # imported only when chosen: it loads a C++ library

        return MavsdkLink(settings, on_event)
    from .mavlink_link import PymavlinkLink

    return PymavlinkLink(settings, on_event)
