"""Zenoh key expressions of one vehicle: ``{prefix}/{vehicle}/{leaf}``."""

from __future__ import annotations

import re
from dataclasses import dataclass

from .errors import ProtocolError

DEFAULT_PREFIX = "uavmec"
DEFAULT_VEHICLE = "uav1"

# A key chunk must not contain zenoh's separators or wildcards, or a vehicle id
# like "a/*" would silently subscribe to every vehicle.
# fullmatch, not match with "$", which accepts a trailing newline ("uav1\n").
_CHUNK = re.compile(r"[A-Za-z0-9_.\-]{1,64}")


def _check_chunk(field: str, value: str) -> str:
    if not isinstance(value, str) or not _CHUNK.fullmatch(value):
        raise ProtocolError(field, f"{value!r} is not a key chunk (1-64 of A-Z a-z 0-9 _ . -)")
    return value


@dataclass(frozen=True)
class Keys:
    """The key expressions of one vehicle under one prefix."""

    prefix: str = DEFAULT_PREFIX
    vehicle: str = DEFAULT_VEHICLE

    def __post_init__(self) -> None:
        _check_chunk("prefix", self.prefix)
        _check_chunk("vehicle", self.vehicle)

    def _key(self, leaf: str) -> str:
        return f"{self.prefix}/{self.vehicle}/{leaf}"

    @property
    def request(self) -> str:
        """Queryable: a user's task request in, an ack or an error out."""
        return self._key("request")

    @property
    def status(self) -> str:
        """Publication: periodic vehicle and service status."""
        return self._key("status")

    @property
    def plan(self) -> str:
        """Publication: the current plan whenever it changes."""
        return self._key("plan")

    @property
    def events(self) -> str:
        """Publication: one message per event (accepted, served, uploaded, ...)."""
        return self._key("events")

    @property
    def state(self) -> str:
        """Queryable: a snapshot of the service state."""
        return self._key("state")

    @property
    def operator(self) -> str:
        """Queryable: the operator's commands (start, hold, status) in, an operator_reply
        out. Under access control only operator certificates may query it."""
        return self._key("operator")

    @property
    def alive(self) -> str:
        """Liveliness token of the service."""
        return self._key("alive")

    @property
    def all(self) -> str:
        """Every key of this vehicle, for a subscriber that wants them all."""
        return self._key("**")
