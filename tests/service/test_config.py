"""Configuration: TOML + overrides, every refusal names its key, the example documents every key."""

from __future__ import annotations

import dataclasses
import re
import tomllib
from pathlib import Path

import pytest

from planner_service.service.config import (ServiceConfig, _SECTIONS, build_config, load_config, parse_overrides,
                                            to_toml)
from planner_service.service.errors import ConfigError

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "planner.example.toml"


def test_defaults_are_the_field_preset_on_loopback() -> None:
    c = load_config(None)
    assert c.scenario().name == "field"
    assert c.zenoh.mode == "peer" and c.zenoh.listen == ("tcp/127.0.0.1:7447",) and not c.zenoh.multicast_scouting
    assert c.mavlink.backend == "pymavlink" and c.mavlink.start_mission is False


def test_file_then_overrides(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text('[zenoh]\nmode = "client"\nconnect = ["tcp/127.0.0.1:9000"]\n'
                    '[planner]\nbudget_ms = 50\n[scenario]\npreset = "field"\nspeed_mps = 15\n')
    c = load_config(path, parse_overrides(["planner.budget_ms=75.5", "mavlink.start_mission=yes",
                                           "zenoh.listen=tcp/127.0.0.1:1,tcp/127.0.0.1:2", "scenario.num_users=4"]))
    assert c.zenoh.mode == "client" and c.zenoh.connect == ("tcp/127.0.0.1:9000",)
    assert c.planner.budget_ms == 75.5 and c.mavlink.start_mission is True
    assert c.zenoh.listen == ("tcp/127.0.0.1:1", "tcp/127.0.0.1:2")
    assert c.scenario().speed_mps == 15.0 and c.scenario().num_users == 4


@pytest.mark.parametrize("overrides, key", [
    ({"zenoh.mode": "broker"}, "zenoh.mode"),
    ({"zenoh.mode": "client"}, "zenoh.connect"),
    ({"zenoh.status_hz": "0.5"}, "zenoh.status_hz"),
    ({"zenoh.vehicle": "a/*"}, "zenoh.vehicle"),
    ({"mavlink.backend": "dronekit"}, "mavlink.backend"),
    ({"mavlink.retries": "many"}, "mavlink.retries"),
    ({"planner.budget_ms": "0"}, "planner.budget_ms"),
    ({"planner.budget": "5"}, "planner.budget"),
    ({"planner.algo": "dqn"}, "planner.algo"),
    ({"scenario.speed_kph": "5"}, "scenario.speed_kph"),
    ({"safety.max_altitude_m": "50"}, "safety.max_altitude_m"),
    ({"safety.energy_margin_j": "-1"}, "safety.energy_margin_j"),
    ({"journal.synchronous": "SOMETIMES"}, "journal.synchronous"),
    ({"sortie.next_battery_fraction": "1.2"}, "sortie.next_battery_fraction"),
    ({"sortie.next_battery_fraction": "0.1"}, "sortie.next_battery_fraction"),  # at the RTL threshold
    ({"sortie.repeat": "maybe"}, "sortie.repeat"),
    ({"nosuch.key": "1"}, "nosuch"),
])
def test_bad_values_name_their_key(overrides: dict[str, str], key: str) -> None:
    with pytest.raises(ConfigError) as err:
        build_config({}, overrides)
    assert err.value.key == key


def test_bad_toml_is_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[zenoh\nmode=")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(path)
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")


def test_round_trip_through_toml(tmp_path: Path) -> None:
    c = build_config({}, {"zenoh.listen": "tcp/127.0.0.1:5", "scenario.speed_mps": "12", "planner.seed": "3"})
    path = tmp_path / "c.toml"
    path.write_text(to_toml(c))
    assert load_config(path) == c


def test_the_example_file_loads_and_documents_every_key() -> None:
    text = EXAMPLE.read_text()
    raw = tomllib.loads(text)
    assert build_config(raw) == build_config({}, {}) or isinstance(build_config(raw), ServiceConfig)
    for section, cls in _SECTIONS.items():
        for f in dataclasses.fields(cls):
            # each key appears with a comment line just above it
            pattern = rf"#[^\n]*\n(#[^\n]*\n)*{f.name} = "
            assert f.name in raw[section], f"{section}.{f.name} missing from the example"
            assert re.search(pattern, text), f"{section}.{f.name} has no comment in the example"
    assert "preset" in raw["scenario"]
