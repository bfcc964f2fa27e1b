"""The service's configuration: a TOML file, every key with a default, overridable on the
command line with ``--set section.key=value``.

Sections are frozen dataclasses whose fields are read by their annotations
(``planner_service.settings``: the same booleans, lists and choices as the scenario's
``--set``), each bound beside its field and checked when a section is built; a section's
``check`` holds the rules between its fields (and the files they name), ``ServiceConfig.check``
those between sections. ``load_config`` reads the file, applies the overrides and checks
everything, so that a bad value is refused at start with the key that holds it, never
half-way through a sortie. ``docs/planner.example.toml`` documents every key with its
default (a test holds it to this file).
"""

from __future__ import annotations

import os
import re
import tomllib
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, ClassVar, Literal, Mapping, get_args

from protocol import Area, GeoOrigin, Keys, ProtocolError
from protocol.errors import MissionError, SigningError
from protocol.fleet_signing import load_private_key, public_hex, read_roster
from protocol.mission import Flavour
from protocol.signing import default_timestamp_path, load_key
from protocol.zenoh_config import access_control_closed, endpoint_problem

from ..model import Scenario, ScenarioError, preset
from ..model.presets import Preset
from ..settings import SettingError, check_fields, kinds, read, read_fields, setting, split_assignment, toml_value
from .errors import ConfigError

ZenohMode = Literal["peer", "client", "router"]
Backend = Literal["pymavlink", "mavsdk"]
FlightAlgo = Literal["mcts", "greedy", "random", "ts-mcts", "mcts-paper"]
"""The algorithms the service can fly (``planner.algo``); the learners (``ql``, ``dqn``)
train before a sortie and are not among them."""
SyncLevel = Literal["OFF", "NORMAL", "FULL", "EXTRA"]
ZENOH_MODES: tuple[str, ...] = get_args(ZenohMode)
BACKENDS: tuple[str, ...] = get_args(Backend)
FLIGHT_ALGOS: tuple[str, ...] = get_args(FlightAlgo)
MAVLINK_SCHEMES = ("udpin", "udpout", "udp", "udpbcast", "tcp", "tcpin")
"""pymavlink's network connection strings, SCHEME:HOST:PORT (``udp`` listens, as udpin)."""
MAVSDK_SCHEMES = ("udpin", "udpout", "tcpin", "tcpout", "serial")
"""MAVSDK's own SCHEME://... forms, taken as they are by the mavsdk backend."""
_HOST_PORT = re.compile(r"(?P<host>[^\s:/,]+):(?P<port>[0-9]{1,5})")
_SERIAL = re.compile(r"(?P<device>/[^\s,]+|COM[0-9]+)(,(?P<baud>[0-9]{3,7}))?")


class Section:
    """A section of the configuration (a TOML table). Its fields are checked against their
    choices and bounds when it is built; ``check`` holds the rules between them."""

    section: ClassVar[str]
    """The TOML table's name: errors name ``section.key``."""

    def __post_init__(self) -> None:
        try:
            check_fields(self)
        except SettingError as err:
            raise ConfigError(f"{self.section}.{err.name}", err.message) from None

    def check(self) -> None:
        """Rules between the section's fields, and the files they name (none by default)."""


@dataclass(frozen=True)
class ZenohConfig(Section):
    section: ClassVar[str] = "zenoh"

    mode: ZenohMode = "peer"
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
    status_hz: float = setting(2.0, ge=1.0, unit="Hz")
    """Rate of the status publication (at least 1 Hz)."""
    max_queries_in_flight: int = setting(64, ge=1)
    """Queries handed from zenoh's threads to the event loop and not yet answered; one more
    is answered at once "busy: ..." from zenoh's thread (bounds the memory a flood takes)."""
    config_file: str = ""
    """A zenoh configuration file (JSON5) used as the session's base (TLS, access control,
    timeouts); mode, listen, connect and multicast_scouting above are applied on top. Empty:
    zenoh's defaults."""

    def check(self) -> None:
        if self.mode == "client" and not self.connect:
            raise ConfigError("zenoh.connect", "client mode needs at least one endpoint to connect to")
        for key in ("listen", "connect"):
            for endpoint in getattr(self, key):
                why = endpoint_problem(endpoint)
                if why is not None:
                    raise ConfigError(f"zenoh.{key}", why)
        try:
            Keys(self.prefix, self.vehicle)
        except ProtocolError as err:
            raise ConfigError(f"zenoh.{err.field}", err.message) from None
        if self.config_file and not Path(self.config_file).is_file():
            raise ConfigError("zenoh.config_file", f"{self.config_file} is not a readable file")


