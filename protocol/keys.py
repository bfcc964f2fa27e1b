"""Zenoh key expressions of one vehicle: ``{prefix}/{vehicle}/{leaf}``, and the per-user
keys below it: ``{prefix}/{vehicle}/request/{user_id}`` (a user's own request key, which
access control can give to that user's certificate alone) and
``{prefix}/{vehicle}/users/{user_id}`` (that user's place in the plan)."""

from __future__ import annotations

import re
from dataclasses import dataclass

from .errors import ProtocolError

DEFAULT_PREFIX = "uavmec"
DEFAULT_VEHICLE = "uav1"
FLEET = "fleet"
"""The chunk after the prefix that holds the fleet's keys (``FleetKeys``); no vehicle's id."""

# A key chunk must not contain zenoh's separators or wildcards, or a vehicle id
# like "a/*" would silently subscribe to every vehicle.
# fullmatch, not match with "$", which accepts a trailing newline ("uav1\n").
_CHUNK = re.compile(r"[A-Za-z0-9_.\-]{1,64}")
_USER_ID = re.compile(r"[A-Za-z0-9_.:\-]{1,64}")
"""A user id (``protocol.messages.UserId``): also a key chunk (":" is no zenoh separator)."""


def _check_chunk(field: str, value: str) -> str:
    if not isinstance(value, str) or not _CHUNK.fullmatch(value):
        raise ProtocolError(field, f"{value!r} is not a key chunk (1-64 of A-Z a-z 0-9 _ . -)")
    return value


def check_user_id(value: str, field: str = "user_id") -> str:
    """``value`` if it is a user id (1-64 of A-Z a-z 0-9 _ . : -), else ``ProtocolError``."""
    if not isinstance(value, str) or not _USER_ID.fullmatch(value):
        raise ProtocolError(field, f"{value!r} is not a user id (1-64 of A-Z a-z 0-9 _ . : -)")
    return value


def _request_user(request: str, key_expr: str, names: str) -> str | None:
    """The user id of ``key_expr``, a query's key: None for ``request`` itself, the user of
    ``request/{user_id}``; ``ProtocolError("key", ...)`` for any other key."""
    if key_expr == request:
        return None
    head = request + "/"
    user = key_expr[len(head):] if key_expr.startswith(head) else None
    if user is None or not _USER_ID.fullmatch(user):
        raise ProtocolError("key", f"{key_expr!r} is neither {request} nor {head}USER_ID "
                                   f"(a request names {names}, without wildcards)")
    return user


@dataclass(frozen=True)
class Keys:
    """The key expressions of one vehicle under one prefix."""

    prefix: str = DEFAULT_PREFIX
    vehicle: str = DEFAULT_VEHICLE

    def __post_init__(self) -> None:
        _check_chunk("prefix", self.prefix)
        _check_chunk("vehicle", self.vehicle)
        if self.vehicle == FLEET:
            raise ProtocolError("vehicle", f"{FLEET!r} names the fleet's keys ({self.prefix}/{FLEET}/...), "
                                           f"not a vehicle")

    def _key(self, leaf: str) -> str:
        return f"{self.prefix}/{self.vehicle}/{leaf}"

    @property
    def request(self) -> str:
        """Queryable: a user's task request in, an ack or an error out."""
        return self._key("request")

    def user_request(self, user_id: str) -> str:
        """Queryable: ``user_id``'s own request key (the service checks that a request on it
        is that user's; under access control only that user's certificate may query it)."""
        return self._key(f"request/{check_user_id(user_id)}")

    @property
    def user_requests(self) -> str:
        """Every user's request key (the service's queryable for them)."""
        return self._key("request/*")

    def request_user(self, key_expr: str) -> str | None:
        """Whose request key ``key_expr`` (a query's key) is: None for the plain request
        key, the user id for ``request/{user_id}``; ``ProtocolError("key", ...)`` for any
        other key (a wildcard, another vehicle's), which names no single user."""
        return _request_user(self.request, key_expr, "one vehicle and at most one user")

    def user(self, user_id: str) -> str:
        """Publication: ``user_id``'s place in the plan (``user_place``)."""
        return self._key(f"users/{check_user_id(user_id)}")

    @property
    def users(self) -> str:
        """Every user's place publication, for a subscriber that follows them all."""
        return self._key("users/*")

    def place_user(self, key_expr: str) -> str | None:
        """The user id of a ``users/{user_id}`` key, or None for any other key."""
        head = self._key("users/")
        user = key_expr[len(head):] if key_expr.startswith(head) else ""
        return user if _USER_ID.fullmatch(user) else None

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


