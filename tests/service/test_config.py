"""Configuration: TOML + overrides, every refusal names its key, the example documents every key."""

from __future__ import annotations

import dataclasses
import re
import tomllib
from pathlib import Path

import pytest

from planner_service.model import Scenario
from planner_service.service.config import (SCENARIO_DEFAULTS, SECTIONS, ServiceConfig, build_config, load_config,
                                            parse_overrides, to_toml)
from planner_service.service.errors import ConfigError
from planner_service.settings import kinds, read

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
    assert build_config(raw) == build_config({}, {}) == ServiceConfig()
    for section, cls in SECTIONS.items():
        for f in dataclasses.fields(cls):
            # each key appears with a comment line just above it
            pattern = rf"#[^\n]*\n(#[^\n]*\n)*{f.name} = "
            assert f.name in raw[section], f"{section}.{f.name} missing from the example"
            assert re.search(pattern, text), f"{section}.{f.name} has no comment in the example"
    assert "preset" in raw["scenario"]


def test_the_example_shows_every_key_with_its_default() -> None:
    # docs/planner.example.toml cannot drift from the code: every field of every section is
    # there, read by its type, with the value the code defaults to; [scenario] holds the
    # preset and exactly the service's own scenario defaults.
    raw = tomllib.loads(EXAMPLE.read_text())
    assert set(raw) == {*SECTIONS, "scenario"}
    for section, cls in SECTIONS.items():
        defaults = cls()
        assert set(raw[section]) == {f.name for f in dataclasses.fields(cls)}, section
        for name, kind in kinds(cls).items():
            shown = read(f"{section}.{name}", kind, raw[section][name])
            default = getattr(defaults, name)
            assert shown == default, f"{section}.{name}: the example shows {shown!r}, the default is {default!r}"
    scenario = dict(raw["scenario"])
    assert read("scenario.preset", kinds(ServiceConfig)["scenario_preset"], scenario.pop("preset")) == "field"
    assert {k: read(f"scenario.{k}", kinds(Scenario)[k], v) for k, v in scenario.items()} == dict(SCENARIO_DEFAULTS)


def test_scenario_overrides_are_values_of_their_fields_type() -> None:
    # The service reads [scenario] keys by the scenario's own field types, once: values, not text.
    c = build_config({"scenario": {"speed_mps": 15, "allow_stay": "on"}}, {"scenario.num_users": "4"})
    assert dict(c.scenario_overrides) == {"task_model": "backlog", "task_arrival_period_s": 55.0, "speed_mps": 15.0,
                                          "allow_stay": True, "num_users": 4}
    assert all(not isinstance(v, str) for k, v in c.scenario_overrides if k != "task_model")
    s = c.scenario()
    assert (s.speed_mps, s.allow_stay, s.num_users, s.task_model) == (15.0, True, 4, "backlog")
    with pytest.raises(ConfigError) as err:
        build_config({"scenario": {"speed_mps": "fast"}})
    assert err.value.key == "scenario.speed_mps" and "cannot read 'fast' as float" in err.value.message
    with pytest.raises(ConfigError) as err:
        build_config({"scenario": {"task_model": "queue"}})
    assert err.value.key == "scenario.task_model"


def test_the_users_draw_from_the_services_scenario() -> None:
    # ``sim_bridge users`` is given the service's scenario as --preset and --set texts: read back,
    # they are the scenario the service plans on, field for field.
    from planner_service.model import preset

    c = build_config({"scenario": {"speed_mps": 12.5, "allow_stay": True, "hover_power_w": 354}},
                     {"scenario.num_users": "4"})
    args = c.scenario_arguments()
    assert args[:2] == ["--preset", c.scenario_preset]
    sets = [args[i + 1] for i in range(2, len(args), 2) if args[i] == "--set"]
    assert len(sets) == len(c.scenario_overrides)
    assert preset(args[1]).with_overrides(sets) == c.scenario()


@pytest.mark.parametrize("text, value", [("true", True), ("Yes", True), ("on", True), ("1", True),
                                         ("false", False), ("no", False), ("OFF", False), ("0", False)])
def test_the_same_booleans_for_the_service_and_the_scenario(text: str, value: bool) -> None:
    c = build_config({}, {"mavlink.start_mission": text, "scenario.allow_stay": text})
    assert c.mavlink.start_mission is value and c.scenario().allow_stay is value
    assert Scenario().with_overrides([f"allow_stay={text}"]).allow_stay is value


def test_typed_literals_refuse_what_they_do_not_name() -> None:
    # A section built in code is held to its choices and bounds as one read from a file.
    from planner_service.service.config import MavlinkConfig, ZenohConfig
    with pytest.raises(ConfigError) as err:
        MavlinkConfig(flavour="apm")  # type: ignore[arg-type]
    assert err.value.key == "mavlink.flavour" and "'apm' is not one of ('ardupilot', 'px4')" in err.value.message
    with pytest.raises(ConfigError) as err:
        ZenohConfig(status_hz=0.5)
    assert err.value.key == "zenoh.status_hz" and err.value.message == "must be at least 1 Hz, got 0.5"
    assert build_config({}, {"journal.synchronous": "normal"}).journal.synchronous == "NORMAL"
