"""The MAVLink vehicle stub (SITL-stub): a simulated multirotor that flies uploaded missions.

It speaks MAVLink 2 as ArduPilot Copter or PX4 would (heartbeat, telemetry, the mission
protocol, arm/mode/takeoff/RTL commands) and drains its battery with the project's energy
model. Logs go to stderr. Stop it with SIGINT or SIGTERM.

--count N runs N vehicles in this one process, each its own endpoint (the URL's port + i),
system id (--sysid + i) and origin (--spacing-m * i metres east), each in its own thread:
twenty stub processes would each load the interpreter, numpy and pymavlink; one process
loads them once (docs/VEHICLE.md, "Many vehicles in one process").
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
import threading
from typing import TYPE_CHECKING, Callable

from protocol.arguments import USAGE_ERROR, non_negative_float, positive_float, positive_int
from protocol.stopping import stop_on_signals

if TYPE_CHECKING:  # the real imports wait for run(): `--help` must not pay for numba and pymavlink
    from planner_service.model import Scenario
    from protocol.geodesy import GeoOrigin
    from sim_bridge.vehicle import Vehicle, VehicleConfig

HELP = "run the simulated MAVLink vehicle (SITL-stub), or --count N of them in one process"

log = logging.getLogger(__name__)

LOG_FORMAT = "%(asctime)s vehicle %(levelname)s %(name)s: %(message)s"
FLEET_LOG_FORMAT = "%(asctime)s vehicle%(vehicle_tag)s %(levelname)s %(name)s: %(message)s"
"""With --count > 1 each line says whose it is (`vehicle sysid=3 INFO ...`); the process's own
lines (`3 vehicles listening`) have no tag. One vehicle keeps the plain format."""

PER_VEHICLE_FILES = {"track": "--track", "state_file": "--state-file",
                     "signing_timestamp_file": "--signing-timestamp-file"}
"""Options naming a file that two vehicles must never share: with --count > 1 the path must
hold ``{i}``, replaced by the vehicle's index (a shared track or state file would be two
flights interleaved; a shared signing timestamp file is refused by its lock)."""

_current = threading.local()
"""The vehicle whose thread (or construction, in the main thread) is logging."""


def _url(text: str) -> str:
    """udpin:HOST:PORT, udpout:HOST:PORT or tcpin:HOST:PORT, checked as parsed."""
    from sim_bridge.vehicle import VehicleError
    from sim_bridge.vehicle.link import parse_url

    try:
        parse_url(text)
    except VehicleError as err:
        raise argparse.ArgumentTypeError(err.message) from None
    return text


def _system_id(text: str) -> int:
    value = positive_int(text)
    if value > 255:
        raise argparse.ArgumentTypeError(f"{text} is not a MAVLink system id (1-255)")
    return value


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--mavlink", default="udpin:127.0.0.1:14550", metavar="URL", type=_url,
                        help="udpin:HOST:PORT, udpout:HOST:PORT or tcpin:HOST:PORT (default %(default)s)")
    parser.add_argument("--flavour", choices=("ardupilot", "px4"), default="ardupilot",
                        help="autopilot to imitate: ArduCopter (streams nothing until asked, item 0 is home, "
                             "missions written item by item) or PX4 (default streams, atomic uploads); "
                             "docs/VEHICLE.md (default %(default)s)")
    parser.add_argument("--preset", default="field", help="scenario preset for the energy model (default %(default)s)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a scenario field, e.g. --set speed_mps=10 (repeatable)")
    parser.add_argument("--origin", default=None, metavar="LAT,LON,ALT",
                        help="geodetic origin of the local frame (default 47.397742,8.545594,488)")
    parser.add_argument("--speedup", type=positive_float, default=1.0,
                        help="simulated seconds per wall second (default 1)")
    parser.add_argument("--sysid", type=_system_id, default=1,
                        help="MAVLink system id (default 1; with --count N, vehicle i has this + i)")
    parser.add_argument("--count", type=positive_int, default=1, metavar="N",
                        help="run N vehicles in this one process, each in its own thread (one interpreter, numpy "
                             "and pymavlink for all, not N): vehicle i (from 0) on the URL's port + i, system id "
                             "--sysid + i, its origin --spacing-m * i metres east of --origin; --track, "
                             "--state-file and --signing-timestamp-file must then contain {i}, replaced by i; "
                             "if one vehicle fails, all stop (default 1)")
    parser.add_argument("--spacing-m", type=non_negative_float, default=40.0, metavar="METRES",
                        help="with --count, metres east between one vehicle's origin and the next's "
                             "(default %(default)g)")
    parser.add_argument("--item-timeout", type=positive_float, default=1.0,
                        help="seconds of the vehicle's time before re-requesting a mission item during an upload, as "
                             "ArduPilot (default 1; at a speed-up, that much less wall time, at least 0.1 s)")
    parser.add_argument("--retries", type=positive_int, default=5, help="re-requests before an upload is abandoned (default 5)")
    parser.add_argument("--fence-margin", type=non_negative_float, default=100.0,
                        help="geofence: the scenario area grown by this many metres (default 100)")
    parser.add_argument("--fence-alt-max", type=positive_float, default=150.0, metavar="METRES",
                        help="geofence ceiling: a mission item above this many metres over home is refused "
                             "INVALID_PARAM7 (ArduPilot's FENCE_ALT_MAX; default %(default)g)")
    parser.add_argument("--max-mission-items", type=positive_int, default=512,
                        help="mission capacity: a larger upload is answered NO_SPACE (default 512)")
    parser.add_argument("--signing-key", default=None, metavar="FILE",
                        help="enforce MAVLink 2 signing with the key in FILE (64 hex characters, mode 0600; make one "
                             "with: python -m planner_service keygen FILE): outgoing messages are signed, incoming "
                             "ones obeyed only if correctly signed (unsigned RADIO_STATUS excepted)")
    parser.add_argument("--signing-timestamp-file", default=None, metavar="FILE",
                        help="where the last signing timestamp is kept across restarts "
                             "(default: beside the key, FILE.vehicle-timestamp; with --count, FILE.vehicle-I-timestamp "
                             "for vehicle I)")
    parser.add_argument("--state-file", default=None, metavar="PATH",
                        help="save the flight (position, battery, armed, mode, time, home) here a few times a "
                             "second and, if the file exists at start, resume from it as after a reboot: in the "
                             "air it holds position, its mission lost; time_boot_ms restarts from 0")
    parser.add_argument("--track", default=None, metavar="PATH",
                        help="write the vehicle's own flight to PATH (CSV: simulated time_s, x_m, y_m, z_m east/"
                             "north/up of the origin, the mission item flown, the mode, armed), one line a tick, "
                             "appended across restarts: what it really flew, as an autopilot's flight log")
    parser.add_argument("--recharge-s", type=non_negative_float, default=None, metavar="SECONDS",
                        help="battery swap: SECONDS of simulated time after landing and disarming, the battery "
                             "is full again (default: never)")
    parser.add_argument("--gps-delay-s", type=float, default=40.0, metavar="SECONDS",
                        help="simulated seconds after boot until the vehicle has a position estimate, as ArduCopter "
                             "SITL's 'EKF3 IMU0 is using GPS' (about 41 s): no position, no home and arming refused "
                             "in a position mode before; 0: a position from the start (default %(default)s)")
    parser.add_argument("--disarm-delay-s", type=float, default=10.0, metavar="SECONDS",
                        help="armed on the ground this many simulated seconds without taking off, the motors stop "
                             "(ArduPilot DISARM_DELAY, PX4 COM_DISARM_PRFLT); 0: never (default %(default)s)")
    parser.add_argument("--max-stream-hz", type=float, default=50.0, metavar="HZ",
                        help="the most any streamed message is sent per wall second: PX4's rates are in its "
                             "simulated time, so a speed-up multiplies them up to this (default %(default)s)")
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"))


def run(args: argparse.Namespace) -> int:
    problem = _count_problem(args)
    if problem is not None:
        print(f"error: {problem}", file=sys.stderr)
        return USAGE_ERROR
    logging.basicConfig(stream=sys.stderr, level=args.log_level,
                        format=LOG_FORMAT if args.count == 1 else FLEET_LOG_FORMAT)
    if args.count > 1:
        for handler in logging.getLogger().handlers:
            handler.addFilter(_tag_record)
    # Imported here so that `--help` does not pay for numba and pymavlink.
    from planner_service.model import ScenarioError, preset
    from protocol.errors import MissionError
    from protocol.errors import SigningError
    from protocol.geodesy import GeoOrigin
    from sim_bridge.vehicle import VehicleError

    try:
        scenario = preset(args.preset).with_overrides(args.set)
        origin = GeoOrigin.parse(args.origin) if args.origin else GeoOrigin()
        vehicles = _vehicles(args, scenario, origin)
    except (ScenarioError, MissionError, VehicleError, SigningError) as exc:
        print(f"vehicle: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    stop_on_signals(stop)
    if len(vehicles) == 1:
        vehicles[0].run(stop)
        return 0
    return fly_all(vehicles, stop)


def _count_problem(args: argparse.Namespace) -> str | None:
    """Why ``--count`` cannot number its vehicles (an id or port past its range, a file that
    all would share), or None; checked before anything is imported or opened."""
    from sim_bridge.vehicle.link import parse_url

    count = args.count
    if count == 1:
        return None
    last_sysid = args.sysid + count - 1
    if last_sysid > 255:
        return (f"--count {count} with --sysid {args.sysid}: system ids up to {last_sysid}; "
                "a MAVLink system id is at most 255")
    _, _, port = parse_url(args.mavlink)
    if port == 0:
        return f"--count {count}: --mavlink {args.mavlink}: port 0 (any free port) cannot be numbered per vehicle"
    if port + count - 1 > 65535:
        return f"--count {count} with --mavlink {args.mavlink}: ports up to {port + count - 1}; a port is at most 65535"
    for dest, option in PER_VEHICLE_FILES.items():
        path = getattr(args, dest)
        if path is not None and "{i}" not in path:
            return (f"{option} {path}: with --count {count} the path must contain {{i}} (replaced by each "
                    "vehicle's index), so that no two vehicles share the file")
    return None


def _tag_record(record: logging.LogRecord) -> bool:
    """A handler filter: the vehicle a line comes from, for ``FLEET_LOG_FORMAT``."""
    record.vehicle_tag = getattr(_current, "tag", "")
    return True


def _vehicles(args: argparse.Namespace, scenario: Scenario, origin: GeoOrigin) -> list[Vehicle]:
    """Every vehicle, its socket bound; if one cannot be made, those made are closed."""
    from sim_bridge.vehicle import Vehicle

    vehicles: list[Vehicle] = []
    try:
        for i in range(args.count):
            config = _vehicle_config(args, scenario, origin, i)
            _current.tag = f" sysid={config.system_id}"  # a resumed state file is logged as it is read
            try:
                vehicles.append(Vehicle(config))
            finally:
                _current.tag = ""
    except BaseException:
        for vehicle in vehicles:
            _close_unstarted(vehicle)
        raise
    return vehicles


def _vehicle_config(args: argparse.Namespace, scenario: Scenario, origin: GeoOrigin, i: int) -> VehicleConfig:
    """Vehicle ``i`` (from 0) of ``--count``: the URL's port + i, ``--sysid`` + i, its origin
    ``--spacing-m`` * i east; vehicle 0 of one is exactly the command line."""
    from sim_bridge.vehicle import VehicleConfig

    return VehicleConfig(
        url=_numbered_url(args.mavlink, i), flavour=args.flavour, scenario=scenario,
        origin=_origin_east(origin, args.spacing_m * i), speedup=args.speedup, system_id=args.sysid + i,
        item_timeout_s=args.item_timeout, max_retries=args.retries, fence_margin_m=args.fence_margin,
        max_mission_items=args.max_mission_items, max_altitude_m=args.fence_alt_max,
        signing_key_file=args.signing_key,
        signing_timestamp_file=_timestamp_file(args, i), state_file=_numbered(args.state_file, args.count, i),
        track_file=_numbered(args.track, args.count, i), recharge_s=args.recharge_s, gps_delay_s=args.gps_delay_s,
        disarm_delay_s=args.disarm_delay_s, max_stream_hz=args.max_stream_hz,
    )


def _numbered_url(url: str, i: int) -> str:
    if i == 0:
        return url  # as typed: one vehicle logs the URL it was given
    from sim_bridge.vehicle.link import parse_url

    kind, host, port = parse_url(url)
    return f"{kind}:{host}:{port + i}"


def _origin_east(origin: GeoOrigin, east_m: float) -> GeoOrigin:
    """The point ``east_m`` east of ``origin``, at its altitude (on the ellipsoid, as the
    service's map and the fleet demo place a UAV's base)."""
    if east_m == 0:
        return origin  # exact: no round trip through the tangent plane
    from protocol.geodesy import GeoOrigin, local_to_global

    lat, lon, alt = local_to_global(origin, east_m, 0.0, 0.0)
    return GeoOrigin(lat, lon, alt)


def _numbered(path: str | None, count: int, i: int) -> str | None:
    """``{i}`` in ``path`` replaced by ``i``; one vehicle's path is used as given."""
    if path is None or count == 1:
        return path
    return path.replace("{i}", str(i))


