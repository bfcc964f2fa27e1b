"""The MAVLink vehicle stub (SITL-stub): a simulated multirotor that flies uploaded missions.

It speaks MAVLink 2 as ArduPilot Copter or PX4 would (heartbeat, telemetry, the mission
protocol, arm/mode/takeoff/RTL commands) and drains its battery with the project's energy
model. Logs go to stderr. Stop it with SIGINT or SIGTERM.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from protocol.arguments import non_negative_float, positive_float, positive_int

HELP = "run the simulated MAVLink vehicle (SITL-stub)"


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
    parser.add_argument("--sysid", type=_system_id, default=1, help="MAVLink system id (default 1)")
    parser.add_argument("--item-timeout", type=positive_float, default=1.0,
                        help="seconds of the vehicle's time before re-requesting a mission item during an upload, as "
                             "ArduPilot (default 1; at a speed-up, that much less wall time, at least 0.1 s)")
    parser.add_argument("--retries", type=positive_int, default=5, help="re-requests before an upload is abandoned (default 5)")
    parser.add_argument("--fence-margin", type=non_negative_float, default=100.0,
                        help="geofence: the scenario area grown by this many metres (default 100)")
    parser.add_argument("--max-mission-items", type=positive_int, default=512,
                        help="mission capacity: a larger upload is answered NO_SPACE (default 512)")
    parser.add_argument("--signing-key", default=None, metavar="FILE",
                        help="enforce MAVLink 2 signing with the key in FILE (64 hex characters, mode 0600; make one "
                             "with: python -m planner_service keygen FILE): outgoing messages are signed, incoming "
                             "ones obeyed only if correctly signed (unsigned RADIO_STATUS excepted)")
    parser.add_argument("--signing-timestamp-file", default=None, metavar="FILE",
                        help="where the last signing timestamp is kept across restarts "
                             "(default: beside the key, FILE.vehicle-timestamp)")
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
    logging.basicConfig(stream=sys.stderr, level=args.log_level,
                        format="%(asctime)s vehicle %(levelname)s %(name)s: %(message)s")
    # Imported here so that `--help` does not pay for numba and pymavlink.
    from planner_service.model import ScenarioError, preset
    from protocol.errors import MissionError
    from protocol.errors import SigningError
    from protocol.geodesy import GeoOrigin
    from sim_bridge.vehicle import Vehicle, VehicleConfig, VehicleError

    try:
        scenario = preset(args.preset).with_overrides(args.set)
        origin = GeoOrigin.parse(args.origin) if args.origin else GeoOrigin()
        config = VehicleConfig(
            url=args.mavlink, flavour=args.flavour, scenario=scenario, origin=origin,
            speedup=args.speedup, system_id=args.sysid, item_timeout_s=args.item_timeout,
            max_retries=args.retries, fence_margin_m=args.fence_margin,
            max_mission_items=args.max_mission_items,
            signing_key_file=args.signing_key, signing_timestamp_file=args.signing_timestamp_file,
            state_file=args.state_file, track_file=args.track, recharge_s=args.recharge_s, gps_delay_s=args.gps_delay_s,
            disarm_delay_s=args.disarm_delay_s, max_stream_hz=args.max_stream_hz,
        )
        vehicle = Vehicle(config)
    except (ScenarioError, MissionError, VehicleError, SigningError) as exc:
        print(f"vehicle: {exc}", file=sys.stderr)
        return 2
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    vehicle.run(stop)
    return 0
