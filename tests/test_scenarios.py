"""The scenarios beyond the lab, each cut to its first legs: the fault the
scenario is about happens there, validation blames the right modality, and
gating maps it better than no validation and than a Cauchy kernel (the
benchmark over whole runs and ten seeds is python -m scripts.bench gating)."""

from __future__ import annotations

import pytest

from conftest import CONFIGS, TELEMAX_CONFIG
from slam.config import load_config
from slam.pipeline.folder import MappingPipeline
from slam.sim import load_scenario, simulate_scenario

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

# scenario: (waypoints kept, the modality whose fault the cut holds)
CUTS = {
    "corridor": (6, "SM_DIST"),       # 90 s: down the featureless corridor
    "hall": (4, "SM_DIST"),           # 85 s: past the steel racks, along the repeated ones
    "compass_steel": (4, "IMU_YAW"),  # 115 s: one lap along the steel cabinets
}
# Gating against a kernel over the same sequential factors: without the
# scan-to-submap constraints and loops, which change both sides (whole runs
# with them: the gating bench; on hall's first legs a Cauchy kernel with
# them maps better than gating).
CHAIN = ["submaps.enabled=false", "loops.enabled=false"]
VARIANTS = {
    "ungated": ["validation.mode=off", *CHAIN],
    "gated": ["validation.mode=on", *CHAIN],
    "cauchy": ["validation.mode=off", "backend.robust_kernel=cauchy", "backend.robust_param=1.0", *CHAIN],
}


@pytest.fixture(scope="module", params=sorted(CUTS))
def cut(request, tmp_path_factory):
    name = request.param
    n, modality = CUTS[name]
    full = load_scenario(CONFIGS / "scenarios" / f"{name}.yaml")
    robot = full.robot.model_copy(update={"waypoints": full.robot.waypoints[:n]})
    run = simulate_scenario(full.model_copy(update={"robot": robot, "name": f"{name}_cut"}),
                            tmp_path_factory.mktemp("sim") / name)
    recording = frontend = None
    metrics = {}
    for variant, overrides in VARIANTS.items():
        cfg = load_config(TELEMAX_CONFIG, [*overrides, "output.plots=false"])
        pipe = MappingPipeline(run.run_dir, cfg, tmp_path_factory.mktemp("map") / variant,
                               recording=recording, frontend=frontend)
        metrics[variant] = pipe.run().metrics
        recording, frontend = pipe.recording, pipe.frontend
    return name, modality, run, metrics


def test_the_cut_holds_the_fault(cut):
    name, modality, run, _ = cut
    assert run.faults[modality], f"{name}: no {modality} fault in the first legs"


def test_validation_blames_the_faulty_modality(cut):
    name, modality, _, metrics = cut
    gated = metrics["gated"]
    assert gated["detection_delay_s"][modality] is not None, f"{name}: {modality} never blamed"
    assert gated["faults_missed"] == 0


def test_gating_beats_no_validation_and_a_cauchy_kernel(cut):
    name, _, _, metrics = cut
    ate = {v: m["ate_rmse_m"] for v, m in metrics.items()}
    assert ate["gated"] < ate["ungated"], ate
    assert ate["gated"] <= 1.1 * ate["cauchy"], ate
