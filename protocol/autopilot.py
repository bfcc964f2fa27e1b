"""What differs between the autopilots this project speaks to, as data: one frozen profile
per autopilot (ArduPilot Copter, PX4), read by the service, the protocol's mission encoding
and the vehicle stub alike. The configuration names an autopilot by its string
(``mavlink.flavour = "ardupilot" | "px4"``, ``--flavour``); ``autopilot_for`` turns it into
its profile once, at the edge, and the profile goes where the string went. A second
autopilot is a third profile, not a hundred ``if``.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Literal, Mapping, Union

from pymavlink.dialects.v20 import ardupilotmega as M

from .errors import MissionError

Flavour = Literal["ardupilot", "px4"]


@dataclass(frozen=True)
class Autopilot:
    """One autopilot's conventions on the wire and in its mission store."""

    name: str
    """As the configuration spells it (``mavlink.flavour``)."""
    modes: Mapping[tuple[int, int], str]
    """(custom main mode, custom sub mode) -> the name ground stations show."""
    main_shift: int
    """HEARTBEAT.custom_mode: the main mode is ``(custom_mode >> main_shift) & main_mask``."""
    main_mask: int
    sub_shift: int | None
    """... and the sub mode ``(custom_mode >> sub_shift) & 0xFF``; None: no sub mode (0)."""
    unknown_mode: str
    """The name shown for a mode not in ``modes`` (``str.format`` of main and sub)."""
    mission_mode: str
    """The mode that flies the mission (start, resume)."""
    return_mode: str
    """The mode of a commanded return to launch."""
    hold_mode: str
    """The mode that holds position where the vehicle is (the operator's hold)."""
    arm_mode: str | None
    """The mode to arm in before flying the mission (set first when the vehicle is in
    another); None: arm in any."""
    home_slots: int
    """Mission items the autopilot keeps for itself at the start of the mission: ArduPilot
    stores home as item 0 and overwrites whatever is uploaded there
    (``AP_Mission::write_home_to_storage``); PX4 keeps home apart (0)."""
    whole_second_holds: bool
    """A waypoint's hold is stored in whole seconds (uint16, truncated): ArduPilot
    (``AP_Mission::mavlink_int_to_mission_cmd``); the hold is then rounded up when encoded,
    never cut short. PX4 stores the float."""
    compacts_items: bool
    """The stored copy of an item loses what the autopilot does not use: ArduPilot turns NaN
    parameters into 0, keeps a waypoint's hold only, and a return to launch without a
    position (frame 0), as read back from ArduCopter 4.7 SITL. PX4 keeps the item as sent."""
    writes_items_as_they_arrive: bool
    """An upload's items replace the mission held as they arrive: ArduPilot writes each to
    storage on receipt (``GCS_MAVLINK::handle_mission_item`` -> ``AP_Mission::replace_cmd``),
    so a failed upload may leave part of itself; PX4 switches over only when the upload is
    complete (``MavlinkMissionManager``'s dataman swap)."""
    return_item_mode: str | None
    """The mode a mission's RETURN_TO_LAUNCH item hands the vehicle to; None: flown in the
    mission mode. PX4 switches to AUTO.RTL as the item begins ("Mission finished, loitering",
    "Returning to launch", seen on PX4 SITL 1.18), so an upload can no longer turn the way
    home back. ArduPilot flies the item in AUTO."""
    modes_after_landing: frozenset[str]
    """Modes the autopilot switches to by itself when a landing in its return mode disarms
    it. PX4 goes back to the last mode chosen that allows arming (``UserModeIntention::
    onDisarm``): AUTO.MISSION after its mission's return, AUTO.LOITER (its mode at boot)
    after a commanded one, both seen on PX4 SITL. ArduPilot stays in its mode."""
    set_current_by_command: bool
    """The flown item is set with MAV_CMD_DO_SET_MISSION_CURRENT (ArduPilot); False: with the
    MISSION_SET_CURRENT message, PX4 SITL 1.18 answering the command MAV_RESULT_UNSUPPORTED."""
    flies_changed_current_item: bool
    """After an upload that changes the item at the index the vehicle keeps, it flies the new
    item by itself: PX4 (seen on PX4 SITL: the new item 3 flown, no item marked current).
    ArduPilot restarts no return-to-launch, takeoff or land item on an upload: the command
    restarts it."""
    unused_streams: Mapping[str, int]
    """Messages the autopilot streams unasked that the service has no use for (name ->
    message id), which the link stops on its own link (SET_MESSAGE_INTERVAL -1) on every
    (re)connection: PX4's onboard link sends about 480 messages a second of its time
    unasked (ATTITUDE 100 Hz, HIGHRES_IMU and ATTITUDE_QUATERNION 50 Hz, ...; PX4 SITL
    1.18), and at PX4 SITL's speed 10 the link lost most mission replies and COMMAND_ACKs
    under them (a download died at item 3 of 5). Rates are per link: another program on
    the same link loses them too. ArduPilot streams nothing unasked (empty)."""
    text_ids_from_zero: bool
    """STATUSTEXT ids count from 0 at boot for every text, so the first text of a boot, when
    chunked, is chunked under id 0: PX4 (its STATUSTEXT stream's counter; seen on PX4 SITL
    1.18). ArduPilot gives id 0 to texts of one message only."""
    mav_autopilot: int
    """MAV_AUTOPILOT: its HEARTBEAT's ``autopilot``, a .plan's ``firmwareType``."""
    estimator_message: str
    """The message that says whether the position estimate can be trusted."""
    estimator_msg_id: int
    estimator_stream: int | None
    """The legacy REQUEST_DATA_STREAM group carrying it (None: no group)."""
    estimator_unaided_flags: int
    """Estimator flags that mean "no GPS" even beside an absolute position: ArduPilot's
    EKF sets CONST_POS_MODE (128) until it uses the GPS (``NavEKF3_core::getFilterStatus``);
    PX4's EKF2 sets the same bit whenever the vehicle is at rest (``Ekf::get_ekf_soln_status``:
    ``const_pos_mode = fake_pos || valid_fake_pos || vehicle_at_rest``), so PX4 SITL on the
    ground, ready to fly, reports 0x3ff: for PX4 the bit says nothing of the GPS (0)."""

    @property
    def first_item(self) -> int:
        """The index of the first item a mission of ours flies (the takeoff)."""
        return self.home_slots

    def mode_name(self, custom_mode: int) -> str:
        """The mode a HEARTBEAT's custom_mode names, as a ground station shows it."""
        main = (custom_mode >> self.main_shift) & self.main_mask
        sub = (custom_mode >> self.sub_shift) & 0xFF if self.sub_shift is not None else 0
        return self.modes.get((main, sub), self.modes.get((main, 0), self.unknown_mode.format(main, sub)))

    def mode_number(self, name: str) -> tuple[int, int]:
        """MAV_CMD_DO_SET_MODE's (custom main mode, custom sub mode) for ``name``."""
        for number, known in self.modes.items():
            if known == name:
                return number
        raise ValueError(f"no {self.name} mode named {name!r}")

    def custom_mode(self, main: int, sub: int = 0) -> int:
        """HEARTBEAT.custom_mode of a (main, sub) mode."""
        return (main << self.main_shift) | ((sub << self.sub_shift) if self.sub_shift is not None else 0)



