"""The layers of docs/DESIGN.md ("Layers: what may import what"), read from the code: every
import of every module (inside functions too) against the layers its own may use."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "planner_service", "sim_bridge")
MODEL, SETTINGS, POLICY = "planner_service.model", "planner_service.settings", "planner_service.policy"
REGISTRY, MCTS, BASELINES = "planner_service.registry", "planner_service.mcts", "planner_service.baselines"
SORTIE, SERVICE, HARNESS = "planner_service.sortie", "planner_service.service", "planner_service.harness"
FLEET_LIVE, ERRORS = "planner_service.service.fleet", "planner_service.service.errors"
"""The live fleet's package, a layer of its own inside the service's (the service uses it; it
uses none of the service but its errors), and the service's errors (pure exceptions)."""
LIVE, WEB = "planner_service.live", "planner_service.web"
EVERYTHING = None
ALLOWED: dict[str, set[str] | None] = {
    "protocol": set(),
    SETTINGS: set(),
    MODEL: {SETTINGS},
    POLICY: {SETTINGS, MODEL},  # the contract: the planners import it, it imports none of them
    MCTS: {SETTINGS, MODEL, POLICY},
    BASELINES: {SETTINGS, MODEL, POLICY},
    REGISTRY: {SETTINGS, MODEL, POLICY, MCTS, BASELINES},
    SORTIE: {SETTINGS, MODEL, POLICY, REGISTRY},
    "planner_service.fleet": {SETTINGS, MODEL, POLICY, REGISTRY, SORTIE},
    "planner_service.experiments": {SETTINGS, MODEL, POLICY, MCTS, SORTIE, "planner_service.fleet"},
    SERVICE: {"protocol", SETTINGS, MODEL, POLICY, MCTS, FLEET_LIVE, ERRORS},
    FLEET_LIVE: {"protocol", MODEL, ERRORS},  # the members' exchange; the claim rule is the model's
    ERRORS: set(),
    HARNESS: {"protocol", SETTINGS, MODEL, POLICY, SORTIE, SERVICE, FLEET_LIVE, ERRORS, "planner_service.fleet",
              LIVE, WEB},
    LIVE: {"protocol", FLEET_LIVE},  # the operator's read model, fed from the members' exchange
    WEB: {"protocol", LIVE},  # the live map's server: the picture and its feed
    "planner_service.bench": EVERYTHING,
    "planner_service.commands": EVERYTHING,
    "planner_service.cli": EVERYTHING,
    "planner_service.operator_view": {"protocol", LIVE},  # the picture, as text
    "planner_service.__main__": EVERYTHING,
    "planner_service": EVERYTHING,
    "sim_bridge": {"protocol", SETTINGS, MODEL},
}


def layer(module: str) -> str | None:
    """The layer of a dotted module name of this project, or None (another package)."""
    parts = module.split(".")
    if parts[0] in ("protocol", "sim_bridge"):
        return parts[0]
    if parts[0] != "planner_service":
        return None
    if len(parts) == 1:
        return "planner_service"
    for inner in (FLEET_LIVE, ERRORS):
        if module == inner or module.startswith(inner + "."):
            return inner
    return f"planner_service.{parts[1]}"


def imports(source: str, module: str, is_package: bool = False) -> set[str]:
    """The dotted modules the code of ``module`` imports, relative imports resolved."""
    package = module if is_package else module.rsplit(".", 1)[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(source, module)):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.add(target)
            out.update(f"{target}.{alias.name}" for alias in node.names)  # from pkg import module
    return out


def test_every_import_stays_within_its_layers() -> None:
    bad = []
    count = 0
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            module = ".".join(path.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__")
            own = layer(module)
            assert own in ALLOWED, f"{module}: no layer in ALLOWED for {own}"
            allowed = ALLOWED[own]
            for target in imports(path.read_text(), module, path.name == "__init__.py"):
                other = layer(target)
                count += 1
                if other is None or other == own or allowed is EVERYTHING or other in allowed:
                    continue
                bad.append(f"{module} imports {target} ({own} may import {sorted(allowed)})")
    assert count > 300, count  # the walk did see the code
    assert not bad, "\n".join(sorted(set(bad)))


def test_the_reading_sees_a_forbidden_import() -> None:
    # the model importing the service, even inside a function, is seen as such
    source = "from . import scenario\ndef f():\n    from ..service import config\n    import protocol.mission\n"
    found = {layer(t) for t in imports(source, "planner_service.model.probe")} - {None}
    assert found == {"planner_service.service", "protocol", MODEL}
    assert {"planner_service.service", "protocol"}.isdisjoint(ALLOWED[MODEL] or set())


def runtime_imports(source: str, module: str, is_package: bool, modules: set[str]) -> set[str]:
    """The project's modules ``module`` imports when it runs: ``from pkg import name`` is
    pkg.name where that is a module, else pkg; imports for type checkers alone
    (``if TYPE_CHECKING:``) do not run."""
    tree = ast.parse(source, module)
    typing_only = {id(n) for block in ast.walk(tree) if isinstance(block, ast.If)
                   and ast.unparse(block.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")
                   for stmt in block.body for n in ast.walk(stmt)}
    package = module if is_package else module.rsplit(".", 1)[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            target = node.module or ""
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            out.update(f"{target}.{a.name}" if f"{target}.{a.name}" in modules else target for a in node.names)
    ancestors = {".".join(module.split(".")[:i]) for i in range(1, module.count(".") + 1)}
    return {t for t in out if t in modules and t != module and t not in ancestors}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected parts of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = stack[stack.index(v):]
            del stack[stack.index(v):]
            if len(part) > 1:
                found.append(sorted(part))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def test_no_module_imports_itself_round_a_circle() -> None:
    # The harness and the service, the planners and their registry, the plots and the
    # experiments' registry once imported each other (issue 24).
    paths = {".".join(p.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__"): p
             for package in PACKAGES for p in sorted((REPO / package).rglob("*.py"))}
    graph = {m: runtime_imports(p.read_text(), m, p.name == "__init__.py", set(paths)) for m, p in paths.items()}
    assert sum(len(v) for v in graph.values()) > 300
    assert not cycles(graph), cycles(graph)
    # the reading sees one
    probe = {"a.x": runtime_imports("from . import y", "a.x", False, {"a.x", "a.y"}),
             "a.y": runtime_imports("def f():\n    from .x import g", "a.y", False, {"a.x", "a.y"})}
    assert cycles(probe) == [["a.x", "a.y"]]
    assert not runtime_imports("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .y import T",
                               "a.x", False, {"a.x", "a.y"})
