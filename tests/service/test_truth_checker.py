"""The checker that holds the journal against the vehicle's own log must be able to fail:
a service longer than the stay, at a point never visited, or a second service on one stay;
SITL's dataflash POS records read as the same track, in time order across restarts."""

from __future__ import annotations

import math

import numpy as np

from planner_service.model import pack, preset
from planner_service.service.planning import hold_time_s
from protocol import GeoOrigin, local_to_global
from tests.support.truth import Fix, Recorded, false_services, one_clock, sitl_track, stays

SCENARIO = preset("field")
P = (120.0, 200.0, 100.0)
USER = (130.0, 190.0, 0.0)
ORIGIN = GeoOrigin()


def track() -> list[Fix]:
    """Flies in, holds at P from t=10 to t=40 (1 s fixes), flies off."""
    out = [Fix(float(t), (120.0 - 10 * (10 - t), 200.0, 100.0)) for t in range(0, 10)]
    out += [Fix(float(t), (120.4, 199.7, 100.0)) for t in range(10, 41)]
    out += [Fix(float(t), (120.0 + 10 * (t - 40), 200.0, 100.0)) for t in range(41, 60)]
    return out


def tasks_for(seconds: float) -> int:
    """The most tasks an upload of ``seconds`` carries from P."""
    per_task = hold_time_s(pack(SCENARIO), np.array(P), np.array(USER), SCENARIO.bits_per_task)
    return int(seconds // per_task)


def test_stays_at_a_point() -> None:
    assert stays(track(), P, 5.0) == [(10.0, 40.0)]
    assert stays(track(), (400.0, 400.0, 100.0), 5.0) == []


def test_what_the_log_bears_out_and_what_it_does_not() -> None:
    ok = Recorded(1, "a", tasks_for(29.0), P, USER)
    assert false_services([ok], track(), SCENARIO, 5.0, 1.0) == []
    too_long = Recorded(1, "a", tasks_for(29.0) + 3, P, USER)
    assert len(false_services([too_long], track(), SCENARIO, 5.0, 1.0)) == 1
    never = Recorded(2, "b", 1, (400.0, 400.0, 100.0), USER)
    (why,) = false_services([ok, never], track(), SCENARIO, 5.0, 1.0)
    assert "never came" in why
    twice = [ok, Recorded(3, "a", 1, P, USER)]
    assert len(false_services(twice, track(), SCENARIO, 5.0, 1.0)) == 1, "one stay, one service"


def pos(time_us: int, xyz: tuple[float, float, float]) -> dict[str, object]:
    """A dataflash POS record as ``Sitl.read_log`` gives it, at local ``xyz`` of the origin."""
    lat, lon, alt = local_to_global(ORIGIN, *xyz)
    return {"mavpackettype": "POS", "TimeUS": time_us, "Lat": lat, "Lng": lon, "Alt": alt,
            "RelHomeAlt": xyz[2], "RelOriginAlt": xyz[2]}


def test_sitl_track_reads_pos_in_local_metres_and_keeps_time_going_across_a_restart() -> None:
    """Two boots (the second log's clock starts again): the fixes stay in time order, so a
    stay before the restart cannot bear out a service after it, nor the other way round."""
    first = [pos(int(t * 1e6), (120.0 + 10 * min(t - 10, 0), 200.0, 100.0)) for t in range(0, 41)]
    second = [pos(int(t * 1e6), (0.0, 0.0, 0.0)) for t in range(2, 20)]
    log = [*first, {"mavpackettype": "MSG", "TimeUS": 5, "Message": "x"}, *second]
    fixes = sitl_track(log, ORIGIN)
    assert len(fixes) == len(first) + len(second)
    assert all(b.time_s > a.time_s for a, b in zip(fixes, fixes[1:]))
    assert math.dist(fixes[0].xyz, (20.0, 200.0, 100.0)) < 1e-3 and fixes[0].time_s == 0.0
    assert math.dist(fixes[25].xyz, P) < 1e-3 and fixes[25].time_s == 25.0
    assert stays(fixes, P, 5.0) == [(10.0, 40.0)]
    assert stays(fixes, (0.0, 0.0, 0.0), 1.0)[0][0] > 40.0  # the second boot comes after
    ok = Recorded(1, "a", tasks_for(29.0), P, USER)
    assert false_services([ok], fixes, SCENARIO, 5.0, 1.0) == []
    at_home = Recorded(2, "b", 1, (0.0, 0.0, 0.0), USER)
    assert false_services([at_home, ok], fixes, SCENARIO, 5.0, 1.0), "order kept: home was after P"


def test_a_stub_restarted_from_its_saved_flight_keeps_its_stays_in_order() -> None:
    """A stub saves its flight during a hold, leaves the point and is killed; restarted, it
    comes back where the saved flight was, its clock 6 s back (a CI run: the service's
    second hold at the point began on the restored clock before the end of the first
    hold's stay, and every later service was judged "never came"). On one clock both holds
    are borne out, in their order."""
    before = [Fix(float(t), P) for t in range(10, 41)]  # first hold, then flying off
    before += [Fix(float(t), (120.0 + 10 * (t - 40), 200.0, 100.0)) for t in range(41, 45)]
    after = [Fix(float(t), P) for t in range(38, 69)]  # saved at t = 38: the second hold there
    first, second = Recorded(1, "a", tasks_for(29.0), P, USER), Recorded(2, "b", tasks_for(29.0), P, USER)
    assert false_services([first, second], before + after, SCENARIO, 5.0, 1.0), "as logged: one stay too early"
    fixes = one_clock(before + after)
    assert all(b.time_s > a.time_s for a, b in zip(fixes, fixes[1:]))
    assert false_services([first, second], fixes, SCENARIO, 5.0, 1.0) == []
