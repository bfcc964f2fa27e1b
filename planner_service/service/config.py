"""The service's configuration: a TOML file, every key with a default, overridable on the
command line with ``--set section.key=value``.

Sections are frozen dataclasses; ``load_config`` reads the file, applies the overrides and
validates everything, so that a bad value is refused at start with the key that holds it,
never half-way through a sortie. ``docs/planner.example.toml`` documents every key.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Mapping

from protocol import Area, GeoOrigin, Keys, ProtocolError
from protocol.errors import SigningError
from protocol.signing import default_timestamp_path, load_key
from protocol.zenoh_config import endpoint_problem

from ..model import Scenario, ScenarioError, preset
from .errors import ConfigError

ZENOH_MODES = ("peer", "client", "router")
BACKENDS = ("pymavlink", "mavsdk")
MAVLINK_SCHEMES = ("udpin", "udpout", "udp", "udpbcast", "tcp", "tcpin")
"""pymavlink's network connection strings, SCHEME:HOST:PORT (``udp`` listens, as udpin)."""
MAVSDK_SCHEMES = ("udpin", "udpout", "tcpin", "tcpout", "serial")
"""MAVSDK's own SCHEME://... forms, taken as they are by the mavsdk backend."""
_HOST_PORT = re.compile(r"(?P<host>[^\s:/,]+):(?P<port>[0-9]{1,5})")
_SERIAL = re.compile(r"(?P<device>/[^\s,]+|COM[0-9]+)(,(?P<baud>[0-9]{3,7}))?")


@dataclass(frozen=True)
class ZenohConfig:
    mode: str = "peer"
    """peer (default), client (needs ``connect``) or router."""
    listen: tuple[str, ...] = ("tcp/127.0.0.1:7447",)
    """Endpoints this session listens on (loopback by default)."""
    connect: tuple[str, ...] = ()
    """Endpoints of routers or peers to connect to."""
    multicast_scouting: bool = False
    """Off by default: peers are found through the explicit endpoints only."""
    prefix: str = "uavmec"
    """First chunk of every key expression."""
    vehicle: str = "uav1"
    """Second chunk: the vehicle id."""
    status_hz: float = 2.0
    """Rate of the status publication (at least 1 Hz)."""
    max_queries_in_flight: int = 64
    """Queries handed from zenoh's threads to the event loop and not yet answered; one more
    is answered at once "busy: ..." from zenoh's thread (bounds the memory a flood takes)."""
    config_file: str = ""
    """A zenoh configuration file (JSON5) used as the session's base (TLS, access control,
    timeouts); mode, listen, connect and multicast_scouting above are applied on top. Empty:
    zenoh's defaults."""


@dataclass(frozen=True)
class IntakeConfig:
    max_pending_requests: int = 100
    """Pending requests that can be served; beyond it a servable request from a user without
    one is refused "busy: ..." (a user replacing its own pending request is still taken; a
    request of no tasks or one the fairness rule leaves out of the sortie holds no place)."""
    max_users: int = 200
    """Distinct user ids in one sortie; a request from a new id beyond it is refused "full: ..."
    (bounds the journal's users and the planner's size)."""
    max_requests_per_s: float = 50.0
    """Accepted requests per second, over a one-second burst, on the monotonic clock; beyond
    it "busy: ..." (bounds the journal's growth and the fsyncs a flood costs)."""


