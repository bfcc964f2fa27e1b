"""The software vehicle (SITL-stub): MAVLink 2 over UDP/TCP, missions flown in simulated time."""

from .errors import VehicleError
from .flight import Flight, FlightEvent
from .link import Link
from .mission_store import MissionStore
from .modes import Mode
from .runner import Vehicle, VehicleConfig

__all__ = ["Flight", "FlightEvent", "Link", "MissionStore", "Mode", "Vehicle", "VehicleConfig", "VehicleError"]
