"""``sortie/evidence.py`` on its own: the record and its judgement, without the sortie
logic (which is tested through it in test_whose_mission.py)."""

from __future__ import annotations

import math

import pytest

from planner_service.service.sortie.evidence import Evidence, Settled, judge, off_segment_m
from planner_service.service.sortie.inputs import VehicleSnapshot
from tests.service.test_sortie_logic import FakeWorld, fly_to_first_point

FLYING = Settled(over=False, commanding=False, granted=True)


def held_and_vehicle() -> tuple:
    run, _ = fly_to_first_point(FakeWorld())
    return run.s.onboard.held, run.v


def test_off_segment() -> None:
    assert off_segment_m((0.0, 0.0), (100.0, 0.0), (50.0, 30.0)) == pytest.approx(30.0)
    assert off_segment_m((0.0, 0.0), (100.0, 0.0), (130.0, 40.0)) == pytest.approx(50.0), "past the end: to the end"
    assert off_segment_m((5.0, 5.0), (5.0, 5.0), (8.0, 9.0)) == pytest.approx(5.0), "a leg of no length"


def test_the_periodic_read_back_is_due_only_under_authority_in_flight() -> None:
    held, v = held_and_vehicle()
    e = Evidence(checked_at=0.0)
    kw = {"leg_tolerance_m": 0.0, "readback_interval_s": 30.0}
    assert judge(e, held, v, 29.0, FLYING, **kw)[1] is None
    assert judge(e, held, v, 30.0, FLYING, **kw)[1].periodic
    assert judge(e, held, v, 30.0, Settled(over=False, commanding=False, granted=False), **kw)[1] is None
    assert judge(e, held, VehicleSnapshot(**{**v.__dict__, "airborne": False}), 30.0, FLYING, **kw)[1] is None
    assert judge(e, held, v, 1e9, FLYING, leg_tolerance_m=0.0, readback_interval_s=0.0)[1] is None


def test_a_count_once_explained_doubts_nothing_again_and_the_count_is_judged_after_the_sortie_too() -> None:
    held, v = held_and_vehicle()
    odd = VehicleSnapshot(**{**v.__dict__, "mission_total": len(held.items) + 3})
    e, doubt = judge(Evidence(), held, odd, 0.0, Settled(over=True, commanding=False, granted=False),
                     leg_tolerance_m=30.0, readback_interval_s=0.0)
    assert doubt is not None and "counts" in doubt.why and e.count_at_doubt == len(held.items) + 3
    assert judge(e.explained(), held, odd, 0.0, FLYING, leg_tolerance_m=30.0, readback_interval_s=0.0)[1] is None


def test_known_starts_the_item_and_leg_checks_afresh_and_keeps_an_id_the_read_back_did_not_say() -> None:
    e = Evidence(mission_id=7, id_at_doubt=9, top_seq=4, leg=(4, 0.0, 0.0, 1.0), off_leg=2)
    assert Evidence().known(5.0, 3, read_back=False) == Evidence(mission_id=3, checked_at=5.0)
    back = e.known(6.0, 0, read_back=True)
    assert (back.mission_id, back.id_explained, back.top_seq, back.leg, back.off_leg, back.checked_at) == \
        (7, 9, -1, None, 0, 6.0)
    assert math.isinf(Evidence().checked_at)
