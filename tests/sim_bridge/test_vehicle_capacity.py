"""The stub's mission capacity is configurable (``--max-mission-items``): one item more is
refused with NO_SPACE and the mission held stays."""

from __future__ import annotations

import pytest

from protocol.geodesy import GeoOrigin
from protocol.mission import HoverPoint, encode_path, same_items
from tests.support.gcs import M, GroundStation, as_stored


@pytest.mark.timeout(30)
def test_an_upload_over_the_capacity_gets_no_space(vehicle) -> None:
    _, port = vehicle("--max-mission-items", "5")
    gcs = GroundStation(f"udpout:127.0.0.1:{port}")
    try:
        gcs.wait_vehicle()
        five = encode_path([HoverPoint(10.0, 20.0, 30.0), HoverPoint(40.0, 50.0, 30.0)], GeoOrigin())
        six = encode_path([HoverPoint(10.0, 20.0, 30.0)] * 3, GeoOrigin())
        assert (len(five), len(six)) == (5, 6)
        assert gcs.upload(five) == M.MAV_MISSION_ACCEPTED
        assert gcs.upload(six) == M.MAV_MISSION_NO_SPACE
        assert same_items(gcs.download()[1:], as_stored(five, "ardupilot")[1:])
    finally:
        gcs.close()
