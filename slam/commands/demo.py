"""``gslam demo``: simulate the Telemax lab mission and compare ungated,
gated and oracle mapping on it, with the configs shipped with the package.

The demo folder ``OUT`` (a container, :func:`slam.results.outdir.open_container`)
holds the simulated run ``OUT/<scenario>/`` and the comparison
``OUT/compare/``. Running the demo again reuses the simulated run when it
was made from the same scenario and seed, and replaces the comparison.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from slam.commands.compare import CompareResult, run_compare
from slam.config import config_files
from slam.results.outdir import classify, open_container, result_command
from slam.resources import shipped_config
from slam.sim import simulate
from slam.sim.scenario import dump_scenario, load_scenario

DEFAULT_SCENARIO = "scenarios/telemax_lab.yaml"
DEFAULT_CONFIG = "telemax.yaml"
DEFAULT_VARIANTS = ("ungated", "gated", "oracle")


@dataclass
class DemoResult:
    """The demo folder, the simulated run, whether it was simulated now
    (False: reused), its duration (s) and the comparison."""

    out_dir: Path
    run_dir: Path
    simulated: bool
    duration_s: float
    compare: CompareResult


def run_demo(
    out_dir: str | Path,
    scenario: str | Path | None = None,
    config: str | Path | None = None,
    variants: str | Path | None = None,
    only: list[str] | None = None,
    seed: int | None = None,
    progress: bool = False,
    force: bool = False,
    command: str | None = None,
) -> DemoResult:
    """Simulate (or reuse) and compare; None for a path means the shipped
    file; ``command``: the command line ``report.html`` names (default:
    this process's)."""
    scenario = Path(scenario) if scenario is not None else shipped_config(DEFAULT_SCENARIO)
    config = Path(config) if config is not None else shipped_config(DEFAULT_CONFIG)
    variants = Path(variants) if variants is not None else shipped_config("variants.yaml")
    wanted = load_scenario(scenario)
    if seed is not None:
        wanted = wanted.model_copy(update={"seed": seed})
    inputs = [scenario, *config_files(config), variants]
    run_dir = Path(out_dir) / scenario.stem
    reuse = result_command(run_dir) == "simulate" and _text(run_dir / "scenario.yaml") == dump_scenario(wanted)
    # Both parts' places are checked before either is written.
    classify(Path(out_dir), "demo", inputs, force)
    if not reuse:
        classify(run_dir, "simulate", [scenario], force)
    classify(Path(out_dir) / "compare", "compare", [run_dir, *inputs[1:]], force)
    out = open_container(out_dir, "demo", inputs, force, (f"{scenario.stem}/", "compare/"))
    duration = 0.0
    if not reuse:
        duration = simulate(scenario, run_dir, seed=seed, progress=progress, force=force).duration_s
    compare = run_compare(run_dir, config, out / "compare", variants, list(only or DEFAULT_VARIANTS),
                          progress=progress, force=force, command=command)
    return DemoResult(out, run_dir, not reuse, duration, compare)


def _text(path: Path) -> str | None:
    try:
        return path.read_text()
    except OSError:
        return None