ARDUPILOT = Autopilot(
    name="ardupilot",
    # Copter's mode numbers and names (ArduCopter/mode.h, Mode::name()).
    modes=MappingProxyType({(0, 0): "STABILIZE", (2, 0): "ALT_HOLD", (3, 0): "AUTO", (4, 0): "GUIDED",
                            (5, 0): "LOITER", (6, 0): "RTL", (9, 0): "LAND", (16, 0): "POSHOLD",
                            (17, 0): "BRAKE"}),
    main_shift=0, main_mask=0xFFFFFFFF, sub_shift=None, unknown_mode="MODE {0}",
    mission_mode="AUTO", return_mode="RTL", hold_mode="LOITER",
    # ArduCopter refuses to arm in AUTO (unless AUTO_OPTIONS allows it); GUIDED arms from a
    # ground station and checks the position as AUTO will.
    arm_mode="GUIDED",
    home_slots=1, whole_second_holds=True, compacts_items=True, writes_items_as_they_arrive=True,
    return_item_mode=None, modes_after_landing=frozenset(), set_current_by_command=True, flies_changed_current_item=False,
    unused_streams=MappingProxyType({}), text_ids_from_zero=False,
    mav_autopilot=M.MAV_AUTOPILOT_ARDUPILOTMEGA, estimator_message="EKF_STATUS_REPORT", estimator_msg_id=M.MAVLINK_MSG_ID_EKF_STATUS_REPORT,
    estimator_stream=M.MAV_DATA_STREAM_EXTRA3, estimator_unaided_flags=M.EKF_CONST_POS_MODE,
)
PX4 = Autopilot(
    name="px4",
    # PX4 main modes and AUTO sub modes (px4_custom_mode.h): custom_mode = main << 16 | sub << 24.
    modes=MappingProxyType({(1, 0): "MANUAL", (2, 0): "ALTCTL", (3, 0): "POSCTL", (4, 1): "AUTO.READY",
                            (4, 2): "AUTO.TAKEOFF", (4, 3): "AUTO.LOITER", (4, 4): "AUTO.MISSION",
                            (4, 5): "AUTO.RTL", (4, 6): "AUTO.LAND", (5, 0): "ACRO", (6, 0): "OFFBOARD",
                            (7, 0): "STABILIZED"}),
    main_shift=16, main_mask=0xFF, sub_shift=24, unknown_mode="PX4 {0}/{1}",
    mission_mode="AUTO.MISSION", return_mode="AUTO.RTL", hold_mode="AUTO.LOITER",
    # Armed in AUTO.MISSION PX4 climbs to the mission at once. Armed in the AUTO.LOITER it
    # boots in, it sat on the ground until the next step: there its land detector can blink
    # "in the air" (Takeoff detected, Landing detected), after which COM_DISARM_LAND (2 s of
    # its time, 0.2 s at x10) disarms it, not COM_DISARM_PRFLT; seen in CI under load.
    arm_mode="AUTO.MISSION",
    home_slots=0, whole_second_holds=False, compacts_items=False, writes_items_as_they_arrive=False,
    return_item_mode="AUTO.RTL", modes_after_landing=frozenset({"AUTO.MISSION", "AUTO.LOITER"}),
    set_current_by_command=False, flies_changed_current_item=True,
    # PX4 SITL 1.18's onboard link, unasked, above 1 Hz of its time, that the link does not read
    # (ESC_INFO 290 and ESC_STATUS 291 are in no dialect pymavlink ships).
    unused_streams=MappingProxyType({
        "ATTITUDE": M.MAVLINK_MSG_ID_ATTITUDE, "ATTITUDE_QUATERNION": M.MAVLINK_MSG_ID_ATTITUDE_QUATERNION,
        "HIGHRES_IMU": M.MAVLINK_MSG_ID_HIGHRES_IMU, "LOCAL_POSITION_NED": M.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
        "ODOMETRY": M.MAVLINK_MSG_ID_ODOMETRY, "ALTITUDE": M.MAVLINK_MSG_ID_ALTITUDE,
        "DISTANCE_SENSOR": M.MAVLINK_MSG_ID_DISTANCE_SENSOR, "ESC_INFO": 290, "ESC_STATUS": 291,
        "ATTITUDE_TARGET": M.MAVLINK_MSG_ID_ATTITUDE_TARGET,
        "POSITION_TARGET_LOCAL_NED": M.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED,
        "SERVO_OUTPUT_RAW": M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, "VFR_HUD": M.MAVLINK_MSG_ID_VFR_HUD}),
    text_ids_from_zero=True,
    mav_autopilot=M.MAV_AUTOPILOT_PX4, estimator_message="ESTIMATOR_STATUS", estimator_msg_id=M.MAVLINK_MSG_ID_ESTIMATOR_STATUS, estimator_stream=None,
    estimator_unaided_flags=0,
)

