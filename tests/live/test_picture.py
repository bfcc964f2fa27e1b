"""The fleet picture (the live map's and ``operator watch``'s read model), pure: each decision
on hand-made messages, in milliseconds."""

from __future__ import annotations

import math

import pytest

from planner_service.live.geojson import NoOrigin, feature_collection
from planner_service.live.picture import STATUS_STALE_S, FleetPicture
from planner_service.service.fleet.separation import Judgement
from protocol import Event, GeoOrigin, PendingRequest, Plan, PlanPoint, Status, UserPlace, local_to_global
from protocol.messages import FleetMember

ORIGIN = GeoOrigin(47.397742, 8.545594, 488.0)


def member(vehicle: str, layer_m: float, east_m: float = 0.0) -> FleetMember:
    lat, lon, _ = local_to_global(ORIGIN, east_m, 0.0, 0.0)
    return FleetMember(vehicle=vehicle, layer_m=layer_m, min_gap_m=15.0, origin_lat_deg=lat, origin_lon_deg=lon,
                       origin_alt_m=ORIGIN.alt_m)


def status(x: float, y: float, z: float = 80.0, **kw: object) -> Status:
    fields = dict(vehicle="uav1", time_s=1000.0, phase="flying", armed=True, mode="AUTO", x_m=x, y_m=y, z_m=z,
                  battery_fraction=0.8, battery_source="autopilot", position_ok=True, authority="operator")
    fields.update(kw)
    return Status(**fields)  # type: ignore[arg-type]


def plan(plan_id: int, time_s: float, *users: str) -> Plan:
    return Plan(plan_id=plan_id, time_s=time_s, points=[PlanPoint(100.0 * i, 50.0, 80.0, 10.0, u)
                                                        for i, u in enumerate(users, 1)])


def test_a_vehicle_is_where_its_last_status_says_with_a_trail_that_skips_holds() -> None:
    p = FleetPicture("uavmec")
    for i, (x, y) in enumerate([(0, 0), (0.5, 0), (10, 0), (10.2, 0.1), (30, 5)]):
        p.on_status("uav1", status(x, y), at=float(i))
    v = p.snapshot(now=4.5, now_wall=2000.0)["vehicles"][0]
    assert (v["x_m"], v["y_m"], v["z_m"]) == (30, 5, 80.0)
    assert v["trail"] == [[0, 0], [10, 0], [30, 5]]  # within 2 m of the last kept: a hold, not a step
    assert v["status_age_s"] == pytest.approx(0.5) and v["battery"] == 0.8 and v["authority"] == "operator"


def test_unknown_stays_unknown() -> None:
    """A vehicle heard only by its token has no position (not 0, 0), no battery, no authority;
    a status whose position is not ok adds nothing to the trail."""
    p = FleetPicture("uavmec")
    p.on_alive("uav2", True)
    p.on_status("uav3", status(5, 5, position_ok=False, battery_fraction=None, battery_source="unknown"), at=0.0)
    by = {v["id"]: v for v in p.snapshot(0.1, 0.0)["vehicles"]}
    assert by["uav2"]["x_m"] is None and by["uav2"]["battery"] is None and by["uav2"]["authority"] is None
    assert by["uav3"]["battery"] is None and by["uav3"]["trail"] == []
    texts = [a["text"] for a in p.snapshot(0.1, 0.0)["alerts"] if a["vehicle"] == "uav3"]
    assert "battery unknown" in texts and any("position not known" in t for t in texts)


