"""The shipped zenoh TLS and access-control files, made usable in a test: certificates from
docs/zenoh/make-certs.sh (the openssl CLI, as an operator makes them) and the shipped JSON5
configurations with their certificate folder replaced."""

from __future__ import annotations

import subprocess
from pathlib import Path

from planner_service.harness.processes import REPO

DOCS = REPO / "docs" / "zenoh"
SHIPPED_DIR = "/etc/uavmec/tls"
MARKS = {"rules": "// more users' rules here", "subjects": "// more users' subjects here",
         "policies": "// more users' policies here"}
VEHICLE_MARKS = {section: mark.replace("users'", "vehicles'") for section, mark in MARKS.items()}


def make_certs(folder: Path, *args: str) -> str:
    return subprocess.run(["sh", str(DOCS / "make-certs.sh"), str(folder), *args], check=True, capture_output=True,
                          text=True).stdout


def shipped(name: str, certs: Path, out: Path, **swap: str) -> Path:
    """The shipped config with its certificate folder (and any other text) replaced."""
    text = (DOCS / name).read_text()
    assert SHIPPED_DIR in text
    text = text.replace(SHIPPED_DIR, str(certs))
    for old, new in swap.items():
        assert old in text
        text = text.replace(old, new)
    out.write_text(text)
    return out


def add_entries(config: Path, printed: str, marks: dict[str, str] = MARKS) -> None:
    """Add the access-control entries make-certs.sh printed (``--user``: ``MARKS``,
    ``--vehicle``: ``VEHICLE_MARKS``) where the shipped file says more go."""
    text = config.read_text()
    for line in printed.splitlines():
        section, _, entries = line.partition(": ")
        if section in marks:
            assert marks[section] in text
            text = text.replace(marks[section], f"{entries}\n      {marks[section]}")
    config.write_text(text)
