"""One name, one meaning (docs/DESIGN.md, "Names"): a public class name is defined once
across the project's packages, so `Landed` in a log, a test or a review is one thing, not
four."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "planner_service", "sim_bridge")


def classes() -> dict[str, list[str]]:
    """Every public class name (not starting with ``_``) and the modules defining it."""
    where: dict[str, list[str]] = defaultdict(list)
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                    where[node.name].append(str(path.relative_to(REPO)))
    return where


def test_every_public_class_name_is_defined_once() -> None:
    where = classes()
    assert len(where) > 100, "the packages were not found"
    twice = {name: paths for name, paths in where.items() if len(paths) > 1}
    assert twice == {}, twice
