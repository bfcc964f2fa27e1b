"""The autopilot link: one small interface (``VehicleLink``), two backends (pymavlink by
default, the native mavsdk 4 binding by configuration), typed events (``events``), and the
pure judgements both share (``telemetry``, ``streams``, ``state``)."""

from __future__ import annotations

from typing import Callable, Literal

from .base import LinkSettings, VehicleLink
from .events import (ArmedChanged, Connected, Current, OnGround, LinkEvent, Lost, ModeChanged,
                     PositionChanged, Reached, Restarted, Restored, StatusText, TelemetryMissing)
from .modes import HOLDING_MODES, MISSION_MODES, RETURNING_MODES, mode_name
from .telemetry import Telemetry

__all__ = ["ArmedChanged", "Connected", "Current", "HOLDING_MODES", "LinkEvent", "LinkSettings", "Lost",
           "MISSION_MODES", "mode_name", "ModeChanged", "OnGround", "open_link", "PositionChanged", "Reached",
           "Restarted", "Restored", "RETURNING_MODES", "StatusText", "Telemetry", "TelemetryMissing", "VehicleLink"]


def open_link(backend: Literal["pymavlink", "mavsdk"], settings: LinkSettings,
              on_event: Callable[[LinkEvent], None]) -> VehicleLink:
    """A link of the named backend (not yet connected)."""
    if backend == "mavsdk":
        from .mavsdk_link import MavsdkLink  # imported only when chosen: it loads a C++ library

        return MavsdkLink(settings, on_event)
    from .mavlink_link import PymavlinkLink

    return PymavlinkLink(settings, on_event)
