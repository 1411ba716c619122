"""The package as pip installs it: every code package listed, the configs
shipped as package data, and a non-editable install that runs from a
folder outside the repository."""

from __future__ import annotations

import tomllib

from slam.resources import configs_dir, resolve_config_path, shipped_config
from tests.conftest import CONFIGS, REPO


def pyproject() -> dict:
    return tomllib.loads((REPO / "pyproject.toml").read_text())


def test_every_package_of_the_tree_is_listed():
    listed = set(pyproject()["tool"]["setuptools"]["packages"])
    found = {
        ".".join(init.parent.relative_to(REPO).parts)
        for top in ("slam", "validation")
        for init in (REPO / top).rglob("__init__.py")
    }
    assert found <= listed, f"add to pyproject.toml [tool.setuptools] packages: {sorted(found - listed)}"


def test_configs_are_package_data():
    tool = pyproject()["tool"]["setuptools"]
    assert tool["package-dir"]["slam.configs"] == "configs"
    patterns = tool["package-data"]["slam.configs"]
    shipped = {p.relative_to(CONFIGS) for pattern in patterns for p in CONFIGS.glob(pattern)}
    every = {p.relative_to(CONFIGS) for p in CONFIGS.rglob("*") if p.is_file()}
    assert shipped == every  # nothing in configs/ is left out of the wheel


def test_shipped_configs_are_found(tmp_path, monkeypatch):
    assert configs_dir() == CONFIGS  # a source checkout reads configs/ itself
    assert shipped_config("variants.yaml").is_file()
    monkeypatch.chdir(tmp_path)
    assert resolve_config_path("configs/telemax.yaml") == CONFIGS / "telemax.yaml"
    assert resolve_config_path("configs/nope.yaml").as_posix() == "configs/nope.yaml"
    (tmp_path / "configs").mkdir()
    (tmp_path / "configs" / "telemax.yaml").write_text("{}\n")
    # One's own configs/ in the working folder comes first.
    assert resolve_config_path("configs/telemax.yaml").resolve() == tmp_path / "configs" / "telemax.yaml"
