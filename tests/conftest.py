"""Shared fixtures: one short simulated run per test session, and its maps.

The short run is the first leg of the compass scenario
(``configs/scenarios/telemax_compass.yaml``): 1.4 m south along the lab's
west wall, a spot turn, then 6.5 m east past the steel cabinet by the south
wall, about 24 s in all. Passing the cabinet bends the magnetic field, so the
run has one true compass (IMU_YAW) fault of about 9 s and nothing else; the
laser sees the lab the whole time and there is no GPS fix indoors.
Simulating it takes well under a second, mapping it about half a second.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from typing import TYPE_CHECKING

try:  # first, so numpy's BLAS kernels are pinned as gslam pins them (slam/host.py)
    import slam  # noqa: F401
except ImportError:  # validation's own tests (tests/validation/) run without slam
    pass

import pytest  # noqa: E402
import yaml  # noqa: E402

# slam's modules are imported by the fixtures that need them, not here.
if TYPE_CHECKING:
    from slam.pipeline.folder import MapResult
    from slam.sim import Scenario, SimulationResult

REPO = Path(__file__).resolve().parents[1]
CONFIGS = REPO / "configs"
TELEMAX_CONFIG = CONFIGS / "telemax.yaml"
SHORT_WAYPOINTS = [(1.0, 2.6), (1.0, 1.2), (7.5, 1.2)]


def short_scenario() -> Scenario:
    """The compass scenario cut to its first leg (see the module docstring)."""
    from slam.sim import load_scenario

    full = load_scenario(CONFIGS / "scenarios" / "telemax_compass.yaml")
    robot = full.robot.model_copy(update={"waypoints": SHORT_WAYPOINTS})
    return full.model_copy(update={"robot": robot, "name": "short_compass"})


@pytest.fixture(scope="session")
def short_scenario_yaml(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The short scenario written as a scenario YAML (for the CLI)."""
    path = tmp_path_factory.mktemp("scenario") / "short_compass.yaml"
    path.write_text(yaml.safe_dump(short_scenario().model_dump(mode="json"), sort_keys=False))
    return path


@pytest.fixture(scope="session")
def short_run(tmp_path_factory: pytest.TempPathFactory) -> SimulationResult:
    """The short run, simulated once per session."""
    from slam.sim import simulate_scenario

    return simulate_scenario(short_scenario(), tmp_path_factory.mktemp("sim") / "short_compass")


@pytest.fixture(scope="session")
def mapped(short_run: SimulationResult, tmp_path_factory: pytest.TempPathFactory) -> Callable[..., MapResult]:
    """``mapped(mode, *overrides)``: the short run mapped with
    ``configs/telemax.yaml`` and ``validation.mode=mode``, once per session."""
    from slam.config import load_config
    from slam.pipeline.folder import run_map

    root = tmp_path_factory.mktemp("maps")
    cache: dict[tuple[str, ...], MapResult] = {}

    def get(mode: str = "off", *overrides: str) -> MapResult:
        key = (mode, *overrides)
        if key not in cache:
            config = load_config(TELEMAX_CONFIG, [f"validation.mode={mode}", *overrides])
            cache[key] = run_map(short_run.run_dir, config, root / f"map{len(cache)}")
        return cache[key]

    return get


def real_data(relative: str) -> Path:
    """A file under the data root (``$GSLAM_DATA``, else ``../shared/data``);
    the calling test is skipped, naming the path, when it is absent."""
    from slam.readers.datasets import data_root

    path = data_root() / relative
    if not path.is_file():
        pytest.skip(f"real data not found: {path} (set GSLAM_DATA to the data folder)")
    return path
