"""The stub's conduct is data keyed by the autopilot profile: one behaviour per profile, and
no branch on the autopilot's name anywhere in the stub (issue 24)."""

import re
from pathlib import Path

import pytest

from protocol.autopilot import PROFILES
from protocol.errors import MissionError
from sim_bridge.vehicle.behaviour import BEHAVIOURS, behaviour_for
from sim_bridge.vehicle.params import PARAMS
from sim_bridge.vehicle.streams import STREAM_RULES
from sim_bridge.vehicle.telemetry import MISSION_CURRENT, SENSORS

STUB = Path(__file__).resolve().parents[2] / "sim_bridge"
NAME_TEST = re.compile(r'flavour *[!=]=|[!=]= *"(ardupilot|px4)"|\.ardupilot\b')


def test_every_profile_has_a_behaviour_and_every_table_an_entry() -> None:
    for table in (BEHAVIOURS, PARAMS, STREAM_RULES, MISSION_CURRENT, SENSORS):
        assert set(table) == set(PROFILES)
    for name, profile in PROFILES.items():
        assert behaviour_for(name).autopilot is profile
        assert behaviour_for(profile) is BEHAVIOURS[name]


def test_an_unknown_autopilot_is_named() -> None:
    with pytest.raises(MissionError) as err:
        behaviour_for("apm")
    assert err.value.where == "flavour" and "'apm'" in str(err.value)


def test_the_stub_never_branches_on_the_autopilots_name() -> None:
    found = [f"{path.relative_to(STUB)}:{n}: {line.strip()}"
             for path in sorted(STUB.rglob("*.py"))
             for n, line in enumerate(path.read_text().splitlines(), 1) if NAME_TEST.search(line)]
    assert found == []