PROFILES: Mapping[str, Autopilot] = MappingProxyType({p.name: p for p in (ARDUPILOT, PX4)})
FLAVOURS: tuple[str, ...] = tuple(PROFILES)


def autopilot_name(mav_autopilot: int) -> str:
    """The configuration's name of the autopilot a HEARTBEAT's ``autopilot`` field names, or
    its MAV_AUTOPILOT name where no profile has it."""
    for profile in PROFILES.values():
        if profile.mav_autopilot == mav_autopilot:
            return profile.name
    entry = M.enums["MAV_AUTOPILOT"].get(mav_autopilot)
    return entry.name if entry is not None else f"MAV_AUTOPILOT {mav_autopilot}"


def autopilot_for(flavour: Union[str, Autopilot]) -> Autopilot:
    """The profile of the autopilot the configuration names (a profile is returned as it
    is); ``MissionError("flavour")`` for a name no profile has."""
    if isinstance(flavour, Autopilot):
        return flavour
    try:
        return PROFILES[flavour]
    except (KeyError, TypeError):
        raise MissionError("flavour", f"{flavour!r} is not one of {FLAVOURS}") from None


__all__ = ["ARDUPILOT", "Autopilot", "FLAVOURS", "Flavour", "PROFILES", "PX4", "autopilot_for", "autopilot_name"]
