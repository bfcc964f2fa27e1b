"""The service's exceptions: one per subsystem, each carrying what failed and why."""

from __future__ import annotations


class ServiceError(Exception):
    """Base of the service's errors."""


class ConfigError(ServiceError):
    """A configuration value was refused; ``key`` names it (``section.key``)."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"{key}: {message}")
        self.key = key
        self.message = message


class JournalError(ServiceError):
    """The journal could not be opened, read or written."""


class PlanningError(ServiceError):
    """A plan failed a safety check (``check`` names which) and was not flown."""

    def __init__(self, check: str, message: str) -> None:
        super().__init__(f"{check}: {message}")
        self.check = check
        self.message = message


class LinkError(ServiceError):
    """A MAVLink operation failed: ``operation`` says what was attempted, ``result`` the
    autopilot's answer (a MAV_MISSION_RESULT / MAV_RESULT name) or why there was none.
    ``outcome_unknown``: an upload whose last item was sent but never acknowledged, and
    the mission held could not be read back either; the autopilot may hold either one."""

    def __init__(self, operation: str, result: str, outcome_unknown: bool = False) -> None:
        super().__init__(f"{operation}: {result}")
        self.operation = operation
        self.result = result
        self.outcome_unknown = outcome_unknown
