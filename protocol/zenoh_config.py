"""The zenoh session configuration of every party (service, clients, routers): an optional
zenoh configuration file (JSON5) as the base, our few keys on top.

The file carries what this project does not model (TLS certificates, ``access_control``,
timeouts, buffer sizes); the mode, endpoints and multicast scouting always come from the
caller, so that one file can be shared by processes that listen or connect differently.
zenoh refuses an unknown key, so a misspelt setting is an error at start, not a silent
default.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Sequence

import zenoh

from .errors import ProtocolError

NO_FILE_RX_MAX_MESSAGE_BYTES = 1 << 20
"""Largest message (after defragmentation) a session without a file accepts; zenoh's own
default is 1 GiB, which lets one query take that much memory before anyone reads it."""

RECONNECT = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}
"""How often a lost ``connect`` endpoint (a restarted router) is tried again, unless the file
sets ``connect/retry``: at most every second, so a router's restart costs about a second
(zenoh's default backs off to 4 s)."""


_SOURCE = re.compile(r" at \S+\.rs:\d+\.?$")


def error_text(err: BaseException) -> str:
    """A zenoh error's message without the Rust source location zenoh appends."""
    return _SOURCE.sub("", str(err).strip())


def session_config(mode: str, listen: Sequence[str] = (), connect: Sequence[str] = (),
                   multicast_scouting: bool = False, config_file: str | Path | None = None) -> zenoh.Config:
    """A zenoh Config: ``config_file`` (or zenoh's defaults) with mode, explicit endpoints and
    multicast scouting on top. ``ProtocolError("config_file", ...)`` if the file is refused."""
    if config_file:
        try:
            conf = zenoh.Config.from_file(str(config_file))
        except (zenoh.ZError, OSError, ValueError) as err:
            raise ProtocolError("config_file", f"{config_file}: {error_text(err)}") from None
    else:
        conf = zenoh.Config()
        conf.insert_json5("transport/link/rx/max_message_size", str(NO_FILE_RX_MAX_MESSAGE_BYTES))
    if json.loads(conf.get_json("connect/retry")) is None:
        conf.insert_json5("connect/retry", json.dumps(RECONNECT))
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5("scouting/multicast/enabled", "true" if multicast_scouting else "false")
    conf.insert_json5("listen/endpoints", json.dumps(list(listen)))
    conf.insert_json5("connect/endpoints", json.dumps(list(connect)))
    return conf
