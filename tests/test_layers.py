"""The layers look down: the validation package does not build on the
pipeline (slam), so it can be used on its own; and no two files of the
project import each other, directly or round a longer loop."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
VALIDATION = REPO / "validation"
PACKAGES = ("slam", "validation", "scripts")


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


def project_modules() -> dict[str, Path]:
    """Every module of the project by dotted name (a package by its own)."""
    modules = {}
    for top in PACKAGES:
        for path in (REPO / top).rglob("*.py"):
            parts = path.relative_to(REPO).with_suffix("").parts
            modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return modules


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the project modules it imports, wherever the import stands
    (top level, inside a function, under ``TYPE_CHECKING``): any of them
    can close a loop. ``from a.b import c`` is an import of ``a.b.c`` when
    that is a module, else of ``a.b``."""
    graph = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(up + ([node.module] if node.module else []))
                for alias in node.names:
                    found.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
        graph[name] = {m for m in found if m in modules and m != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_loop():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles():
    modules = project_modules()
    assert {"slam.pipeline.core", "slam.pipeline.folder", "validation.validator", "scripts.bench.common"} <= set(modules)
    assert cycles(import_graph(modules)) == []


# --- folders: the stages of slam/ as the data flows --------------------------------

LAYERS = (
    ("validation",),  # the method, and its shared basics (validation.base): imports nothing of slam
    ("slam", "slam.host", "slam.errors", "slam.recording", "slam.resources", "slam.config", "slam.processes", "slam.results"),
    ("slam.readers", "slam.matching"),
    ("slam.frontend", "slam.graph"),
    ("slam.gating", "slam.submaps", "slam.loops", "slam.sim"),
    ("slam.outputs",),
    ("slam.pipeline",),
    ("slam.commands",),
    ("slam.cli",),
    ("scripts",),
)
"""Lowest first: a folder (or top-level module) imports its own layer and
the ones below it, never one above."""


def folder_of(module: str) -> str:
    """The stage a module belongs to: ``slam.graph.backend`` -> ``slam.graph``;
    every module of validation/ or scripts/ is one stage."""
    parts = module.split(".")
    return parts[0] if parts[0] in ("validation", "scripts") else ".".join(parts[:2])


def folder_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    folders: dict[str, set[str]] = {}
    for module, imported in graph.items():
        mine = folder_of(module)
        folders.setdefault(mine, set()).update(folder_of(m) for m in imported if folder_of(m) != mine)
    return folders


def layer_of(folder: str) -> int:
    found = [k for k, layer in enumerate(LAYERS) if folder in layer]
    assert found, f"{folder}: add it to a layer in tests/test_layers.py (LAYERS)"
    return found[0]


def test_no_cycles_between_folders():
    graph = import_graph(project_modules())
    assert cycles(folder_graph(graph)) == []
    # and the check sees one where a low stage imports a high one
    graph["slam.readers.carmen"] = graph["slam.readers.carmen"] | {"slam.pipeline.core"}
    assert cycles(folder_graph(graph)) != []


def test_each_folder_imports_only_its_layer_and_below():
    graph = import_graph(project_modules())
    upward = sorted(
        (module, imported)
        for module, deps in graph.items()
        for imported in deps
        if layer_of(folder_of(imported)) > layer_of(folder_of(module))
    )
    assert upward == []


def test_readers_matching_and_graph_never_import_commands_outputs_or_pipeline():
    graph = folder_graph(import_graph(project_modules()))
    for low in ("slam.readers", "slam.matching", "slam.graph"):
        assert not graph[low] & {"slam.commands", "slam.outputs", "slam.pipeline", "slam.cli"}, low


def test_slam_keeps_few_top_level_modules():
    """The package's public face and the data model; the rest lives in the stages' folders."""
    top = sorted(p.name for p in (REPO / "slam").glob("*.py"))
    assert len(top) <= 6, top
    for folder in (REPO / "slam").iterdir():
        if folder.is_dir() and (folder / "__init__.py").exists():
            doc = ast.get_docstring(ast.parse((folder / "__init__.py").read_text()))
            assert doc and "\n" not in doc.split("\n\n")[0], f"{folder.name}/__init__.py: says what it owns in one line"


def test_validations_own_tests_run_without_slam():
    """tests/validation/ tests the method alone: with ``slam`` made
    unimportable, every one of them still runs and passes."""
    import subprocess
    import sys

    code = ("import sys; sys.modules['slam'] = None; import pytest; "
            "sys.exit(pytest.main(['-q', '-p', 'no:cacheprovider', 'tests/validation']))")
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-2000:]
    assert " passed" in done.stdout and "error" not in done.stdout.lower().split("passed")[-1]


def test_the_validation_tests_spell_out_the_pipelines_factor_types():
    from importlib.util import module_from_spec, spec_from_file_location

    from slam.graph.measurements import FACTOR_DOFS

    spec = spec_from_file_location("gating_tests", REPO / "tests" / "validation" / "test_gating.py")
    module = module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.FACTOR_DOFS == FACTOR_DOFS


def test_the_gating_mode_is_typed_once():
    """``validation.mode`` is a :class:`GatingMode`; what depends on it asks
    the one policy :func:`slam.gating.policy.gating_policy` chooses. No code
    compares the mode with a string."""
    import re

    value = r"""["'](off|on|oracle|interval_oracle)["']"""
    compared = re.compile(rf"""\bmode\s*(==|!=|\bin\b|\bnot in\b)\s*[(\[{{]?\s*{value}|{value}\s*(==|!=)""")
    found = [
        f"{path.relative_to(REPO)}:{n}"
        for top in PACKAGES
        for path in sorted((REPO / top).rglob("*.py"))
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if compared.search(line.split("#")[0])
    ]
    assert found == []
    assert compared.search('if vcfg.mode == "on":') and compared.search('cfg.mode in ("on", "interval_oracle")')
