"""The configs shipped with the package, found from any working folder.

The repository's ``configs/`` folder is installed as the package data
``slam/configs`` (pyproject.toml maps it), so an installed ``gslam`` has the
Telemax config, the variants, the scenarios, the validation models, the
dataset configs and the ablation specs without the repository. In a source
checkout (or an editable install) they are read from ``configs/`` itself.

A path given on the command line is taken as written. Only when it does not
exist, is relative and starts with ``configs/``, it names the shipped file
of that name: ``gslam simulate configs/scenarios/telemax_lab.yaml`` works
from any folder, and a ``configs/`` folder of one's own, in the working
folder, comes first.
"""

from __future__ import annotations

from pathlib import Path

from slam.errors import GslamError

_PREFIX = "configs"


def configs_dir() -> Path:
    """The folder of the shipped configs."""
    here = Path(__file__).resolve().parent
    for candidate in (here / _PREFIX, here.parent / _PREFIX):  # installed, source checkout
        if (candidate / "telemax.yaml").is_file():
            return candidate
    raise GslamError(f"the configs shipped with gslam are missing (looked in {here / _PREFIX}); reinstall the package")


def shipped_config(relative: str) -> Path:
    """A shipped config by its path inside ``configs/``, e.g. ``variants.yaml``."""
    return configs_dir() / relative


def resolve_config_path(path: str | Path) -> Path:
    """``path`` itself if it exists; else, for a relative ``configs/...``
    path, the shipped file of that name if there is one; else ``path``
    (whose reader then reports it missing)."""
    path = Path(path)
    if path.exists() or path.is_absolute() or not path.parts or path.parts[0] != _PREFIX:
        return path
    shipped = configs_dir().joinpath(*path.parts[1:])
    return shipped if shipped.exists() else path
