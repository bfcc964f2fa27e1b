"""The zenoh configuration: a JSON5 file as the base with our keys on top, and the new
configuration keys refused with their names."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from planner_service.service.config import load_config, parse_overrides
from planner_service.service.errors import ConfigError
from protocol import ProtocolError
from protocol.zenoh_config import NO_FILE_RX_MAX_MESSAGE_BYTES, RECONNECT, session_config


def test_the_file_is_the_base_and_our_keys_win(tmp_path: Path) -> None:
    path = tmp_path / "base.json5"
    path.write_text("""{
      // comments are fine: JSON5
      mode: "client",
      connect: { retry: { period_init_ms: 5000, period_max_ms: 5000, period_increase_factor: 1 } },
      listen: { endpoints: ["tcp/127.0.0.1:1"] },
      transport: { link: { tls: { enable_mtls: true, root_ca_certificate: "/x/ca.pem" } } },
    }""")
    conf = session_config("router", ["tls/127.0.0.1:7000"], [], False, path)
    assert json.loads(conf.get_json("mode")) == "router"
    assert json.loads(conf.get_json("listen/endpoints")) == ["tls/127.0.0.1:7000"]
    assert json.loads(conf.get_json("transport/link/tls/enable_mtls")) is True
    assert json.loads(conf.get_json("transport/link/tls/root_ca_certificate")) == "/x/ca.pem"
    # what the file sets is left alone: its reconnection and (zenoh's default) message size
    assert json.loads(conf.get_json("connect/retry"))["period_max_ms"] == 5000
    assert json.loads(conf.get_json("transport/link/rx/max_message_size")) != NO_FILE_RX_MAX_MESSAGE_BYTES


def test_without_a_file_messages_are_capped() -> None:
    conf = session_config("peer", ["tcp/127.0.0.1:7000"])
    assert json.loads(conf.get_json("transport/link/rx/max_message_size")) == NO_FILE_RX_MAX_MESSAGE_BYTES
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("connect/retry")) == RECONNECT


@pytest.mark.parametrize("text, words", [
    ("{ transport: { link: { tls: { no_such_key: 1 } } } }", "no_such_key"),
    ("{ not json", "expected"),
])
def test_a_bad_file_is_refused_naming_it(tmp_path: Path, text: str, words: str) -> None:
    path = tmp_path / "bad.json5"
    path.write_text(text)
    with pytest.raises(ProtocolError, match=words) as info:
        session_config("peer", [], [], False, path)
    assert info.value.field == "config_file" and str(path) in info.value.message


@pytest.mark.parametrize("override, key", [
    ("zenoh.max_queries_in_flight=0", "zenoh.max_queries_in_flight"),
    ("zenoh.config_file=/no/such/file.json5", "zenoh.config_file"),
    ("intake.max_pending_requests=0", "intake.max_pending_requests"),
    ("intake.max_requests_per_s=0", "intake.max_requests_per_s"),
    ("planner.min_requests=5", "planner.min_requests"),
])
def test_new_keys_are_checked(override: str, key: str) -> None:
    extra = ["intake.max_pending_requests=4"] if override.startswith("planner") else []
    with pytest.raises(ConfigError) as info:
        load_config(None, parse_overrides([override, *extra]))
    assert info.value.key == key
