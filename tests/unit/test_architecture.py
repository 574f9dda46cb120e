"""The rules between the rooms (../shared/design/architecture.md, issue 19), read from
the source: who may import whom, and nobody reaches into another module's private
names. A violation names the file and line."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PRODUCT = ("station", "api", "drivers", "sim")
#: the composition root, the CLI and the benches may build concrete stations
MAY_BUILD = ("station/runtime.py", "station/cli/", "station/bench/")
#: concrete drivers and the test kit: never imported by the domain
CONCRETE = ("drivers.modbus_axis", "drivers.encoder", "drivers.camera", "drivers.testing")
#: private names of the standard library that are its public API
#: the standard library's documented functions whose names start with "_": ``os._exit``,
#: and ``sys._current_frames`` (the one way to read another thread's stack)
STDLIB_PRIVATE = {("os", "_exit"), ("sys", "_current_frames")}


def sources(*packages: str):
    for pkg in packages:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            yield rel, ast.parse(path.read_text(encoding="utf-8"), filename=rel)


def imported_modules(tree: ast.AST):
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module


def _under(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def test_the_domain_imports_no_twin_no_composition_root_no_concrete_driver_no_api():
    bad = []
    for rel, tree in sources("station"):
        if rel.startswith(MAY_BUILD):
            continue
        for line, mod in imported_modules(tree):
            if any(_under(mod, p) for p in ("sim", "station.runtime", "station.cli", "station.bench", "api", "testkit",
                                             *CONCRETE)):
                bad.append(f"{rel}:{line}: imports {mod}")
    assert not bad, "\n".join(bad)


def test_drivers_import_nothing_of_ours_but_their_own_interfaces_and_sim_no_api():
    bad = []
    for rel, tree in sources("drivers"):
        for line, mod in imported_modules(tree):
            if any(_under(mod, p) for p in ("station", "sim", "api", "testkit")):
                bad.append(f"{rel}:{line}: imports {mod}")
    for rel, tree in sources("sim"):
        for line, mod in imported_modules(tree):
            if any(_under(mod, p) for p in ("api", "testkit", "station.runtime", "station.cli")):
                bad.append(f"{rel}:{line}: imports {mod}")
    assert not bad, "\n".join(bad)


def _own_names(tree: ast.AST) -> set[str]:
    """Every name a module defines itself (functions, classes, attributes it assigns)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
    return names


def test_no_module_reaches_into_another_modules_private_names():
    bad = []
    for rel, tree in sources(*PRODUCT):
        own = _own_names(tree)
        for node in ast.walk(tree):
            if not (isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__")):
                continue
            base = node.value
            if isinstance(base, ast.Name) and (base.id in ("self", "cls") or (base.id, node.attr) in STDLIB_PRIVATE):
                continue
            if node.attr in own:  # the module's own private name, on another instance of its own class
                continue
            bad.append(f"{rel}:{node.lineno}: {ast.unparse(node)}")
    assert not bad, "\n".join(bad)


def test_no_module_imports_another_modules_private_names():
    ours = ("station", "api", "drivers", "sim", "testkit")
    bad = []
    for rel, tree in sources(*PRODUCT):
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module \
                    and any(_under(node.module, p) for p in ours):
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        bad.append(f"{rel}:{node.lineno}: from {node.module} import {alias.name}")
    assert not bad, "\n".join(bad)


def test_the_checks_above_can_fail():
    """The walkers find what they look for (a check that sees nothing proves nothing)."""
    tree = ast.parse("import sim.world\nfrom station.runtime import open_session\nx = engine._fault\n")
    assert [m for _, m in imported_modules(tree)] == ["sim.world", "station.runtime"]
    attrs = [n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)]
    assert attrs == ["_fault"] and "_fault" not in _own_names(tree)