def test_the_next_point_is_the_first_whose_user_was_not_served_since_the_plan() -> None:
    p = FleetPicture("uavmec")
    p.on_plan("uav1", plan(4, 100.0, "u1", "u2", "u3"))
    assert p.next_point("uav1") == 0
    p.on_event("uav1", Event(event="user_served", time_s=90.0, user_id="u1"))  # before the plan: an older service
    assert p.next_point("uav1") == 0
    p.on_event("uav1", Event(event="user_served", time_s=120.0, user_id="u1"))
    p.on_event("uav1", Event(event="waypoint_skipped", time_s=121.0, user_id="u2"))
    assert p.next_point("uav1") == 2
    p.on_event("uav1", Event(event="user_served", time_s=150.0, user_id="u3"))
    assert p.next_point("uav1") is None  # on the way home
    p.on_plan("uav1", plan(3, 99.0, "u9"))  # an older plan arriving late changes nothing
    assert p.vehicles["uav1"].plan.plan_id == 4
    p.on_plan("uav1", plan(5, 160.0, "u3", "u1"))  # a new plan: its own next point
    assert p.next_point("uav1") == 0


def test_eta_and_user_states_come_from_the_services_places() -> None:
    p = FleetPicture("uavmec")
    p.on_plan("uav1", plan(4, 100.0, "u1", "u2"))
    p.on_place("uav1", UserPlace(user_id="u1", plan_id=4, time_s=100.0, place=1, eta_s=30.0, backlog=12))
    p.on_place("uav1", UserPlace(user_id="u2", plan_id=4, time_s=100.0, place=2, eta_s=80.0, backlog=5))
    p.on_place("uav2", UserPlace(user_id="u4", plan_id=1, time_s=100.0, place=None, backlog=6))
    p.on_place("uav2", UserPlace(user_id="u5", plan_id=1, time_s=100.0, place=None, backlog=0, services=1,
                                 served_tasks=9))
    p.on_pending("uav1", [PendingRequest(7, "u1", 210.0, 330.0, 0.0, 12)])
    snap = p.snapshot(1.0, now_wall=110.0)
    assert snap["vehicles"][0]["plan"]["next"] == 0 and snap["vehicles"][0]["plan"]["eta_s"] == pytest.approx(20.0)
    users = {u["id"]: u for u in snap["users"]}
    assert users["u1"]["state"] == "next" and (users["u1"]["x_m"], users["u1"]["y_m"]) == (210.0, 330.0)
    assert users["u2"]["state"] == "planned" and users["u2"]["eta_s"] == pytest.approx(70.0)
    assert users["u4"]["state"] == "waiting" and users["u4"]["x_m"] is None  # no position known: not drawn
    assert users["u5"]["state"] == "served" and users["u5"]["served_tasks"] == 9
    # a place from an older plan gives no ETA for the new one
    p.on_plan("uav1", plan(5, 120.0, "u1"))
    assert p.snapshot(1.0, 125.0)["vehicles"][0]["plan"]["eta_s"] is None


def test_a_member_with_its_own_origin_is_drawn_in_the_pictures_frame() -> None:
    """Each member reports metres from its own origin; the picture puts them in one frame."""
    p = FleetPicture("uavmec")
    p.on_fleet({"uav1": member("uav1", 80.0), "uav2": member("uav2", 100.0, east_m=250.0)}, None, {})
    p.on_status("uav2", status(10.0, 20.0), at=0.0)
    p.on_plan("uav2", plan(1, 0.0, "u1"))
    v = p.snapshot(0.0, 0.0)["vehicles"][0]
    assert p.origin is not None and p.origin.lat_deg == pytest.approx(ORIGIN.lat_deg, abs=1e-9)  # uav1's, first
    assert v["x_m"] == pytest.approx(260.0, abs=0.05) and v["y_m"] == pytest.approx(20.0, abs=0.05)
    assert v["plan"]["points"][0]["x_m"] == pytest.approx(350.0, abs=0.05)
    assert v["layer_m"] == 100.0


