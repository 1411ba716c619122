"""The layers look down: the validation package does not build on the
pipeline (slam), so it can be used on its own."""

from __future__ import annotations

import ast
from pathlib import Path

VALIDATION = Path(__file__).resolve().parents[1] / "validation"


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names


def test_validation_does_not_import_slam():
    offenders = {
        str(p.relative_to(VALIDATION)): sorted(m for m in imported_modules(p) if m == "slam" or m.startswith("slam."))
        for p in sorted(VALIDATION.rglob("*.py"))
    }
    assert {name: mods for name, mods in offenders.items() if mods} == {}
    assert len(offenders) > 10  # the package was found
