"""The fleet's separation on the vehicles' own positions (``planner_service.service.fleet.separation``):
two armed UAVs too close horizontally within their layer gap have lost it; what is not known
is reported, never taken as separated; each member's position is put in one frame from its
own origin."""

from __future__ import annotations

from protocol import GeoOrigin, global_to_local, local_to_global
from protocol.messages import FleetMember, FleetPosition
from planner_service.service.fleet.separation import Seen, in_frame, judge, occupied, whereabouts

HOME = GeoOrigin()


def member(vehicle: str, origin: GeoOrigin = HOME, gap_m: float = 10.0) -> FleetMember:
    return FleetMember(vehicle=vehicle, layer_m=100.0, min_gap_m=gap_m, origin_lat_deg=origin.lat_deg,
                       origin_lon_deg=origin.lon_deg, origin_alt_m=origin.alt_m)


def seen(vehicle: str, x: float, y: float, z: float, armed: bool = True, at_s: float = 100.0) -> Seen:
    return Seen(FleetPosition(x_m=x, y_m=y, z_m=z, armed=armed), at_s)


def test_too_close_within_the_layer_gap_is_a_loss_of_separation() -> None:
    members = {"uav1": member("uav1"), "uav2": member("uav2")}
    lost = judge(members, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", 12, 9, 105)}, 100.5)
    assert lost.conflicts == ("uav1-uav2: 15 m apart horizontally, 5 m vertically",) and lost.unknown == ()
    # 12 m above: outside the 10 m gap; 25 m aside: outside the 20 m
    assert judge(members, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", 12, 9, 112)}, 100.5).conflicts == ()
    ok = judge(members, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", 25, 0, 100)}, 100.5)
    assert ok.conflicts == () and ok.closest.startswith("uav1-uav2: 25 m apart")
    # the vertical separation is the watcher's rule (fleet.vertical_separation_m), not the
    # layer gap a member announces (the separation plus a margin for altitude errors)
    wide = {"uav1": member("uav1"), "uav2": member("uav2", gap_m=15.0)}
    assert judge(wide, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", 5, 0, 112)}, 100.5).conflicts == ()
    assert judge(wide, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", 5, 0, 112)}, 100.5,
                 vertical_separation_m=15.0).conflicts != ()
    # a bound of one's own: 30 m
    assert judge(members, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", 25, 0, 100)}, 100.5,
                 min_horizontal_m=30.0).conflicts != ()


def test_vehicles_on_the_ground_and_disarmed_are_not_judged() -> None:
    members = {"uav1": member("uav1"), "uav2": member("uav2")}
    j = judge(members, {"uav1": seen("uav1", 0, 0, 0, armed=False), "uav2": seen("uav2", 3, 0, 0, armed=False)}, 100.5)
    assert j.conflicts == () and j.unknown == () and j.closest == ""


def test_unknown_is_reported_never_separated() -> None:
    members = {"uav1": member("uav1"), "uav2": member("uav2"), "uav3": None}
    j = judge(members, {"uav1": seen("uav1", 0, 0, 100, at_s=90.0)}, 100.0)
    assert j.unknown == ("uav1: position 10.0 s old", "uav2: no position", "uav3: no announcement")
    assert j.conflicts == ()


def test_positions_are_put_in_one_frame_from_each_members_origin() -> None:
    """uav2's origin lies 100 m east of uav1's: its local (-95, 0) is 5 m from uav1's (0, 0)."""
    east = GeoOrigin(*local_to_global(HOME, 100.0, 0.0, 0.0))
    members = {"uav1": member("uav1"), "uav2": member("uav2", east)}
    j = judge(members, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", -95, 0, 100)}, 100.5)
    assert j.conflicts == ("uav1-uav2: 5 m apart horizontally, 0 m vertically",)
    assert abs(global_to_local(HOME, east.lat_deg, east.lon_deg, east.alt_m)[0] - 100.0) < 0.01
    assert judge(members, {"uav1": seen("uav1", 0, 0, 100), "uav2": seen("uav2", 0, 0, 100)}, 100.5).conflicts == ()


def test_whereabouts_are_the_fresh_armed_positions_in_this_members_frame() -> None:
    """Where the members on their way home are, to rank who answers a new request first:
    put in this member's frame (as they are when the origins are one), and only the fresh,
    armed and announced."""
    east = GeoOrigin(*local_to_global(HOME, 100.0, 0.0, 0.0))
    members = {"uav1": member("uav1"), "uav2": member("uav2", east), "uav3": member("uav3"), "uav4": None,
               "uav5": member("uav5")}
    last = {"uav1": seen("uav1", 10, 20, 100), "uav2": seen("uav2", -95, 0, 100), "uav3": seen("uav3", 0, 0, 100,
            at_s=90.0), "uav4": seen("uav4", 0, 0, 100), "uav5": seen("uav5", 0, 0, 0, armed=False)}
    where = whereabouts(HOME, ["uav1", "uav2", "uav3", "uav4", "uav5", "uav6"], members, last, 100.5)
    assert where.keys() == {"uav1", "uav2"} and where["uav1"] == (10, 20)
    assert abs(where["uav2"][0] - 5.0) < 0.01 and abs(where["uav2"][1]) < 0.01
    assert in_frame(HOME, members["uav1"], last["uav1"].position) == (10, 20, 100)



def test_the_points_another_vehicle_is_over() -> None:
    """A hovering point within the radius of a vehicle, horizontally, is occupied (a member
    plans without it, whatever it heard of that member's claims); one further is not."""
    points = [(0.0, 0.0), (50.0, 0.0), (100.0, 50.0)]
    assert occupied({"uav2": (3.0, 4.0), "uav3": (100.0, 61.0)}, points, 10.0) == {0}
    assert occupied({"uav2": (44.0, 8.0)}, points, 10.0) == {1}
    assert occupied({}, points, 10.0) == frozenset()

def test_a_member_gone_with_its_vehicle_armed_stays_unknown() -> None:
    """Its service's token went while its last status showed the vehicle armed: it may still
    fly its uploaded mission, and nothing says where. Unknown until its service is back
    (then it is a member again, judged on its statuses)."""
    members = {"uav1": member("uav1")}
    j = judge(members, {"uav1": seen("uav1", 0, 0, 100)}, 112.0, stale_s=20.0,
              lost={"uav2": seen("uav2", 3, 0, 100, at_s=100.0)})
    assert j.unknown == ("uav2: its service is gone; its vehicle was armed when last seen 12 s ago",)
    assert j.conflicts == ()  # 3 m away when last seen, but not judged on an old position
    back = {"uav1": member("uav1"), "uav2": member("uav2")}
    j = judge(back, {"uav1": seen("uav1", 0, 0, 100, at_s=112.0)}, 112.0, lost={"uav2": seen("uav2", 3, 0, 100)})
    assert j.unknown == ("uav2: no position",)  # back as a member: its status awaited