@dataclass(frozen=True)
class IntakeConfig(Section):
    section: ClassVar[str] = "intake"

    max_pending_requests: int = setting(100, ge=1)
    """Pending requests that can be served; beyond it a servable request from a user without
    one is refused "busy: ..." (a user replacing its own pending request is still taken; a
    request of no tasks or one the fairness rule leaves out of the sortie holds no place)."""
    max_users: int = setting(200, ge=1)
    """Distinct user ids that hold a place in one sortie; beyond it a servable request from a
    new id is refused "full: ..." (bounds the planner's size). A user takes a place with its
    first request that can be served: a request of no tasks or one the fairness rule leaves
    out of the sortie holds none, and is taken even when the bound is reached."""
    max_requests_per_s: float = setting(50.0, gt=0)
    """Accepted requests per second, over a one-second burst, on the monotonic clock; beyond
    it "busy: ..." (bounds the journal's growth and the fsyncs a flood costs)."""


@dataclass(frozen=True)
class MavlinkConfig(Section):
    section: ClassVar[str] = "mavlink"

    backend: Backend = "pymavlink"
    """pymavlink (default) or mavsdk (the native mavsdk 4 binding, mission_raw)."""
    url: str = "udpout:127.0.0.1:14550"
    """pymavlink connection string (udpout:, udpin:, tcp:, serial device); the mavsdk
    backend takes the same string and rewrites it to its own form (udpout://...)."""
    flavour: Flavour = "ardupilot"
    """ardupilot (item 0 is home) or px4."""
    start_mission: bool = False
    """Arm and start the mission once one is uploaded, in the first sortie the process
    flies (later sorties wait for the operator's start). Off by default: on a real
    aircraft the operator arms; turn it on only where the operator allows it (the stub,
    SITL)."""
    item_timeout_s: float = setting(0.5, gt=0)
    """Longest wait for the autopilot's next request or ack before repeating the last
    message (the link waits about four measured round trips when that is shorter)."""
    retries: int = setting(10, ge=1)
    """Repeats of one message before an upload is given up."""
    link_timeout_s: float = setting(3.0, gt=0)
    """Silence (no message at all) after which the link counts as lost."""
    source_system: int = 255
    source_component: int = 190
    max_mission_items: int = setting(512, ge=3, le=65535,
                                     why="home, takeoff and return to launch take 3; MISSION_COUNT is a uint16")
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

    def check(self) -> None:
        why = mavlink_url_problem(self.url, self.backend)
        if why is not None:
            raise ConfigError("mavlink.url", why)
        self._check_signing()

    def _check_signing(self) -> None:
        """The key must load (exists, 64 hex characters, owner-only) and the timestamp file's
        folder be writable, so that a signing setup that cannot work is refused at start."""
        if not self.signing_key_file:
            if self.signing_timestamp_file:
                raise ConfigError("mavlink.signing_timestamp_file", "set without mavlink.signing_key_file")
            return
        if self.backend != "pymavlink":
            raise ConfigError("mavlink.backend", "signing needs the pymavlink backend: the mavsdk 4 binding has no "
                              "MAVLink signing (mavlink.signing_key_file is set)")
        try:
            load_key(self.signing_key_file)
        except SigningError as err:
            raise ConfigError("mavlink.signing_key_file", str(err)) from None
        stamps = self.signing_timestamp_file or str(default_timestamp_path(self.signing_key_file, "service"))
        folder = os.path.dirname(stamps) or "."
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ConfigError("mavlink.signing_timestamp_file", f"{stamps}: the folder {folder} is missing or not "
                              "writable (the signing timestamp is stored there)")


