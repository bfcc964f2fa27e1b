"""The software vehicle (SITL-stub): MAVLink 2 over UDP/TCP, missions flown in simulated time."""

from .errors import VehicleError
from .events import FlightEvent
from .flight import Flight, MissionState, Refusal
from .link import Link
from .mission_store import MissionStore, StoreHooks
from .modes import Mode
from .runner import Vehicle, VehicleConfig

__all__ = [
    "Flight", "FlightEvent", "Link", "MissionState", "MissionStore", "Mode", "Refusal", "StoreHooks", "Vehicle",
    "VehicleConfig", "VehicleError",
]