@dataclass(frozen=True)
class MavlinkConfig:
    backend: str = "pymavlink"
    """pymavlink (default) or mavsdk (the native mavsdk 4 binding, mission_raw)."""
    url: str = "udpout:127.0.0.1:14550"
    """pymavlink connection string (udpout:, udpin:, tcp:, serial device); the mavsdk
    backend takes the same string and rewrites it to its own form (udpout://...)."""
    flavour: str = "ardupilot"
    """ardupilot (item 0 is home) or px4."""
    start_mission: bool = False
    """Arm and start the mission once one is uploaded. Off by default: on a real aircraft
    the operator arms; turn it on only where the operator allows it (the stub, SITL)."""
    item_timeout_s: float = 0.5
    """Longest wait for the autopilot's next request or ack before repeating the last
    message (the link waits about four measured round trips when that is shorter)."""
    retries: int = 10
    """Repeats of one message before an upload is given up."""
    link_timeout_s: float = 3.0
    """Silence (no message at all) after which the link counts as lost."""
    source_system: int = 255
    source_component: int = 190
    max_mission_items: int = 512
    """The autopilot's mission capacity: a plan of more items is refused before upload
    (``protocol.validate_mission``). ArduPilot's depends on its storage; the stub's is
    ``--max-mission-items``."""
    signing_key_file: str = ""
    """MAVLink 2 signing: sign every message with the key in this file (64 hex characters,
    mode 0600; ``keygen`` makes one) and accept only correctly signed ones. Empty: off.
    Needs the pymavlink backend."""
    signing_timestamp_file: str = ""
    """Where the last signing timestamp is kept so that a restart never reuses one; empty:
    beside the key (KEY.service-timestamp)."""


FLIGHT_ALGOS = ("mcts", "greedy", "random", "ts-mcts", "mcts-paper")
"""The algorithms the service can fly (``planner.algo``); the learners (``ql``, ``dqn``)
train before a sortie and are not among them."""


@dataclass(frozen=True)
class PlannerConfig:
    algo: str = "mcts"
    """The algorithm flown: ``mcts`` (default), ``greedy``, ``random``, ``ts-mcts`` or
    ``mcts-paper`` (``FLIGHT_ALGOS``)."""
    budget_ms: float = 200.0
    """Wall-clock budget of one MCTS decision (``mcts``)."""
    iterations: int = 0
    """Iteration cap per decision; 0: the budget alone decides. ``mcts-paper`` and
    ``ts-mcts`` run this many iterations, 0 meaning the paper's 1000."""
    seed: int = 0
    """Seed of the planner's random generator."""
    min_requests: int = 1
    """Pending requests needed before the first plan of a sortie."""
    max_failures: int = 8
    """Failed plans or uploads in a row after which the service stops trying (and says so)
    until the link, a request or the operator changes something; each retry waits twice as
    long as the last, from 1 s up to 30 s."""
    replan_min_interval_s: float = 1.0
    """Least wall time between two re-plans caused by new requests (re-plans at a
    hovering point are never delayed); 0 re-plans on every request."""


@dataclass(frozen=True)
class JournalConfig:
    path: str = "planner-journal.sqlite"
    """SQLite file (WAL); a restart with the same file resumes the sortie."""
    synchronous: str = "FULL"
    """SQLite synchronous level: FULL syncs every accepted request to disk before the ack."""


@dataclass(frozen=True)
class OriginConfig:
    lat_deg: float = 47.397742
    lon_deg: float = 8.545594
    alt_m: float = 488.0
    """The geodetic point that is local (0, 0, 0) (default: PX4 SITL's home)."""


@dataclass(frozen=True)
class SafetyConfig:
    area_side_m: float = 500.0
    """Every waypoint and request inside [0, side]^2 local metres."""
    max_altitude_m: float = 120.0
    min_flight_altitude_m: float = 10.0
    rtl_battery_fraction: float = 0.1
    """Command return to launch when the battery fraction reaches this (airborne)."""
    hold_radius_m: float = 5.0
    """A service counts only while the vehicle's own position is within this distance of
    its hovering point (ArduPilot's WPNAV_RADIUS is 2 m; GPS wanders about a metre)."""
    hold_margin_s: float = 1.0
    """Each planned hold is this much longer than the upload needs: the service ends a hold
    itself once the vehicle's position reports show it; the autopilot's hold is the ceiling."""
    energy_margin_j: float = 1000.0
    """Kept back from every plan on top of the model's reserve and the landing descent,
    for what the model does not see (wind, an estimate's error)."""