@dataclass(frozen=True)
class PlannerConfig(Section):
    section: ClassVar[str] = "planner"

    algo: FlightAlgo = "mcts"
    """The algorithm flown: ``mcts`` (default), ``greedy``, ``random``, ``ts-mcts`` or
    ``mcts-paper`` (``FLIGHT_ALGOS``)."""
    budget_ms: float = setting(200.0, gt=0)
    """Wall-clock budget of one MCTS decision (``mcts``)."""
    iterations: int = setting(0, ge=0)
    """Iteration cap per decision; 0: the budget alone decides. ``mcts-paper`` and
    ``ts-mcts`` run this many iterations, 0 meaning the paper's 1000."""
    seed: int = 0
    """Seed of the planner's random generator."""
    min_requests: int = setting(1, ge=1)
    """Pending requests needed before the first plan of a sortie."""
    max_failures: int = setting(8, ge=1)
    """Failed plans or uploads in a row after which the service stops trying (and says so)
    until the link, a request or the operator changes something; each retry waits twice as
    long as the last, from 1 s up to 30 s."""
    replan_min_interval_s: float = setting(1.0, ge=0)
    """Least wall time between two re-plans caused by new requests (re-plans at a
    hovering point are never delayed); 0 re-plans on every request."""


@dataclass(frozen=True)
class JournalConfig(Section):
    section: ClassVar[str] = "journal"

    path: str = "planner-journal.sqlite"
    """SQLite file (WAL); a restart with the same file resumes the sortie."""
    synchronous: SyncLevel = "FULL"
    """SQLite synchronous level: FULL syncs every accepted request to disk before the ack."""


@dataclass(frozen=True)
class OriginConfig(Section):
    section: ClassVar[str] = "origin"

    lat_deg: float = 47.397742
    lon_deg: float = 8.545594
    alt_m: float = 488.0
    """The geodetic point that is local (0, 0, 0) (default: PX4 SITL's home)."""

    def check(self) -> None:
        try:
            self.point()
        except MissionError as err:  # its bounds are the protocol's: it names the field
            raise ConfigError(err.where, err.message) from None

    def point(self) -> GeoOrigin:
        return GeoOrigin(self.lat_deg, self.lon_deg, self.alt_m)


_AREA_KEYS = {"side_m": "area_side_m", "max_altitude_m": "max_altitude_m",
              "min_flight_altitude_m": "min_flight_altitude_m"}


@dataclass(frozen=True)
class SafetyConfig(Section):
    section: ClassVar[str] = "safety"

    area_side_m: float = 500.0
    """Every waypoint and request inside [0, side]^2 local metres."""
    max_altitude_m: float = 120.0
    min_flight_altitude_m: float = 10.0
    rtl_battery_fraction: float = setting(0.1, ge=0, lt=1)
    """Command return to launch when the battery fraction reaches this (airborne)."""
    hold_radius_m: float = setting(5.0, ge=0.5, le=50.0, unit="m")
    """A service counts only while the vehicle's own position is within this distance of
    its hovering point (ArduPilot's WPNAV_RADIUS is 2 m; GPS wanders about a metre)."""
    hold_margin_s: float = setting(1.0, ge=0.0, le=30.0, unit="s")
    """Each planned hold is this much longer than the upload needs: the service ends a hold
    itself once the vehicle's position reports show it; the autopilot's hold is the ceiling."""
    energy_margin_j: float = setting(1000.0, ge=0)
    """Kept back from every plan on top of the model's reserve and the landing descent,
    for what the model does not see (wind, an estimate's error)."""

    def check(self) -> None:
        try:
            self.area()
        except ProtocolError as err:  # its bounds are the protocol's: name our key for its field
            raise ConfigError(f"safety.{_AREA_KEYS.get(err.field, err.field)}", err.message) from None

    def area(self) -> Area:
        return Area(self.area_side_m, self.max_altitude_m, self.min_flight_altitude_m)


@dataclass(frozen=True)
class SortieConfig(Section):
    section: ClassVar[str] = "sortie"

    repeat: bool = True
    """After a landing, begin the next sortie once the vehicle is ready again; false: one
    sortie per journal, the intake stays closed after the landing."""
    next_battery_fraction: float = setting(0.95, gt=0, le=1)
    """The next sortie begins when the vehicle is on the ground, disarmed and its battery
    is back at or above this fraction (swapped or charged); above
    ``safety.rtl_battery_fraction`` (``ServiceConfig.check``)."""
    readback_interval_s: float = setting(30.0, ge=0)
    """Wall seconds between read-backs of the mission the service flies under authority,
    compared item by item with the one it uploaded: another station's mission that no
    report shows (ArduPilot names no mission; one of the same length keeps the count) ends
    the authority within this; 0: no periodic read-back (a disagreement still reads back
    at once)."""
    leg_tolerance_m: float = setting(30.0, ge=0)
    """How far (m, horizontally) the vehicle may stray from the leg it flies to a point of
    ours (from where it began that item to the point) for three reports in a row before the
    mission is read back: another station's mission of the same length flies elsewhere;
    0: not checked."""


