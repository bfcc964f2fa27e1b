"""The long-running flight-side service: intake, journal, planning, MAVLink link, zenoh."""

from .config import ServiceConfig, load_config, parse_overrides
from .errors import ConfigError, JournalError, LinkError, PlanningError, ServiceError
from .journal import Journal

__all__ = ["ConfigError", "Journal", "JournalError", "LinkError", "PlanningError", "ServiceConfig", "ServiceError",
           "load_config", "parse_overrides"]