def _timestamp_file(args: argparse.Namespace, i: int) -> str | None:
    """The signing timestamp file of vehicle ``i``. Several vehicles sharing a key get one
    file each by default (``KEY.vehicle-I-timestamp``): one file is locked by one signer."""
    if args.signing_timestamp_file is not None or args.signing_key is None or args.count == 1:
        return _numbered(args.signing_timestamp_file, args.count, i)
    from protocol.signing import default_timestamp_path

    return str(default_timestamp_path(args.signing_key, f"vehicle-{i}"))


def _close_unstarted(vehicle: Vehicle) -> None:
    """Release what a vehicle that never ran holds (socket, signing lock, track file); best
    effort, since the error that stopped the start is the one to report."""
    closers = [vehicle.link.close]
    closers += [vehicle.signer.close] if vehicle.signer is not None else []
    closers += [vehicle.track.close] if vehicle.track is not None else []
    for close in closers:
        with contextlib.suppress(Exception):
            close()


def fly_all(vehicles: list[Vehicle], stop: threading.Event) -> int:
    """Run each vehicle in its own thread until ``stop``; 0, or 1 if one failed (its failure
    sets ``stop``: a fleet is never left flying half its vehicles without a word)."""
    listening = [threading.Event() for _ in vehicles]
    failed: list[int] = []
    threads = [threading.Thread(target=_fly, args=(vehicle, stop, up.set, failed),
                                name=f"vehicle-sysid-{vehicle.config.system_id}")
               for vehicle, up in zip(vehicles, listening)]
    for thread in threads:
        thread.start()
    if _all_set(listening, stop):
        log.info("%d vehicles listening", len(vehicles))  # after every vehicle's own line
    stop.wait()
    for thread in threads:
        thread.join()
    if failed:
        log.error("stopped: vehicle(s) with system id %s failed", ", ".join(map(str, sorted(failed))))
        return 1
    return 0


def _fly(vehicle: Vehicle, stop: threading.Event, on_listening: Callable[[], None], failed: list[int]) -> None:
    sysid = vehicle.config.system_id
    _current.tag = f" sysid={sysid}"
    try:
        vehicle.run(stop, on_listening)
    except BaseException:
        log.exception("vehicle sysid=%d failed: stopping every vehicle", sysid)
        failed.append(sysid)
        stop.set()


def _all_set(events: list[threading.Event], stop: threading.Event) -> bool:
    """Wait until every event is set (True), or ``stop`` is (False)."""
    for event in events:
        while not event.wait(0.1):
            if stop.is_set():
                return False
    return True