ProofRule = Literal["auto", "always"]
OPERATOR_KEY_NAME = "operator.key"
"""The operator key's file name beside the journal (``operator.key_file`` empty)."""


@dataclass(frozen=True)
class OperatorConfig(Section):
    """Who may send the operator's commands (docs/SERVICE.md, "The operator's key")."""

    section: ClassVar[str] = "operator"

    proof: ProofRule = "auto"
    """``auto``: every operator command must carry the proof of the operator key unless
    ``zenoh.config_file`` turns zenoh's access control on with default_permission "deny"
    (its rules then say who may query the operator key: the shipped ones, operator
    certificates only); ``always``: the proof is needed under access control too."""
    key_file: str = ""
    """The operator key (64 hex characters, mode 0600), made by the service at start when
    absent; a file that its group or others may read is refused. Empty: ``operator.key``
    beside the journal."""
    proof_window_s: float = setting(30.0, gt=0, le=300.0, unit="s")
    """A command's ``sent_at_ms`` must lie this close to the service's clock (either way);
    its client_ref is refused again for twice this long (replays)."""


@dataclass(frozen=True)
class MembershipConfig(Section):
    """Membership of a fleet of UAVs, one service each, under ``zenoh.prefix`` (docs/OPERATIONS.md,
    "A fleet"). The UAV's altitude layer is its scenario's ``altitude_m``."""

    section: ClassVar[str] = "fleet"

    enabled: bool = False
    """Join the fleet: announce this UAV's layer and hold a member's token; refuse to start
    when another member is this vehicle, flies a layer within ``vertical_separation_m`` +
    ``altitude_margin_m``, or has a clock more than ``max_clock_offset_s`` off."""
    vertical_separation_m: float = setting(10.0, gt=0, unit="m")
    """Two armed UAVs closer than this vertically, and closer than ``min_horizontal_m``
    horizontally, have lost separation (judged on their own positions; logged as an error)."""
    altitude_margin_m: float = setting(5.0, ge=0, unit="m")
    """What two UAVs' altitude errors may add up to: layers are kept ``vertical_separation_m``
    plus this apart (the larger of the two members' sums applies; docs/OPERATIONS.md)."""
    min_horizontal_m: float = setting(20.0, gt=0, unit="m")
    """Two armed UAVs closer than this horizontally, and vertically closer than
    ``vertical_separation_m``, have lost separation."""
    max_clock_offset_s: float = setting(2.0, gt=0, le=4.0, unit="s")
    """How far another member's clock may read from this computer's: a service refuses to join
    beside one further off, and logs an error when a member drifts beyond it (the members
    compare signed times with their own clocks; 4 s at most: a message signed more than 5 s
    ahead of a reader is refused)."""
    position_stale_s: float = setting(3.0, gt=0, unit="s")
    """A member's position older than this is unknown (logged): never taken as separated."""
    discovery_s: float = setting(3.0, gt=0, le=60.0, unit="s")
    """How long a joining service waits for the mesh to tell it of every member (then for
    their layers until each is read: 5 s at most, or this if longer) before it judges the
    separation and goes on."""
    key_file: str = ""
    """This vehicle's fleet signing key (Ed25519, mode 0600: ``python -m planner_service
    fleet-key``); every fleet message it sends is signed with it. Required with ``enabled``."""
    roster_file: str = ""
    """The fleet's roster: ``VEHICLE PUBLIC-KEY`` per line, every enrolled member's; a
    message from any other is ignored and counted. Required with ``enabled``."""
    insecure: bool = False
    """Fly a fleet over zenoh endpoints that are neither loopback nor TLS with access control
    (``zenoh.config_file``): refused without this (any peer could then put what it likes on
    the fleet's keys; the signatures stop it speaking for a member, not reading or flooding)."""
    max_layer_gap_m: float = setting(100.0, gt=0, unit="m")
    """A member announcing a layer gap above this is refused and ignored (a gap of 1e9 m would
    bar every other member)."""
    lost_airspace_s: float = setting(1800.0, gt=0, unit="s")
    """How long a member gone with its vehicle armed keeps its airspace (its route, its
    unknown separation): at most a sortie's flight on one battery."""
    answer_step_s: float = setting(2.0, ge=0, le=30.0, unit="s")
    """Of the members on their way home, the one nearest to a new request answers it first;
    each other waits this long (wall clock) for each member nearer than it, so that their
    claims are heard before its turn (a planning, an upload and a radio's hearing delay;
    0: all answer at once)."""
    answer_tie_m: float = setting(50.0, ge=0, unit="m")
    """Members whose distances to the pending users differ by at most this (what a position a
    report late may be off) answer in the order of their vehicle ids."""
    occupied_m: float = setting(10.0, ge=0, le=100.0, unit="m")
    """A hovering point another member's vehicle is within this of horizontally (by its signed
    position, whatever its layer) is planned without, whatever was heard of that member's
    claims (a claim may come seconds late; its positions come twice a second). 0: off."""
    max_answer_rank: int = setting(3, ge=0, le=20)
    """At most this many steps are waited, whatever the number of nearer members (one may be
    unable to answer: its battery, its plan)."""
    settle_max_s: float = setting(10.0, ge=0, le=60.0, unit="s")
    """A decision's first point is flown to once its claim has settled: every other member's
    intentions signed after it (``settle_margin_s`` later) were heard, so that the claim rule
    has judged every claim made before it (of two members that chose one point within a
    radio's hearing delay, the first to claim flies, the other decides again). Waited at most
    this long (wall clock: a member heard late, a token declared under an enrolled id by a
    rogue peer, or a member whose key was stolen and that says nothing, delays each decision
    by this at most); then flown as decided, and logged. A replacement of a point lost in
    flight waits hovering where the vehicle is (a pause this long in vehicle time, ended
    by the service once the claim has settled), and a hold's service is recorded once its
    binding has settled, within this too (docs/OPERATIONS.md). 0: off."""
    settle_margin_s: float = setting(0.1, ge=0, le=4.0, unit="s")
    """How far apart the members' clocks may read for the settling above to hold (it compares
    their signed times with this computer's): GPS or NTP time on the field."""
    intentions_every_s: float = setting(1.0, gt=0, le=10.0, unit="s")
    """A member signs and puts its intentions again at least this often, unchanged or not:
    what the others settle their claims on (each member's traffic grows by one message this
    often, each member's downlink by one per other member)."""

    def check(self) -> None:
        super().check()
        if not self.enabled:
            return
        for name in ("key_file", "roster_file"):
            if not getattr(self, name):
                raise ConfigError(f"fleet.{name}", "a fleet needs its enrolment: this vehicle's signing key and the "
                                  "fleet's roster (make them with: python -m planner_service fleet-key)")
        try:
            load_private_key(self.key_file)
        except SigningError as err:
            raise ConfigError("fleet.key_file", str(err)) from None
        try:
            read_roster(self.roster_file)
        except SigningError as err:
            raise ConfigError("fleet.roster_file", str(err)) from None


