"""The vehicle stub's exception: what was refused and why."""

from __future__ import annotations


class VehicleError(ValueError):
    """Bad configuration of the vehicle stub (link address, flavour, scenario...)."""

    def __init__(self, what: str, message: str) -> None:
        super().__init__(f"{what}: {message}")
        self.what = what
        self.message = message