@dataclass(frozen=True)
class SortieConfig:
    repeat: bool = True
    """After a landing, begin the next sortie once the vehicle is ready again; false: one
    sortie per journal, the intake stays closed after the landing."""
    next_battery_fraction: float = 0.95
    """The next sortie begins when the vehicle is on the ground, disarmed and its battery
    is back at or above this fraction (swapped or charged)."""


@dataclass(frozen=True)
class ServiceConfig:
    zenoh: ZenohConfig = field(default_factory=ZenohConfig)
    intake: IntakeConfig = field(default_factory=IntakeConfig)
    mavlink: MavlinkConfig = field(default_factory=MavlinkConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    journal: JournalConfig = field(default_factory=JournalConfig)
    origin: OriginConfig = field(default_factory=OriginConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    sortie: SortieConfig = field(default_factory=SortieConfig)
    scenario_preset: str = "field"
    scenario_overrides: tuple[tuple[str, Any], ...] = ()
    """(name, value) pairs from the [scenario] section besides ``preset``."""

    def scenario(self) -> Scenario:
        """The planning scenario: the preset with the configured overrides."""
        try:
            base = preset(self.scenario_preset)
            return base.with_overrides({k: v if isinstance(v, str) else _text(v) for k, v in self.scenario_overrides})
        except ScenarioError as err:
            raise ConfigError(f"scenario.{err.field}", str(err)) from None

    def scenario_arguments(self) -> list[str]:
        """The scenario as ``sim_bridge users`` takes it: ``--preset NAME`` and a
        ``--set NAME=VALUE`` for each override (so the users draw from the same model)."""
        out = ["--preset", self.scenario_preset]
        for name, value in self.scenario_overrides:
            out += ["--set", f"{name}={value if isinstance(value, str) else _text(value)}"]
        return out

    def area(self) -> Area:
        s = self.safety
        return Area(s.area_side_m, s.max_altitude_m, s.min_flight_altitude_m)

    def origin_point(self) -> GeoOrigin:
        return GeoOrigin(self.origin.lat_deg, self.origin.lon_deg, self.origin.alt_m)

    def keys(self) -> Keys:
        return Keys(self.zenoh.prefix, self.zenoh.vehicle)


_SECTIONS = {"zenoh": ZenohConfig, "intake": IntakeConfig, "mavlink": MavlinkConfig, "planner": PlannerConfig,
             "journal": JournalConfig, "origin": OriginConfig, "safety": SafetyConfig, "sortie": SortieConfig}


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return ",".join(str(v) for v in value)
    return str(value)


def _coerce(key: str, current: Any, value: Any) -> Any:
    """``value`` (from TOML or a ``--set`` string) as the type of the default ``current``."""
    try:
        if isinstance(current, bool):
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text not in ("true", "false", "1", "0", "yes", "no", "on", "off"):
                raise ValueError
            return text in ("true", "1", "yes", "on")
        if isinstance(current, int):
            if isinstance(value, bool) or (isinstance(value, float) and not value.is_integer()):
                raise ValueError
            return int(value)
        if isinstance(current, float):
            if isinstance(value, bool):
                raise ValueError
            number = float(value)
            if not math.isfinite(number):
                raise ValueError
            return number
        if isinstance(current, tuple):
            if isinstance(value, str):
                return tuple(part.strip() for part in value.split(",") if part.strip())
            if isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
                return tuple(value)
            raise ValueError
        if isinstance(current, str):
            if not isinstance(value, str):
                raise ValueError
            return value
    except (TypeError, ValueError):
        raise ConfigError(key, f"cannot read {value!r} as {type(current).__name__}") from None
    return value


def _apply(raw: dict[str, dict[str, Any]], overrides: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    merged = {section: dict(values) for section, values in raw.items()}
    for dotted, value in overrides.items():
        section, _, key = dotted.partition(".")
        if not key:
            raise ConfigError(dotted, "an override is section.key=value")
        merged.setdefault(section, {})[key] = value
    return merged


def parse_overrides(items: list[str]) -> dict[str, str]:
    """``["zenoh.mode=client", ...]`` -> {"zenoh.mode": "client"}."""
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(item, "an override is section.key=value")
        out[key.strip()] = value.strip()
    return out


def build_config(raw: Mapping[str, Any], overrides: Mapping[str, Any] | None = None) -> ServiceConfig:
    """A validated ``ServiceConfig`` from parsed TOML and ``section.key`` overrides."""
    for section, values in raw.items():
        if section != "scenario" and section not in _SECTIONS:
            raise ConfigError(section, f"unknown section; expected one of {sorted([*_SECTIONS, 'scenario'])}")
        if not isinstance(values, dict):
            raise ConfigError(section, "must be a table")
    merged = _apply({k: v for k, v in raw.items()}, overrides or {})
    sections: dict[str, Any] = {}
    for name, cls in _SECTIONS.items():
        values = merged.get(name, {})
        defaults = cls()
        known = {f.name for f in fields(cls)}
        kwargs: dict[str, Any] = {}
        for key, value in values.items():
            if key not in known:
                raise ConfigError(f"{name}.{key}", f"unknown key; expected one of {sorted(known)}")
            kwargs[key] = _coerce(f"{name}.{key}", getattr(defaults, key), value)
        sections[name] = dataclasses.replace(defaults, **kwargs)
    for name in merged:
        if name not in _SECTIONS and name != "scenario":
            raise ConfigError(name, f"unknown section; expected one of {sorted([*_SECTIONS, 'scenario'])}")
    scenario = dict(merged.get("scenario", {}))
    preset_name = scenario.pop("preset", "field")
    if not isinstance(preset_name, str):
        raise ConfigError("scenario.preset", "must be a string")
    config = ServiceConfig(**sections, scenario_preset=preset_name,
                           scenario_overrides=tuple(sorted(scenario.items())))
    validate(config)
    return config


def load_config(path: str | Path | None, overrides: Mapping[str, Any] | None = None) -> ServiceConfig:
    """Read ``path`` (TOML; None: only defaults) and apply ``overrides``."""
    raw: dict[str, Any] = {}
    if path is not None:
        try:
            with open(path, "rb") as handle:
                raw = tomllib.load(handle)
        except OSError as err:
            raise ConfigError("config", f"cannot read {path}: {err.strerror or err}") from None
        except tomllib.TOMLDecodeError as err:
            raise ConfigError("config", f"{path} is not valid TOML: {err}") from None
    return build_config(raw, overrides)


def validate(c: ServiceConfig) -> None:
    """Refuse values the service could not run with; ``ConfigError`` names the key."""
    z, m, p, s = c.zenoh, c.mavlink, c.planner, c.safety
    if z.mode not in ZENOH_MODES:
        raise ConfigError("zenoh.mode", f"{z.mode!r} is not one of {ZENOH_MODES}")
    if z.mode == "client" and not z.connect:
        raise ConfigError("zenoh.connect", "client mode needs at least one endpoint to connect to")
    if not z.status_hz >= 1.0:
        raise ConfigError("zenoh.status_hz", f"must be at least 1 Hz, got {z.status_hz}")
    if z.max_queries_in_flight < 1:
        raise ConfigError("zenoh.max_queries_in_flight", "must be at least 1")
    if z.config_file and not Path(z.config_file).is_file():
        raise ConfigError("zenoh.config_file", f"{z.config_file} is not a readable file")
    for key in ("listen", "connect"):
        for endpoint in getattr(z, key):
            why = endpoint_problem(endpoint)
            if why is not None:
                raise ConfigError(f"zenoh.{key}", why)
    i = c.intake
    if i.max_pending_requests < 1 or i.max_users < 1:
        raise ConfigError("intake", "max_pending_requests and max_users must be at least 1")
    if not i.max_requests_per_s > 0:
        raise ConfigError("intake.max_requests_per_s", "must be positive")
    try:
        c.keys()
    except ProtocolError as err:
        raise ConfigError(f"zenoh.{err.field}", err.message) from None
    if m.backend not in BACKENDS:
        raise ConfigError("mavlink.backend", f"{m.backend!r} is not one of {BACKENDS}")
    why = mavlink_url_problem(m.url, m.backend)
    if why is not None:
        raise ConfigError("mavlink.url", why)
    if m.flavour not in ("ardupilot", "px4"):
        raise ConfigError("mavlink.flavour", f"{m.flavour!r} is not ardupilot or px4")
    for key in ("item_timeout_s", "link_timeout_s"):
        if not getattr(m, key) > 0:
            raise ConfigError(f"mavlink.{key}", "must be positive")
    if m.retries < 1:
        raise ConfigError("mavlink.retries", "must be at least 1")
    if not 3 <= m.max_mission_items <= 65535:  # home, takeoff and RTL; MISSION_COUNT is uint16
        raise ConfigError("mavlink.max_mission_items", f"must lie in 3..65535, got {m.max_mission_items}")
    _validate_signing(m)
    if p.algo not in FLIGHT_ALGOS:
        raise ConfigError("planner.algo", f"{p.algo!r} is not one of {FLIGHT_ALGOS}")
    if not p.budget_ms > 0:
        raise ConfigError("planner.budget_ms", "must be positive")
    if p.iterations < 0 or p.min_requests < 1 or p.replan_min_interval_s < 0:
        raise ConfigError("planner", "iterations >= 0, min_requests >= 1, replan_min_interval_s >= 0")
    if p.min_requests > c.intake.max_pending_requests:
        raise ConfigError("planner.min_requests", f"{p.min_requests} can never be pending: "
                          f"intake.max_pending_requests is {c.intake.max_pending_requests}")
    if c.journal.synchronous.upper() not in ("OFF", "NORMAL", "FULL", "EXTRA"):
        raise ConfigError("journal.synchronous", "must be OFF, NORMAL, FULL or EXTRA")
    if not s.energy_margin_j >= 0:
        raise ConfigError("safety.energy_margin_j", "must not be negative")
    if not 0.5 <= s.hold_radius_m <= 50.0:
        raise ConfigError("safety.hold_radius_m", f"must lie in [0.5, 50] m, got {s.hold_radius_m}")
    if not 0.0 <= s.hold_margin_s <= 30.0:
        raise ConfigError("safety.hold_margin_s", f"must lie in [0, 30] s, got {s.hold_margin_s}")
    if p.max_failures < 1:
        raise ConfigError("planner.max_failures", "must be at least 1")
    if not 0.0 <= s.rtl_battery_fraction < 1.0:
        raise ConfigError("safety.rtl_battery_fraction", "must lie in [0, 1)")
    if not s.rtl_battery_fraction < c.sortie.next_battery_fraction <= 1.0:
        raise ConfigError("sortie.next_battery_fraction", f"must lie in (safety.rtl_battery_fraction = "
                          f"{s.rtl_battery_fraction}, 1]: a sortie must not begin at the return threshold")
    try:
        area = c.area()
        c.origin_point()
    except (ProtocolError, ValueError) as err:
        raise ConfigError("safety" if isinstance(err, ProtocolError) else "origin", str(err)) from None
    scenario = c.scenario()
    if scenario.dimensions != 2:
        raise ConfigError("scenario.preset", "the service flies 2-D scenarios (one altitude)")
    if scenario.area_side_m > area.side_m:
        raise ConfigError("safety.area_side_m", f"the scenario's area ({scenario.area_side_m} m) exceeds the safety area ({area.side_m} m)")
    if not area.min_flight_altitude_m <= scenario.altitude_m <= area.max_altitude_m:
        raise ConfigError("safety.max_altitude_m", f"the scenario's altitude {scenario.altitude_m} m is outside "
                          f"[{area.min_flight_altitude_m}, {area.max_altitude_m}] m")


def mavlink_url_problem(url: str, backend: str) -> str | None:
    """Why ``url`` is not a connection string the backend can open, or None. pymavlink
    takes anything (``bogus:1`` becomes a UDP listener on a host named bogus, and the
    service would wait for an autopilot there for ever); this refuses it at start."""
    forms = ("udpin:HOST:PORT (listen), udpout:HOST:PORT (send), tcp:HOST:PORT, tcpin:HOST:PORT, "
             "or a serial device /dev/ttyX[,BAUD]")
    scheme, sep, rest = url.partition(":")
    if sep and rest.startswith("//"):
        if backend != "mavsdk":
            return f"{url!r}: SCHEME://... is MAVSDK's form (mavlink.backend = mavsdk); pymavlink takes {forms}"
        if scheme not in MAVSDK_SCHEMES:
            return f"{url!r}: {scheme!r} is not one of MAVSDK's {', '.join(MAVSDK_SCHEMES)}"
        address = rest[2:]
        if scheme == "serial":
            device, _, baud = address.partition(":")
            return _serial_problem(url, device, baud)
        return _host_port_problem(url, address, forms)
    if scheme in MAVLINK_SCHEMES and sep:
        return _host_port_problem(url, rest, forms)
    serial = _SERIAL.fullmatch(url)
    if serial is not None:
        return _serial_problem(url, serial.group("device"), serial.group("baud") or "")
    if sep and not url.startswith("/"):
        return f"{url!r} has no known scheme ({scheme!r}); write {forms}"
    return f"{url!r} is not a MAVLink connection: write {forms}"


def _host_port_problem(url: str, address: str, forms: str) -> str | None:
    match = _HOST_PORT.fullmatch(address)
    if match is None:
        return f"{url!r}: after the scheme comes HOST:PORT ({forms})"
    if not 1 <= int(match.group("port")) <= 65535:
        return f"{url!r}: port {int(match.group('port'))} is not in 1..65535"
    return None


def _serial_problem(url: str, device: str, baud: str) -> str | None:
    if baud and not baud.isdigit():
        return f"{url!r}: the baud rate {baud!r} is not a number"
    if device.startswith("/") and not os.path.exists(device):
        return f"{url!r}: no such serial device {device}"
    return None


def _validate_signing(m: MavlinkConfig) -> None:
    """The key must load (exists, 64 hex characters, owner-only) and the timestamp file's
    folder be writable, so that a signing setup that cannot work is refused at start."""
    if not m.signing_key_file:
        if m.signing_timestamp_file:
            raise ConfigError("mavlink.signing_timestamp_file", "set without mavlink.signing_key_file")
        return
    if m.backend != "pymavlink":
        raise ConfigError("mavlink.backend", "signing needs the pymavlink backend: the mavsdk 4 binding has no MAVLink "
                          "signing (mavlink.signing_key_file is set)")
    try:
        load_key(m.signing_key_file)
    except SigningError as err:
        raise ConfigError("mavlink.signing_key_file", str(err)) from None
    stamps = m.signing_timestamp_file or str(default_timestamp_path(m.signing_key_file, "service"))
    folder = os.path.dirname(stamps) or "."
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ConfigError("mavlink.signing_timestamp_file", f"{stamps}: the folder {folder} is missing or not writable "
                          "(the signing timestamp is stored there)")


def to_toml(c: ServiceConfig) -> str:
    """The configuration as TOML (the demo writes the one it runs)."""
    lines: list[str] = []
    for name in _SECTIONS:
        lines.append(f"[{name}]")
        for f in fields(getattr(c, name)):
            lines.append(f"{f.name} = {_toml_value(getattr(getattr(c, name), f.name))}")
        lines.append("")
    lines.append("[scenario]")
    lines.append(f"preset = {_toml_value(c.scenario_preset)}")
    for key, value in c.scenario_overrides:
        lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (tuple, list)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return repr(value)
