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
