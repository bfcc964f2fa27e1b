"""A fleet's vehicle stubs stand at their homes, ``BASE_STEP_M`` apart east, and take every
point of the fleet's area (planner_service/harness/fleet_demo.py ``stub_fence``): with each
stub's fence around the area from its own home, UAV 5 of 5 (160 m east) refused every point
west of 60 m (MAV_MISSION_INVALID_PARAM5_X), and flew parts of missions (bench --fleet --scale,
N = 10: uav7 "plan 3 not flown", "the vehicle lost its mission" again and again)."""

from __future__ import annotations

from pathlib import Path

from planner_service.harness.fleet_demo import BASE_STEP_M, stub_fence
from planner_service.harness.processes import Child, free_port
from protocol import GeoOrigin, local_to_global
from tests.support.gcs import M, GroundStation, ten_items


def test_the_eastmost_uavs_stub_takes_a_mission_over_the_west_of_the_area(tmp_path: Path) -> None:
    uavs = 5
    lat, lon, alt = local_to_global(GeoOrigin(), BASE_STEP_M * (uavs - 1), 0.0, 0.0)
    port = free_port()
    stub = Child("sim_bridge", ["vehicle", "--mavlink", f"udpin:127.0.0.1:{port}", "--gps-delay-s", "0",
                                "--origin", f"{lat:.7f},{lon:.7f},{alt:.2f}", *stub_fence(uavs, 120.0)],
                 tmp_path / "vehicle.log")
    gcs = None
    try:
        stub.wait_ready("listening")
        gcs = GroundStation(f"udpout:127.0.0.1:{port}")
        gcs.wait_vehicle()
        items = ten_items()  # over the fleet's area, its first point 30 m east of the area's edge
        assert gcs.upload(items) == M.MAV_MISSION_ACCEPTED, stub.log()[-1500:]
    finally:
        if gcs is not None:
            gcs.close()
        assert stub.stop() == 0
