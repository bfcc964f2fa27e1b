"""A fleet's configuration (issue 34, the insecure default), in milliseconds: ``[fleet]
enabled`` without its enrolment refuses to start naming the key; zenoh endpoints neither
loopback nor TLS with access control need ``fleet.insecure``; ``fleet-key`` enrols."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import msgspec
import pytest

from planner_service.service.app import fleet_presence
from planner_service.service.fleet.presence import layer_clashes
from planner_service.service.config import build_config
from planner_service.service.errors import ConfigError
from protocol.fleet_signing import read_roster
from tests.support.fleet import enrol, fleet_settings


def test_a_fleet_without_enrolment_refuses_to_start(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as err:
        build_config({}, {"fleet.enabled": "true"}).check()
    assert err.value.key == "fleet.key_file" and "fleet-key" in str(err.value)
    roster = enrol(tmp_path, ["uav2"])
    with pytest.raises(ConfigError) as err:  # a key that is not there
        build_config({}, {"fleet.enabled": "true", **fleet_settings(roster)}).check()
    assert err.value.key == "fleet.key_file" and "uav1.key" in str(err.value)
    with pytest.raises(ConfigError, match="uav1 is not enrolled"):  # its key, not in the roster
        enrol(tmp_path / "other", ["uav1"])
        config = build_config({}, {"fleet.enabled": "true", "fleet.roster_file": str(roster),
                                   "fleet.key_file": str(tmp_path / "other" / "uav1.key")})
        config.check()
        fleet_presence(config)
    assert build_config({}, {}).fleet.enabled is False  # a lone UAV needs nothing


def test_a_fleet_open_to_any_peer_starts_only_when_told_so(tmp_path: Path) -> None:
    settings = {"fleet.enabled": "true", **fleet_settings(enrol(tmp_path, ["uav1"]))}
    build_config({}, settings).check()  # loopback: this computer only
    field = {**settings, "zenoh.listen": "tcp/0.0.0.0:7447"}
    with pytest.raises(ConfigError) as err:
        build_config({}, field).check()
    assert err.value.key == "fleet.insecure" and "tcp/0.0.0.0:7447" in str(err.value)
    config = build_config({}, {**field, "fleet.insecure": "true"})
    config.check()
    assert config.fleet_transport_open()


def test_fleet_key_enrols_a_vehicle(tmp_path: Path) -> None:
    run = [sys.executable, "-m", "planner_service", "fleet-key", str(tmp_path / "uav1.key"), "--vehicle", "uav1",
           "--roster", str(tmp_path / "roster")]
    done = subprocess.run(run, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "enrolled in" in done.stdout, done.stderr
    assert list(read_roster(tmp_path / "roster")) == ["uav1"]
    again = subprocess.run(run, capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "already" in again.stderr


def test_the_default_layers_keep_a_margin_over_the_vertical_separation(tmp_path: Path) -> None:
    """Issue 35, finding 2: section 11's layers 10 m apart sat on the 10 m separation rule
    itself (stacked SITL copters 9.98-10.04 m apart: losses of separation the layers were to
    rule out). With the defaults a layer 10 m from a member's is refused; 15 m is the least."""
    settings = {"fleet.enabled": "true", **fleet_settings(enrol(tmp_path, ["uav1"])), "scenario.altitude_m": "90"}
    presence = fleet_presence(build_config({}, settings))
    assert presence is not None and presence.own.min_gap_m == 15.0
    assert presence.vertical_separation_m == 10.0
    at = {"uav2": msgspec.structs.replace(presence.own, vehicle="uav2", layer_m=80.0)}
    assert layer_clashes(presence.own, at) == [
        "uav2 flies at 80 m, within 15 m of this UAV's layer 90 m (fleet.vertical_separation_m + "
        "fleet.altitude_margin_m)"]
    assert layer_clashes(presence.own, {"uav2": msgspec.structs.replace(at["uav2"], layer_m=75.0)}) == []
    wide = fleet_presence(build_config({}, {**settings, "fleet.altitude_margin_m": "10"}))
    assert wide is not None and wide.own.min_gap_m == 20.0
