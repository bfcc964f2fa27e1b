"""What the simulated autopilot does differently, as data: one ``Behaviour`` per profile of
``protocol.autopilot`` (keyed by it), read by the flight, the commands, the telemetry, the
parameters and the runner. The profile holds what both sides of the link know (mode names
and numbers, home slots, how items are stored); this table holds what only the stub needs
to act as that autopilot: its texts, its answers, its mission execution's choices. A
branch in the stub tests a named field here, never the autopilot's name.

Each field's docstring says what the real autopilot does and where (ArduPilot: checked on
ArduCopter SITL V4.7.0-dev and read in ``ArduCopter/``, ``libraries/``; PX4: read in
``src/modules/``); docs/VEHICLE.md has the observations.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Callable, Mapping, Union

from pymavlink.dialects.v20 import common as M

from protocol.autopilot import ARDUPILOT, PX4, Autopilot, autopilot_for
from protocol.mission import MissionItem

from .estimator import Stage
from .modes import Mode
from .stored_items import Problem, ardupilot_problem, px4_problem


@dataclass(frozen=True)
class Behaviour:
    """One autopilot's conduct, as the stub imitates it."""

    autopilot: Autopilot

    # --- boot and arming ---------------------------------------------------------------------
    boot_mode: Mode
    """The mode after boot (and after a restart on the ground): Copter boots in STABILIZE
    (``ArduCopter/system.cpp`` ``init_ardupilot``: ``set_mode(STABILIZE)``); PX4 in AUTO.LOITER
    (commander's ``_user_mode_intention`` starts at the hold mode, ``src/modules/commander``)."""
    arm_position_in_any_mode: bool
    """Arming needs a position whatever the mode: PX4's ``PreFlightCheck`` (global position
    check, ``src/modules/commander/HealthAndArmingChecks``); Copter only in a mode that
    ``requires_GPS`` (``AP_Arming_Copter::gps_checks``)."""
    arm_no_origin_text: str | None
    """The check that fails before the estimator has an origin (Copter's
    ``AP_Arming_Copter::gps_checks``: ``AHRS: waiting for home``); None: none apart."""
    arm_no_position_text: str
    """The check that fails without a position estimate (Copter ``Need Position Estimate``;
    PX4 ``Navigation error: No valid global position estimate``)."""
    arms_in_mission_mode: bool
    """Arming in the mission mode is allowed: PX4 yes; Copter no, ``ModeAuto::allows_arming``
    with AUTO_OPTIONS 0 (``AUTO mode not armable``; ``Mode requires mission`` without one)."""
    disarm_resets_mission: bool
    """Disarming forgets the navigation index (MISSION_CURRENT 0): ArduPilot,
    ``AP_Arming_Copter::disarm`` -> ``AP_Mission::reset``; PX4 keeps it."""
    arming_text: str | None
    """The STATUSTEXT at arming (``AP_Arming::arm``: ``Arming motors``); None: none."""
    disarming_text: str | None
    """... and at disarming (``AP_Arming::disarm``: ``Disarming motors``)."""
    prearm_report_s: float | None
    """Failing pre-arm checks are reported unasked, ``PreArm: <check>``, this often while
    disarmed (``AP_Arming::update``: every 30 s, seen on SITL); None: PX4 does not."""

    # --- modes -------------------------------------------------------------------------------
    mode_checks_disarmed: bool
    """A mode's position check applies disarmed too: PX4 (commander refuses a mode it cannot
    run); Copter checks only armed (``Copter::set_mode``: disarmed every mode is allowed)."""
    mode_no_position_text: str
    """Why a mode that needs a position is refused without one (``Copter::set_mode``:
    ``requires position``; PX4 ``Navigation error: No valid global position estimate``)."""
    mode_refused_text: str | None
    """The STATUSTEXT prefix of a refused mode change, ``{name}`` the mode's name (Copter's
    ``Mode change to %s failed: %s``, ``ArduCopter/mode.cpp``); None: PX4's refusal has none."""
    auto_needs_takeoff_on_ground: bool
    """AUTO armed on the ground needs a mission that starts with a takeoff
    (``ModeAuto::init`` -> ``AP_Mission::starts_with_takeoff_cmd``, ``Auto: Missing Takeoff
    Cmd``); PX4 takes off on its own."""
    auto_needs_mission: bool
    """The mission mode needs a mission (PX4 ``No valid mission available``,
    ``src/modules/navigator/mission.cpp``); Copter enters AUTO without one."""

    # --- the mission ---------------------------------------------------------------------------
    mission_start_range: bool
    """MAV_CMD_MISSION_START's first item is honoured: PX4 sets it current; Copter answers a
    first or last item DENIED (``GCS_MAVLINK_Copter::handle_command_mission_start``)."""
    mission_start_arms: bool
    """MAV_CMD_MISSION_START arms a disarmed vehicle (its pre-arm checks first) and switches
    to the mission mode: PX4 SITL 1.18 (measured: ACK 0, armed, AUTO.MISSION, takes off);
    Copter needs arming first."""
    waits_for_mission_start: bool
    """AUTO armed on the ground climbs only after MISSION_START (Copter's ``auto_armed``,
    ``ModeAuto::run``); PX4 flies the mission once armed in mission mode."""
    pause_switches_to_hold: bool
    """MAV_CMD_DO_PAUSE_CONTINUE switches to the hold mode and back (PX4, commander); Copter
    pauses inside AUTO (``ModeAuto::pause``)."""
    takeoff_switches_mode: bool
    """MAV_CMD_NAV_TAKEOFF switches to its own mode (PX4 AUTO.TAKEOFF, needs a position);
    Copter takes off only in GUIDED (``ModeGuided::do_user_takeoff``)."""
    takeoff_alt_amsl: bool
    """MAV_CMD_NAV_TAKEOFF's altitude is above mean sea level (PX4, commander); Copter's is
    relative to home."""
    set_current_to_nav_command: bool
    """MISSION_SET_CURRENT moves to the next navigation command, never item 0 and not with
    only home, and starts it now only if the mission runs (``AP_Mission::set_current_cmd``);
    PX4 sets any item and loads it in mission mode (``MissionBase``)."""
    resumes_at_nav_index: bool
    """Entering AUTO resumes at the navigation index, a completed mission starting again at
    item 1 (``AP_Mission::start_or_resume``); PX4 continues at its current item, a completed
    one at 0 (``src/modules/navigator/mission_base.cpp``)."""
    do_items_reached: bool
    """A command without a position is reported reached (MISSION_ITEM_REACHED) when run:
    PX4 (``MissionBase::set_mission_items``); Copter reports navigation commands only."""
    disarms_at_mission_end_landed: bool
    """A mission that ends on the ground disarms (``ModeAuto::exit_mission``); PX4 leaves it
    to the land detector's auto-disarm."""
    empty_mission_keeps_command: bool
    """With the stored mission emptied under it the command in progress is flown and never
    completes (``AP_Mission::update`` does nothing with no commands); PX4 has no such case
    (a new mission replaces the active one whole)."""

    # --- texts and reports -------------------------------------------------------------------
    command_started_text: str | None
    """At each command started, ``{seq}`` and ``{name}`` (``AP_Mission::start_command``:
    ``Mission: %u %s``)."""
    waypoint_reached_text: str | None
    """At a waypoint reached, ``{seq}`` (``ModeAuto::verify_nav_wp``: ``Reached command #%i``)."""
    reached_repeats: int
    """MISSION_ITEM_REACHED is sent again at 1 Hz this many times (PX4,
    ``MavlinkMissionManager::send``); 0: once (ArduPilot)."""
    mission_done_text: str | None
    """At the end of the mission (PX4's navigator: ``Mission finished, loitering``)."""
    restarted_text: str | None
    """A mission changed in flight restarted the command (``ModeAuto::run``'s change
    detector: ``Auto mission changed, restarted command``)."""
    gps_fix_texts: tuple[str, ...]
    """At the first GPS fix (``AP_GPS::detect_instance``: ``GPS 1: detected u-blox``)."""
    origin_texts: tuple[str, ...]
    """When the estimator has an origin, ``{alt_m}`` the field elevation
    (``AP_NavEKF3_Control.cpp``: ``EKF3 IMU0 origin set``; ``AP_Baro``: ``Field Elevation Set``)."""
    using_gps_texts: tuple[str, ...]
    """When the estimator navigates with GPS (``EKF3 IMU%u is using GPS``, each core)."""
    home_set_messages: tuple[int, ...]
    """Messages sent once, unasked, to every link when home is set (ArduPilot
    GPS_GLOBAL_ORIGIN and HOME_POSITION, seen on SITL at origin and at arming)."""
    mission_current_to_all: bool
    """MISSION_CURRENT at an event goes to every link (PX4, ``MavlinkMissionManager``);
    ArduPilot's is an extra report to the links that stream it."""
    echoes_set_current: bool
    """MISSION_SET_CURRENT is answered with MISSION_CURRENT of the requested seq to the sender
    (``GCS_MAVLINK::handle_mission_set_current``)."""
    current_flag_is_command: bool
    """A downloaded item's ``current`` compares the item's command id with the current index
    (sic, ``MissionItemProtocol_Waypoints::get_item``); PX4 compares its seq."""
    timesync_interval_s: float | None
    """TIMESYNC (tc1 0) sent unasked this often (ArduPilot, seen on SITL every 10 s)."""

    # --- command answers -------------------------------------------------------------------
    refusal_results: Mapping[str, int]
    """The MAV_RESULT of a refused command, by what it asked (``arm``, ``disarm``, ``mode``,
    ``mission_start``, ``takeoff``, ``pause``): Copter FAILED throughout
    (``GCS_MAVLINK_Copter::handle_command_*``); PX4 TEMPORARILY_REJECTED for arming and mode
    changes, DENIED for the rest (commander)."""
    unknown_mode_result: int
    """DO_SET_MODE with a mode the autopilot has not (Copter FAILED, PX4 DENIED)."""
    unknown_message_result: int
    """REQUEST_MESSAGE for a message it cannot send (ArduPilot FAILED, PX4 UNSUPPORTED)."""
    home_request_sends_origin: bool
    """MAV_CMD_GET_HOME_POSITION sends GPS_GLOBAL_ORIGIN after home, before the ACK
    (``GCS_MAVLINK::handle_command_get_home_position``)."""

    # --- telemetry --------------------------------------------------------------------------
    standby_while_landed: bool
    """HEARTBEAT.system_status is STANDBY on the ground, armed or not
    (``GCS_MAVLINK_Copter::vehicle_system_status``); PX4 is ACTIVE once armed."""
    gps_position_before_estimate: bool
    """GLOBAL_POSITION_INT is sent from boot (lat/lon 0 before a fix, then the GPS position
    before the estimator navigates), as SITL does; PX4 sends none until it is valid."""
    local_position_from: Stage
    """The estimator stage from which LOCAL_POSITION_NED is sent (ArduPilot: an origin;
    PX4: a valid position)."""
    prearm_in_sys_status: bool
    """SYS_STATUS carries the pre-arm bit, healthy only when the checks pass (ArduPilot)."""
    stopped_mission_paused: bool
    """MISSION_CURRENT.mission_state of a stopped mission that ran is PAUSED (PX4); ArduPilot
    says NOT_STARTED for any stopped mission (``GCS_MAVLINK::send_mission_current``)."""
    estimator_report_streamed: bool
    """The stub builds the profile's estimator message (EKF_STATUS_REPORT); PX4's
    ESTIMATOR_STATUS is not simulated."""
    firmware_version: tuple[int, int, int]
    """AUTOPILOT_VERSION's flight software version the stub claims."""

    # --- parameters ---------------------------------------------------------------------------
    params_bytewise: bool
    """Integer parameters are sent bytewise, the int32's bytes in the float field (PX4,
    MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE, ``mavlink_parameters.cpp``); ArduPilot
    casts to float."""
    param_index_by_name: int | None
    """param_index in the answer to a read by name (ArduPilot 65535,
    ``GCS_Param.cpp``); None: the parameter's index (PX4)."""

    # --- mission items -------------------------------------------------------------------------
    item_problem: Callable[[MissionItem], Problem | None]
    """Why the autopilot refuses an uploaded item (``stored_items.py``)."""


