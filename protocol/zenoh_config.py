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

IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
"""zenoh link protocols whose address is HOST:PORT."""
OTHER_PROTOCOLS = ("unixsock-stream", "unixpipe", "vsock", "serial")
_ENDPOINT = re.compile(r"(?P<protocol>[a-z][a-z0-9-]*)/(?P<address>[^?#]+)(\?[^#]*)?(#.*)?", re.S)
_HOST_PORT = re.compile(r"(?P<host>\[[0-9A-Fa-f:.%a-zA-Z]+\]|[^\s:\[\]/]+):(?P<port>[0-9]{1,5})")


def endpoint_problem(text: str) -> str | None:
    """Why ``text`` is not a zenoh endpoint, or None. zenoh itself checks only the
    ``<protocol>/<address>`` shape when configured and says the rest when the session
    opens (as a multi-line Rust error); this says it at once, in words."""
    match = _ENDPOINT.fullmatch(text) if isinstance(text, str) else None
    example = "e.g. tcp/127.0.0.1:7447 or tls/uav1.local:7447"
    if match is None:
        return f"{text!r} is not a zenoh endpoint (<protocol>/<address>, {example})"
    protocol, address = match.group("protocol"), match.group("address")
    if protocol not in IP_PROTOCOLS + OTHER_PROTOCOLS:
        return (f"{text!r}: {protocol!r} is not a zenoh link protocol "
                f"(one of {', '.join(IP_PROTOCOLS + OTHER_PROTOCOLS)})")
    if protocol in IP_PROTOCOLS:
        hp = _HOST_PORT.fullmatch(address)
        if hp is None:
            return f"{text!r}: the address must be HOST:PORT ({example})"
        if not 1 <= int(hp.group("port")) <= 65535:
            return f"{text!r}: port {int(hp.group('port'))} is not in 1..65535"
    return None


def check_endpoints(option: str, endpoints: Sequence[str]) -> None:
    """``ProtocolError(option, why)`` for the first endpoint that is not one."""
    for endpoint in endpoints:
        why = endpoint_problem(endpoint)
        if why is not None:
            raise ProtocolError(option, why)


def error_text(err: BaseException) -> str:
    """A zenoh error's message without the Rust source location zenoh appends."""
    return _SOURCE.sub("", str(err).strip())


def session_config(mode: str, listen: Sequence[str] = (), connect: Sequence[str] = (),
                   multicast_scouting: bool = False, config_file: str | Path | None = None) -> zenoh.Config:
    """A zenoh Config: ``config_file`` (or zenoh's defaults) with mode, explicit endpoints and
    multicast scouting on top. ``ProtocolError("config_file", ...)`` if the file is refused,
    ``ProtocolError("listen" or "connect", ...)`` for an endpoint that is not one."""
    check_endpoints("listen", listen)
    check_endpoints("connect", connect)
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


def access_control_closed(config_file: str | Path | None) -> bool:
    """Does ``config_file`` turn zenoh's access control on with everything not allowed
    denied (``access_control.enabled: true``, ``default_permission: "deny"``)? Only then
    can its rules (not the service) decide who may query a key. False without a file;
    ``ProtocolError("config_file", ...)`` if the file is refused."""
    if not config_file:
        return False
    conf = session_config("peer", config_file=config_file)
    enabled = json.loads(conf.get_json("access_control/enabled"))
    default = json.loads(conf.get_json("access_control/default_permission"))
    return enabled is True and default == "deny"
