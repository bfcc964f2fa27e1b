"""A fleet's configuration (issue 34, the insecure default), in milliseconds: ``[fleet]
enabled`` without its enrolment refuses to start naming the key; zenoh endpoints neither
loopback nor TLS with access control need ``fleet.insecure``; ``fleet-key`` enrols."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from planner_service.service.app import fleet_presence
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