ARDUPILOT_BEHAVIOUR = Behaviour(
    autopilot=ARDUPILOT, boot_mode=Mode.MANUAL,
    arm_position_in_any_mode=False, arm_no_origin_text="AHRS: waiting for home",
    arm_no_position_text="Need Position Estimate", arms_in_mission_mode=False, disarm_resets_mission=True,
    arming_text="Arming motors", disarming_text="Disarming motors", prearm_report_s=30.0,
    mode_checks_disarmed=False, mode_no_position_text="requires position",
    mode_refused_text="Mode change to {name} failed: ", auto_needs_takeoff_on_ground=True, auto_needs_mission=False,
    mission_start_range=False, mission_start_arms=False, waits_for_mission_start=True, pause_switches_to_hold=False,
    takeoff_switches_mode=False, takeoff_alt_amsl=False, set_current_to_nav_command=True,
    resumes_at_nav_index=True, do_items_reached=False, disarms_at_mission_end_landed=True,
    empty_mission_keeps_command=True,
    command_started_text="Mission: {seq} {name}", waypoint_reached_text="Reached command #{seq}",
    reached_repeats=0, mission_done_text=None, restarted_text="Auto mission changed, restarted command",
    gps_fix_texts=("GPS 1: detected u-blox",),
    origin_texts=("EKF3 IMU0 origin set", "Field Elevation Set: {alt_m:.0f}m"),
    using_gps_texts=("EKF3 IMU0 is using GPS", "EKF3 IMU1 is using GPS"),
    home_set_messages=(M.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN, M.MAVLINK_MSG_ID_HOME_POSITION),
    mission_current_to_all=False, echoes_set_current=True, current_flag_is_command=True,
    timesync_interval_s=10.0,
    refusal_results=MappingProxyType({k: M.MAV_RESULT_FAILED
                                      for k in ("arm", "disarm", "mode", "mission_start", "takeoff", "pause")}),
    unknown_mode_result=M.MAV_RESULT_FAILED, unknown_message_result=M.MAV_RESULT_FAILED,
    home_request_sends_origin=True,
    standby_while_landed=True, gps_position_before_estimate=True, local_position_from=Stage.ORIGIN,
    prearm_in_sys_status=True, stopped_mission_paused=False, estimator_report_streamed=True,
    firmware_version=(4, 6, 0),
    params_bytewise=False, param_index_by_name=65535,
    item_problem=ardupilot_problem,
)
PX4_BEHAVIOUR = Behaviour(
    autopilot=PX4, boot_mode=Mode.HOLD,
    arm_position_in_any_mode=True, arm_no_origin_text=None,
    arm_no_position_text="Arming denied: Resolve system health failures first", arms_in_mission_mode=True,
    disarm_resets_mission=False, arming_text=None, disarming_text=None, prearm_report_s=None,
    mode_checks_disarmed=False, mode_no_position_text="Navigation error: No valid global position estimate",
    mode_refused_text=None, auto_needs_takeoff_on_ground=False, auto_needs_mission=True,
    mission_start_range=True, mission_start_arms=True, waits_for_mission_start=False, pause_switches_to_hold=True,
    takeoff_switches_mode=True, takeoff_alt_amsl=True, set_current_to_nav_command=False,
    resumes_at_nav_index=False, do_items_reached=True, disarms_at_mission_end_landed=False,
    empty_mission_keeps_command=False,
    command_started_text=None, waypoint_reached_text=None, reached_repeats=10,
    mission_done_text="Mission finished, loitering", restarted_text=None,
    gps_fix_texts=(), origin_texts=(), using_gps_texts=(), home_set_messages=(),
    mission_current_to_all=True, echoes_set_current=False, current_flag_is_command=False,
    timesync_interval_s=None,
    refusal_results=MappingProxyType({
        "arm": M.MAV_RESULT_TEMPORARILY_REJECTED, "mode": M.MAV_RESULT_TEMPORARILY_REJECTED,
        "pause": M.MAV_RESULT_TEMPORARILY_REJECTED, "disarm": M.MAV_RESULT_DENIED,
        "mission_start": M.MAV_RESULT_DENIED, "takeoff": M.MAV_RESULT_DENIED}),
    unknown_mode_result=M.MAV_RESULT_DENIED, unknown_message_result=M.MAV_RESULT_UNSUPPORTED,
    home_request_sends_origin=False,
    standby_while_landed=False, gps_position_before_estimate=False, local_position_from=Stage.NAVIGATING,
    prearm_in_sys_status=True, stopped_mission_paused=True, estimator_report_streamed=False,
    firmware_version=(1, 15, 0),
    params_bytewise=True, param_index_by_name=None,
    item_problem=px4_problem,
)

BEHAVIOURS: Mapping[str, Behaviour] = MappingProxyType(
    {b.autopilot.name: b for b in (ARDUPILOT_BEHAVIOUR, PX4_BEHAVIOUR)})


def behaviour_for(flavour: Union[str, Autopilot, Behaviour]) -> Behaviour:
    """The stub's conduct as the autopilot ``flavour`` names (``MissionError("flavour")``
    from ``autopilot_for`` for an unknown one; a ``Behaviour`` is returned as it is)."""
    if isinstance(flavour, Behaviour):
        return flavour
    return BEHAVIOURS[autopilot_for(flavour).name]


__all__ = ["ARDUPILOT_BEHAVIOUR", "BEHAVIOURS", "Behaviour", "PX4_BEHAVIOUR", "behaviour_for"]
