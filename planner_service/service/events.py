"""What the service tells on its events key: one frozen dataclass per kind, so a typo is a
name error and not an event nobody hears. Each carries its wire ``kind`` (``EventKind`` in
protocol/messages.py, which decoders check); ``to_wire`` makes the ``Event`` message.
``KINDS`` lists them all: tests derive their lists from it, so they cannot drift."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from protocol import Event
from protocol.messages import EventKind
from protocol.text import printable

DETAIL_CHARS = 256


@dataclass(frozen=True)
class ServiceEvent:
    kind: ClassVar[EventKind]
    detail: str = ""
    user_id: str | None = None
    request_id: int | None = None


@dataclass(frozen=True)
class RequestAccepted(ServiceEvent):
    kind: ClassVar[EventKind] = "request_accepted"


@dataclass(frozen=True)
class RequestRejected(ServiceEvent):
    kind: ClassVar[EventKind] = "request_rejected"


@dataclass(frozen=True)
class MissionUploaded(ServiceEvent):
    kind: ClassVar[EventKind] = "mission_uploaded"


@dataclass(frozen=True)
class UploadFailed(ServiceEvent):
    kind: ClassVar[EventKind] = "upload_failed"


@dataclass(frozen=True)
class UploadAbandoned(ServiceEvent):
    kind: ClassVar[EventKind] = "upload_abandoned"


@dataclass(frozen=True)
class UserServed(ServiceEvent):
    kind: ClassVar[EventKind] = "user_served"


@dataclass(frozen=True)
class WaypointReached(ServiceEvent):
    kind: ClassVar[EventKind] = "waypoint_reached"


@dataclass(frozen=True)
class WaypointSkipped(ServiceEvent):
    kind: ClassVar[EventKind] = "waypoint_skipped"


@dataclass(frozen=True)
class Returning(ServiceEvent):
    kind: ClassVar[EventKind] = "returning"


@dataclass(frozen=True)
class Landed(ServiceEvent):
    kind: ClassVar[EventKind] = "landed"


@dataclass(frozen=True)
class LinkLost(ServiceEvent):
    kind: ClassVar[EventKind] = "link_lost"


@dataclass(frozen=True)
class LinkRestored(ServiceEvent):
    kind: ClassVar[EventKind] = "link_restored"


@dataclass(frozen=True)
class VehicleRestarted(ServiceEvent):
    kind: ClassVar[EventKind] = "vehicle_restarted"


@dataclass(frozen=True)
class MissionResumed(ServiceEvent):
    kind: ClassVar[EventKind] = "mission_resumed"


@dataclass(frozen=True)
class ResumeNeeded(ServiceEvent):
    kind: ClassVar[EventKind] = "resume_needed"


@dataclass(frozen=True)
class SortieStarted(ServiceEvent):
    kind: ClassVar[EventKind] = "sortie_started"


@dataclass(frozen=True)
class CommandFailed(ServiceEvent):
    kind: ClassVar[EventKind] = "command_failed"


@dataclass(frozen=True)
class AuthorityGranted(ServiceEvent):
    kind: ClassVar[EventKind] = "authority_granted"


@dataclass(frozen=True)
class AuthorityRevoked(ServiceEvent):
    kind: ClassVar[EventKind] = "authority_revoked"


@dataclass(frozen=True)
class AuthorityReleased(ServiceEvent):
    kind: ClassVar[EventKind] = "authority_released"


@dataclass(frozen=True)
class Degraded(ServiceEvent):
    kind: ClassVar[EventKind] = "degraded"


@dataclass(frozen=True)
class PlanUpdated(ServiceEvent):
    kind: ClassVar[EventKind] = "plan_updated"


KINDS: dict[str, type[ServiceEvent]] = {cls.kind: cls for cls in ServiceEvent.__subclasses__()}
"""Every event by its wire kind (tests check these are exactly protocol's ``EventKind``)."""


def to_wire(event: ServiceEvent, time_s: float) -> Event:
    """The ``Event`` message of ``event`` (its detail escaped and bounded)."""
    return Event(event=event.kind, time_s=time_s, user_id=event.user_id, request_id=event.request_id,
                 detail=printable(event.detail, DETAIL_CHARS) if event.detail else "")