def test_separation_is_none_alone_unknown_until_judged_and_lost_is_an_error_alert() -> None:
    p = FleetPicture("uavmec")
    assert p.snapshot(0, 0)["separation"]["state"] == "none"
    members = {"uav1": member("uav1", 80.0), "uav2": member("uav2", 100.0)}
    p.on_fleet(members, None, {})
    assert p.snapshot(0, 0)["separation"]["state"] == "unknown"  # members, no judgement: never "ok"
    p.on_fleet(members, Judgement((), ("uav2: no position",)), {})
    assert p.snapshot(0, 0)["separation"]["state"] == "unknown"
    p.on_fleet(members, Judgement((), (), "uav1-uav2: 300 m"), {})
    assert p.snapshot(0, 0)["separation"]["state"] == "ok"
    p.on_fleet(members, Judgement(("uav1-uav2: 3 m apart horizontally, 4 m vertically",), ()), {"uav1": {"u1"}},
               lost=["uav3"])
    snap = p.snapshot(0, 0)
    assert snap["separation"]["state"] == "lost"
    assert snap["alerts"][0] == {"severity": "error", "vehicle": None,
                                 "text": "SEPARATION LOST uav1-uav2: 3 m apart horizontally, 4 m vertically"}
    assert any(a["vehicle"] == "uav3" and "armed" in a["text"] for a in snap["alerts"])


def test_alerts_name_revoked_authority_degraded_a_stale_status_and_a_gone_service() -> None:
    p = FleetPicture("uavmec")
    p.on_status("uav1", status(0, 0, authority="revoked", authority_detail="the pilot switched to LOITER"), at=0.0)
    p.on_status("uav2", status(0, 0, degraded="the journal cannot be written"), at=0.0)
    p.on_status("uav3", status(0, 0), at=0.0)
    p.on_alive("uav3", False)
    alerts = {(a["vehicle"], a["severity"], a["text"]) for a in p.snapshot(STATUS_STALE_S + 1.0, 0)["alerts"]}
    assert ("uav1", "error", "authority revoked: the pilot switched to LOITER") in alerts
    assert ("uav2", "error", "DEGRADED the journal cannot be written") in alerts
    assert ("uav3", "error", "service gone with its vehicle armed") in alerts
    assert ("uav1", "warning", "no status for 4 s") in alerts
    assert not any(v == "uav3" and t.startswith("no status") for v, _, t in alerts)  # said once: gone


def test_every_change_moves_the_version_and_a_repeated_fleet_view_does_not() -> None:
    p = FleetPicture("uavmec")
    seen = [p.version]
    p.on_status("uav1", status(0, 0), 0.0)
    p.on_fleet({"uav1": member("uav1", 80.0)}, Judgement((), ()), {"uav1": ["u1"]})
    seen.append(p.version)
    p.on_fleet({"uav1": member("uav1", 80.0)}, Judgement((), ()), {"uav1": ["u1"]})
    assert p.version == seen[-1] and seen[0] < seen[1]


def test_geojson_places_the_picture_on_the_earth_or_says_why_not() -> None:
    p = FleetPicture("uavmec")
    p.on_status("uav1", status(0, 0), 0.0)
    with pytest.raises(NoOrigin, match="--origin"):
        feature_collection(p.snapshot(0, 0))
    p = FleetPicture("uavmec", origin=ORIGIN)
    p.on_status("uav1", status(0, 0), 0.0)
    p.on_status("uav1", status(0, 1000.0), 1.0)
    p.on_plan("uav1", plan(1, 0.0, "u1", "u2"))
    p.on_pending("uav1", [PendingRequest(1, "u1", 0.0, 0.0, 0.0, 5)])
    fc = feature_collection(p.snapshot(1.0, 0.0))
    kinds = {f["properties"]["kind"]: f for f in fc["features"]}
    assert set(kinds) == {"vehicle", "trail", "plan", "user"}
    lon, lat, alt = kinds["vehicle"]["geometry"]["coordinates"]
    assert alt == pytest.approx(568.0) and lon == pytest.approx(ORIGIN.lon_deg, abs=1e-7)
    # 1000 m north is 1000 / 111 km of latitude
    assert (lat - ORIGIN.lat_deg) * math.pi / 180 * 6_371_000 == pytest.approx(1000.0, rel=0.01)
    assert kinds["plan"]["properties"]["users"] == ["u1", "u2"]
    assert kinds["user"]["geometry"]["coordinates"][:2] == [ORIGIN.lon_deg, ORIGIN.lat_deg]