SECTIONS: dict[str, type[Section]] = {
    "zenoh": ZenohConfig, "intake": IntakeConfig, "mavlink": MavlinkConfig, "planner": PlannerConfig,
    "journal": JournalConfig, "origin": OriginConfig, "safety": SafetyConfig, "sortie": SortieConfig,
    "operator": OperatorConfig, "fleet": MembershipConfig}
"""The TOML tables besides ``[scenario]``, in the order ``to_toml`` writes them."""
SCENARIO_DEFAULTS: tuple[tuple[str, Any], ...] = (("task_arrival_period_s", 55.0), ("task_model", "backlog"))
"""The ``[scenario]`` keys the service sets besides the preset's: live users' requests are
data waiting (docs/PROTOCOL.md), so the planner's futures keep their backlogs unless the
configuration says otherwise (the paper's redraw), and their new data come in time, not
once per interval: ``task_arrival_mean`` tasks per 55 s, what an interval of the field
preset lasts (docs/MODEL.md, "Task models")."""


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
    operator: OperatorConfig = field(default_factory=OperatorConfig)
    fleet: MembershipConfig = field(default_factory=MembershipConfig)
    scenario_preset: Preset = "field"
    scenario_overrides: tuple[tuple[str, Any], ...] = SCENARIO_DEFAULTS
    """(name, value) pairs of the [scenario] section besides ``preset``, each value of its
    scenario field's type, sorted by name."""

    def scenario(self) -> Scenario:
        """The planning scenario: the preset with the configured overrides."""
        try:
            return preset(self.scenario_preset).replace(**dict(self.scenario_overrides))
        except ScenarioError as err:
            raise ConfigError(f"scenario.{err.field}", str(err)) from None

    def scenario_arguments(self) -> list[str]:
        """The scenario as ``sim_bridge users`` takes it: ``--preset NAME`` and a
        ``--set NAME=VALUE`` for each override (so the users draw from the same model)."""
        out = ["--preset", self.scenario_preset]
        for name, value in self.scenario_overrides:
            out += ["--set", f"{name}={value if isinstance(value, str) else toml_value(value)}"]
        return out

    def area(self) -> Area:
        return self.safety.area()

    def origin_point(self) -> GeoOrigin:
        return self.origin.point()

    def keys(self) -> Keys:
        return Keys(self.zenoh.prefix, self.zenoh.vehicle)

    def operator_key_path(self) -> Path:
        """The operator key's file: ``operator.key_file``, or ``operator.key`` beside the journal."""
        return Path(self.operator.key_file or Path(self.journal.path).parent / OPERATOR_KEY_NAME)

    def operator_proof_needed(self) -> bool:
        """Must operator commands carry the key's proof (``operator.proof``)? Checked
        zenoh.config_file first: it is read here."""
        if self.operator.proof == "always":
            return True
        try:
            return not access_control_closed(self.zenoh.config_file or None)
        except ProtocolError as err:
            raise ConfigError("zenoh.config_file", err.message) from None

    def _check_operator_key(self) -> None:
        """An operator key that exists must load (owner-only, 64 hex characters), and one
        that does not must be creatable: refused at start, never at the first command."""
        if not self.operator_proof_needed():
            return
        path = self.operator_key_path()
        if os.path.lexists(path):
            try:
                load_key(path)
            except SigningError as err:
                raise ConfigError("operator.key_file", str(err)) from None
            return
        folder = path.parent
        if not os.access(folder, os.W_OK | os.X_OK):
            raise ConfigError("operator.key_file", f"{path}: the folder {folder} is missing or not writable "
                                                   "(the service makes the operator key there)")

    def fleet_transport_open(self) -> str:
        """Why the fleet's zenoh is open to any peer ("" when it is not): an endpoint neither
        loopback nor TLS under access control (``zenoh.config_file``)."""
        z = self.zenoh
        endpoints = [*z.listen, *z.connect]
        if all(_loopback(e) for e in endpoints):
            return ""
        try:
            closed = access_control_closed(z.config_file or None)
        except ProtocolError as err:
            raise ConfigError("zenoh.config_file", err.message) from None
        if closed and all(e.startswith("tls/") for e in endpoints):
            return ""
        return f"zenoh endpoints {', '.join(endpoints)} are not all loopback, nor TLS with access control"

    def _check_fleet_enrolment(self) -> None:
        """This vehicle's key must be the one the roster enrols for it: the others would
        refuse every message it signs, without a word to it."""
        if not self.fleet.enabled:
            return
        roster = read_roster(self.fleet.roster_file)
        enrolled = roster.get(self.zenoh.vehicle)
        if enrolled is None:
            raise ConfigError("fleet.roster_file", f"{self.zenoh.vehicle} is not enrolled in {self.fleet.roster_file} "
                              "(python -m planner_service fleet-key)")
        if public_hex(load_private_key(self.fleet.key_file)) != enrolled.public_bytes_raw().hex():
            raise ConfigError("fleet.key_file", f"{self.fleet.key_file} is not the key {self.fleet.roster_file} "
                              f"enrols for {self.zenoh.vehicle}")

    def _check_fleet_transport(self) -> None:
        if self.fleet.enabled and not self.fleet.insecure:
            why = self.fleet_transport_open()
            if why:
                raise ConfigError("fleet.insecure", f"{why}: any peer could read and flood the fleet's keys; give "
                                  "zenoh TLS and access control, or set fleet.insecure = true to fly so knowingly")

    def check(self) -> None:
        """Every section's rules, then those between sections; ``ConfigError`` names the key."""
        for name in SECTIONS:
            getattr(self, name).check()
        self._check_operator_key()
        self._check_fleet_enrolment()
        self._check_fleet_transport()
        p, s = self.planner, self.safety
        if p.min_requests > self.intake.max_pending_requests:
            raise ConfigError("planner.min_requests", f"{p.min_requests} can never be pending: "
                              f"intake.max_pending_requests is {self.intake.max_pending_requests}")
        if not s.rtl_battery_fraction < self.sortie.next_battery_fraction:
            raise ConfigError("sortie.next_battery_fraction", f"must lie in (safety.rtl_battery_fraction = "
                              f"{s.rtl_battery_fraction}, 1]: a sortie must not begin at the return threshold")
        area, scenario = self.area(), self.scenario()
        if scenario.dimensions != 2:
            raise ConfigError("scenario.preset", "the service flies 2-D scenarios (one altitude)")
        if scenario.area_side_m > area.side_m:
            raise ConfigError("safety.area_side_m", f"the scenario's area ({scenario.area_side_m} m) exceeds the "
                              f"safety area ({area.side_m} m)")
        if not area.min_flight_altitude_m <= scenario.altitude_m <= area.max_altitude_m:
            raise ConfigError("safety.max_altitude_m", f"the scenario's altitude {scenario.altitude_m} m is outside "
                              f"[{area.min_flight_altitude_m}, {area.max_altitude_m}] m")