@dataclass(frozen=True)
class FleetKeys:
    """The keys the services of one fleet share under one prefix: ``{prefix}/fleet/...``.
    Each service's own are below its vehicle's chunk (``Keys``), so that access control can
    give a UAV's certificate its own member keys alone."""

    prefix: str = DEFAULT_PREFIX

    def __post_init__(self) -> None:
        _check_chunk("prefix", self.prefix)

    def _key(self, leaf: str) -> str:
        return f"{self.prefix}/{FLEET}/{leaf}"

    def member(self, vehicle: str) -> str:
        """Liveliness token of ``vehicle``'s service while it is a member of the fleet."""
        return self._key(f"members/{_check_chunk('vehicle', vehicle)}")

    @property
    def members(self) -> str:
        """Every member's token (a liveliness subscriber's key)."""
        return self._key("members/*")

    def announce(self, vehicle: str) -> str:
        """Publication with a cache: what ``vehicle``'s service says of itself to the fleet
        (``fleet_member``: its altitude layer)."""
        return self._key(f"uavs/{_check_chunk('vehicle', vehicle)}")

    @property
    def announces(self) -> str:
        """Every member's announcement (an advanced subscriber's key)."""
        return self._key("uavs/*")

    @property
    def statuses(self) -> str:
        """Every vehicle's status publication (``Keys.status``): the members' positions."""
        return f"{self.prefix}/*/status"

    def status_vehicle(self, key_expr: str) -> str | None:
        """The vehicle id of a ``{prefix}/{vehicle}/status`` key; None for any other key."""
        return self._vehicle_key(key_expr, "status")

    def user_places(self, user_id: str) -> str:
        """``user_id``'s place on every member's key (``Keys.user`` of each vehicle): each
        member that journalled the user publishes it, with a place if its plan has the user."""
        return f"{self.prefix}/*/users/{check_user_id(user_id)}"

    def place_vehicle(self, key_expr: str, user_id: str) -> str | None:
        """The vehicle id of a ``{prefix}/{vehicle}/users/{user_id}`` key; None for any other key."""
        return self._vehicle_key(key_expr, "users", user_id)

    def _vehicle_key(self, key_expr: str, *leaf: str) -> str | None:
        """The vehicle id of ``{prefix}/{vehicle}/{leaf...}``; None for any other key."""
        parts = key_expr.split("/")
        if parts[0] == self.prefix and parts[2:] == list(leaf) and parts[1] != FLEET and _CHUNK.fullmatch(parts[1]):
            return parts[1]
        return None

    @property
    def request(self) -> str:
        """Queryable of every member: a user's request to the fleet, whichever UAV serves it
        (each live service journals it and answers with its own ack)."""
        return self._key("request")

    def user_request(self, user_id: str) -> str:
        """Queryable: ``user_id``'s own fleet request key (access control can give it to that
        user's certificate alone)."""
        return self._key(f"request/{check_user_id(user_id)}")

    @property
    def user_requests(self) -> str:
        """Every user's fleet request key (each member's queryable for them)."""
        return self._key("request/*")

    def request_user(self, key_expr: str) -> str | None:
        """As ``Keys.request_user``, for the fleet's request keys."""
        return _request_user(self.request, key_expr, "at most one user")

    def intentions(self, vehicle: str) -> str:
        """Publication with a cache: the users ``vehicle``'s plan means to serve, and when
        (``fleet_intentions``), on every plan."""
        return self._key(f"intentions/{_check_chunk('vehicle', vehicle)}")

    @property
    def all_intentions(self) -> str:
        return self._key("intentions/*")

    def served(self, vehicle: str) -> str:
        """Publication with a cache: each service ``vehicle`` flew (``fleet_served``)."""
        return self._key(f"served/{_check_chunk('vehicle', vehicle)}")

    @property
    def all_served(self) -> str:
        return self._key("served/*")

    def position(self, vehicle: str) -> str:
        """Publication: ``vehicle``'s own position, signed (a ``fleet_position`` in a fleet
        envelope, with each status), on which the members judge the fleet's separation."""
        return self._key(f"positions/{_check_chunk('vehicle', vehicle)}")

    @property
    def positions(self) -> str:
        return self._key("positions/*")

    def signed_status(self, vehicle: str) -> str:
        """Publication: ``vehicle``'s whole ``status``, signed, with each status: the
        operator's live map reads an enrolled member's status here. The members do not
        subscribe to it (each reads the others' ``position``, about half its size): zenoh sends
        it only where someone subscribes."""
        return self._key(f"statuses/{_check_chunk('vehicle', vehicle)}")

    @property
    def signed_statuses(self) -> str:
        return self._key("statuses/*")

    def vehicle_of(self, key_expr: str) -> str | None:
        """The vehicle id that ends a member, announcement, intentions, served, position or
        signed status key; None for any other key."""
        for head in (self._key("members/"), self._key("uavs/"), self._key("intentions/"), self._key("served/"),
                     self._key("positions/"), self._key("statuses/")):
            if key_expr.startswith(head) and _CHUNK.fullmatch(key_expr[len(head):]):
                return key_expr[len(head):]
        return None
