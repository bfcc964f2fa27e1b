"""One user's place across the fleet (``protocol.fleet_places``): the member whose plan has
the user soonest, older words and other users' ignored, a member gone forgotten; and the keys
it is read from."""

from __future__ import annotations

import pytest

from protocol import FleetKeys, ProtocolError
from protocol.fleet_places import FleetPlaces
from protocol.messages import UserPlace


def place(plan_id: int, at_s: float, eta_s: float | None, user: str = "u", sortie: int = 1) -> UserPlace:
    return UserPlace(user_id=user, sortie=sortie, plan_id=plan_id, time_s=at_s,
                     place=None if eta_s is None else 1, eta_s=eta_s)


def test_the_member_that_plans_the_user_soonest_holds_its_place() -> None:
    places = FleetPlaces("u")
    assert places.where() is None
    assert places.update("uav1", place(3, 100.0, None))  # uav1 holds the request, plans it not
    assert places.where() is None
    assert places.update("uav2", place(7, 101.0, 30.0))
    here = places.where()
    assert here is not None and here.vehicle == "uav2" and here.due_s == 131.0
    # uav1 plans it too, due sooner in wall clock (a claim not heard yet): the sooner is the place
    assert places.update("uav1", place(4, 105.0, 20.0))
    assert places.where().vehicle == "uav1"  # type: ignore[union-attr]
    assert not places.update("uav1", place(3, 106.0, None))  # an older plan, delivered late
    assert not places.update("uav1", place(9, 106.0, 1.0, user="v"))  # another user's
    assert places.where().vehicle == "uav1"  # type: ignore[union-attr]
    assert places.update("uav1", place(1, 200.0, None, sortie=2))  # a new sortie renumbers the plans
    assert places.where().vehicle == "uav2"  # type: ignore[union-attr]


def test_a_member_gone_is_forgotten_and_a_tie_goes_to_the_smaller_id() -> None:
    places = FleetPlaces("u")
    places.update("uav2", place(1, 100.0, 10.0))
    places.update("uav1", place(1, 105.0, 5.0))
    assert places.where().vehicle == "uav1"  # type: ignore[union-attr]
    assert places.forget("uav1") and not places.forget("uav1")
    assert places.where().vehicle == "uav2" and list(places.members()) == ["uav2"]  # type: ignore[union-attr]


def test_the_keys_of_a_users_place_on_every_member() -> None:
    keys = FleetKeys("pfx")
    assert keys.user_places("u-1") == "pfx/*/users/u-1"
    assert keys.place_vehicle("pfx/uav3/users/u-1", "u-1") == "uav3"
    for other in ("pfx/uav3/users/u-2", "pfx/fleet/users/u-1", "other/uav3/users/u-1", "pfx/a/b/users/u-1",
                  "pfx/uav3/users/u-1/x", "pfx"):
        assert keys.place_vehicle(other, "u-1") is None, other
    assert keys.status_vehicle("pfx/uav3/status") == "uav3" and keys.status_vehicle("pfx/fleet/status") is None
    with pytest.raises(ProtocolError):
        keys.user_places("*")
