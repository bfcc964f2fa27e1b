"""The sortie logic is pure: it imports no database, no event loop and no wire library, so
its tests run in milliseconds and a row type is all it knows of the journal."""

from __future__ import annotations

import ast
from pathlib import Path

SORTIE = Path(__file__).resolve().parents[2] / "planner_service" / "service" / "sortie"
FORBIDDEN = ("sqlite3", "asyncio", "zenoh", "mavsdk", "planner_service.service.journal", "..journal", ".journal")


def imported(path: Path) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            names.append("." * node.level + (node.module or ""))
    return names


def test_the_sortie_logic_imports_no_io() -> None:
    found = {f"{path.name}: {name}" for path in SORTIE.glob("*.py") for name in imported(path)
             if name in FORBIDDEN or name.split(".")[0] in FORBIDDEN}
    assert not found, sorted(found)