def parse_overrides(items: list[str]) -> dict[str, str]:
    """``["zenoh.mode=client", ...]`` -> {"zenoh.mode": "client"}."""
    out: dict[str, str] = {}
    for item in items:
        try:
            key, value = split_assignment(item)
        except SettingError:
            raise ConfigError(item, "an override is section.key=value") from None
        out[key] = value
    return out


def build_config(raw: Mapping[str, Any], overrides: Mapping[str, Any] | None = None) -> ServiceConfig:
    """A checked ``ServiceConfig`` from parsed TOML and ``section.key`` overrides (text or
    values), every value read by its field's type."""
    tables = sorted([*SECTIONS, "scenario"])
    merged: dict[str, dict[str, Any]] = {}
    for name, values in raw.items():
        if name not in tables:
            raise ConfigError(name, f"unknown section; expected one of {tables}")
        if not isinstance(values, dict):
            raise ConfigError(name, "must be a table")
        merged[name] = dict(values)
    for dotted, value in (overrides or {}).items():
        name, _, key = dotted.partition(".")
        if not key:
            raise ConfigError(dotted, "an override is section.key=value")
        if name not in tables:
            raise ConfigError(name, f"unknown section; expected one of {tables}")
        merged.setdefault(name, {})[key] = value
    try:
        sections = {name: cls(**read_fields(cls, merged.get(name, {}), lambda key, name=name: f"{name}.{key}"))
                    for name, cls in SECTIONS.items()}
        scenario = dict(merged.get("scenario", {}))
        preset_name = read("scenario.preset", kinds(ServiceConfig)["scenario_preset"], scenario.pop("preset", "field"))
        values = read_fields(Scenario, scenario, lambda key: f"scenario.{key}")
    except SettingError as err:
        raise ConfigError(err.name, err.message) from None
    config = ServiceConfig(**sections, scenario_preset=preset_name,  # type: ignore[arg-type]
                           scenario_overrides=tuple(sorted({**dict(SCENARIO_DEFAULTS), **values}.items())))
    config.check()
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


def _loopback(endpoint: str) -> bool:
    """A zenoh endpoint on this computer only (127.0.0.0/8, ::1, localhost)."""
    address = endpoint.split("/", 1)[-1].split("#", 1)[0]
    host = address.rsplit(":", 1)[0].strip("[]")
    return host == "localhost" or host == "::1" or host.startswith("127.")


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


def to_toml(c: ServiceConfig) -> str:
    """The configuration as TOML (the demo writes the one it runs)."""
    lines: list[str] = []
    for name in SECTIONS:
        lines.append(f"[{name}]")
        for f in fields(getattr(c, name)):
            lines.append(f"{f.name} = {toml_value(getattr(getattr(c, name), f.name))}")
        lines.append("")
    lines.append("[scenario]")
    lines.append(f"preset = {toml_value(c.scenario_preset)}")
    for key, value in c.scenario_overrides:
        lines.append(f"{key} = {toml_value(value)}")
    return "\n".join(lines) + "\n"
