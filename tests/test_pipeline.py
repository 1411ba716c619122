"""The mapping pipeline end to end on the short simulated run (conftest.py):
result files, accuracy, gating, optimisers, determinism, atomic output."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from slam.config import load_config
from slam.errors import GslamError
from slam.outputs.pointcloud import import_open3d
from slam.outputs.tum import read_tum
from slam.graph.measurements import FACTOR_DOFS
from slam.pipeline.folder import run_map
from slam.sim import simulate_scenario
from slam.sim.world import World, distance_to_segments
from tests.conftest import TELEMAX_CONFIG, short_scenario

MAP_FILES = {
    "trajectory.tum", "groundtruth.tum", "metrics.json", "config.yaml",
    "trajectory.png", "map.ply", "map.png", "map.pgm", "map.yaml", "run.mcap", "loops.csv", ".gslam-result.json",
}
METRICS = ("ate_rmse_m", "rpe_trans_pct", "rpe_rot_deg_per_m", "final_error_m", "n_poses", "runtime_s")
VALIDATION_METRICS = (
    "alarm_fraction", "isolation_precision", "isolation_recall", "detection_delay_s",
    "faults_missed", "validation_steps", "validation_time_s", "keyframes_excluded",
)
TIMING_KEYS = {"runtime_s", "timings_s", "realtime_factor", "validation_time_s", "input"}
FACTORS = ("compass", "gps", "gyro", "odometry", "scan_matching")
GATE_COLUMNS = [f"gate.{f}.{d}" for f in FACTORS for d in FACTOR_DOFS[f]]


def listing(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


def without_timings(metrics: dict) -> dict:
    return {k: v for k, v in metrics.items() if k not in TIMING_KEYS}


# --- the short run itself ---------------------------------------------------------


def test_short_run_has_one_compass_fault(short_run):
    assert 20.0 < short_run.duration_s < 30.0
    faults = {c: iv for c, iv in short_run.faults.items() if iv}
    assert list(faults) == ["IMU_YAW"] and len(faults["IMU_YAW"]) == 1
    a, b = faults["IMU_YAW"][0]
    assert 5.0 < b - a < 15.0  # passing the steel cabinet


# --- result folder -------------------------------------------------------------


def test_map_writes_every_documented_file(mapped, short_run):
    res = mapped("off")
    assert listing(res.out_dir) == MAP_FILES  # no validation.csv with gating off, no leftovers
    metrics = json.loads((res.out_dir / "metrics.json").read_text())
    assert metrics == json.loads(json.dumps(res.metrics))
    for key in METRICS:
        assert isinstance(metrics[key], (int, float)), key
    assert metrics["n_poses"] == len(res.trajectory)
    assert set(metrics["timings_s"]) == {
        "read", "frontend", "validation", "loops", "submaps", "graph_build", "optimise", "write", "grid", "mcap",
        "prepare", "frontend_wait", "plots_wait", "self_check",
    }
    assert not any(k in metrics for k in ("alarm_fraction", "validation_steps"))
    assert metrics["self_check"]["verdict"] == "pass" and metrics["self_check"]["blame_share"] is None

    # TUM files carry absolute stamps t0 + t.
    est, t0 = read_tum(res.out_dir / "trajectory.tum", short_run.t0)
    assert t0 == short_run.t0
    assert len(est) == metrics["n_poses"]
    np.testing.assert_allclose(est.t, res.trajectory.t, atol=1e-6)
    np.testing.assert_allclose(est.xy(), res.trajectory.xy(), atol=1e-6)
    gt, _ = read_tum(res.out_dir / "groundtruth.tum", short_run.t0)
    assert gt.t[0] <= est.t[0] and gt.t[-1] >= est.t[-1] - 0.1

    # The config used, loadable on its own.
    assert load_config(res.out_dir / "config.yaml") == load_config(TELEMAX_CONFIG, ["validation.mode=off"])
    for png in ("trajectory.png", "map.png"):
        assert (res.out_dir / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def wall_distances(res) -> np.ndarray:
    """Distance (m) of every map.ply point to the nearest wall or obstacle."""
    cloud = import_open3d().io.read_point_cloud(str(res.out_dir / "map.ply"))
    pts = np.asarray(cloud.points)
    assert len(pts) > 500
    assert np.all(pts[:, 2] == 0.0)
    world = World.from_config(short_scenario().world)
    return distance_to_segments(pts[:, :2], world.segments)[0]


def test_map_ply_is_the_lab_seen_from_the_estimate(mapped):
    # Laser points in the estimated poses lie on the walls and obstacles of
    # the simulated world (range noise 1 cm, map voxels 5 cm). Measured with
    # gating on: median 8 mm, all within 10 cm. With gating off the bent
    # compass tilts the map by up to 2 deg: median 4.6 cm, 83 % within 10 cm.
    on = wall_distances(mapped("on"))
    assert np.mean(on < 0.1) > 0.97
    assert np.median(on) < 0.02
    off = wall_distances(mapped("off"))
    assert np.median(off) > np.median(on)


# --- accuracy and gating --------------------------------------------------------


@pytest.mark.slow
def test_short_run_accuracy(mapped):
    # Measured: ATE 0.016 m (off), 0.010 m (on), 0.013 m (oracle), 0.010 m
    # (interval oracle); RPE 0.4-0.6 %, final error 0.02-0.04 m. Bounds with
    # a 2.5x margin.
    for mode in ("off", "on", "oracle", "interval_oracle"):
        m = mapped(mode).metrics
        assert m["ate_rmse_m"] < 0.06, mode
        assert m["final_error_m"] < 0.1, mode
        assert m["rpe_trans_pct"] < 2.0, mode
        assert m["rpe_rot_deg_per_m"] < 0.5, mode
        assert m["fallback_steps"] == 0
    # Passing the steel cabinet the compass is 20-30 deg off: gating it out
    # (causally or with the truth) beats keeping it; the tight oracle by less.
    off = mapped("off").metrics["ate_rmse_m"]
    assert mapped("on").metrics["ate_rmse_m"] < 0.75 * off
    assert mapped("oracle").metrics["ate_rmse_m"] < off
    assert mapped("interval_oracle").metrics["ate_rmse_m"] < 0.75 * off


@pytest.mark.parametrize("mode", ["on", "interval_oracle"])
def test_gating_writes_validation_csv_and_metrics(mapped, mode):
    res = mapped(mode)
    assert listing(res.out_dir) == MAP_FILES | {"validation.csv"}
    m = json.loads((res.out_dir / "metrics.json").read_text())
    for key in VALIDATION_METRICS:
        assert key in m, key
    lines = (res.out_dir / "validation.csv").read_text().splitlines()
    assert len(lines) - 1 == m["validation_steps"] > 0
    header = lines[0].split(",")
    # configs/telemax.yaml closes loops: with gating on, LOOP's observation,
    # diagnosis and gate follow the sensors' gates (the interval oracle
    # gates no loops).
    loop_columns = ["loop_consistency", "loop_diagnosis", "gate.loop", "loops"] if mode == "on" else []
    gates = header[len(header) - len(loop_columns) - len(GATE_COLUMNS) : len(header) - len(loop_columns)]
    assert header[0] == "t" and gates == GATE_COLUMNS
    assert header[len(header) - len(loop_columns) :] == loop_columns
    if mode == "on":
        assert {"consistent", "diagnoses", "yaw_compass_gyro.counter"} <= set(header)
    else:
        assert len(header) == 1 + len(GATE_COLUMNS)
    # Only the compass is ever gated, only it is blamed.
    assert m["keyframes_excluded"]["compass"] > 0
    assert all(m["keyframes_excluded"][f] == 0 for f in FACTORS if f != "compass")
    assert m["blamed_steps"].keys() == {"IMU_YAW"}
    assert m["faults_missed"] == 0


def test_causal_gating_finds_the_compass_fault(mapped, short_run):
    m = mapped("on").metrics
    # Measured: delay 0.65 s, precision 0.69 (the hold-off and look-back
    # gate some healthy steps around the fault), recall 0.93.
    assert 0.0 <= m["detection_delay_s"]["IMU_YAW"] < 1.5
    assert m["isolation_precision"] > 0.5 and m["isolation_recall"] > 0.8
    assert m["no_diagnosis_steps"] == 0


def test_oracle_gates_exactly_the_true_fault(mapped, short_run):
    res = mapped("interval_oracle")
    m = res.metrics
    assert m["isolation_precision"] == 1.0 and m["isolation_recall"] == 1.0
    assert m["detection_delay_s"]["IMU_YAW"] <= 0.1  # within one 10 Hz step
    (a, b), = short_run.faults["IMU_YAW"]
    lines = (res.out_dir / "validation.csv").read_text().splitlines()[1:]
    checked = 0
    for line in lines:
        t, compass, *others = line.split(",")
        t = float(t)
        assert others == ["include"] * (len(GATE_COLUMNS) - 1)
        if min(abs(t - a), abs(t - b)) > 1e-3:  # the CSV rounds t to 0.1 ms
            assert compass == ("exclude" if a <= t <= b else "include"), t
            checked += 1
    assert checked > 0.9 * len(lines)


def test_tight_oracle_excludes_exactly_the_wrong_measurements(mapped):
    res = mapped("oracle")
    k = res.metrics["oracle_k_sigma"]
    header, *rows = [line.split(",") for line in (res.out_dir / "validation.csv").read_text().splitlines()]
    assert len(rows) == res.metrics["n_poses"]
    columns = {name: [row[i] for row in rows] for i, name in enumerate(header)}
    checked = 0
    for name in header:
        if not name.endswith(".z"):
            continue
        excluded = columns[name.removesuffix(".z") + ".excluded"]
        for z, x in zip(columns[name], excluded):
            if z:  # empty where the measurement is absent
                assert x == ("1" if abs(float(z)) > k else "0"), name
                checked += 1
    assert checked > 300  # 49 keyframes, 5 factor types
    # The steel cabinet bends the compass by 20-30 deg: the oracle drops those headings.
    assert res.metrics["excluded_dofs"]["compass"]["yaw"] > 0


# --- optimisers and determinism ---------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["off", "on"])
def test_batch_and_isam2_agree(mapped, mode):
    batch = mapped(mode)
    isam2 = mapped(mode, "backend.optimizer=isam2")
    assert load_config(isam2.out_dir / "config.yaml").backend.optimizer == "isam2"
    a, b = batch.trajectory, isam2.trajectory
    np.testing.assert_array_equal(a.t, b.t)
    # Measured: 1.7 mm and 0.06 deg at most (off), 0.2 mm (on).
    assert np.max(np.hypot(a.x - b.x, a.y - b.y)) < 0.01
    assert np.degrees(np.max(np.abs(np.angle(np.exp(1j * (a.yaw - b.yaw)))))) < 0.3
    assert abs(batch.metrics["ate_rmse_m"] - isam2.metrics["ate_rmse_m"]) < 0.005


@pytest.mark.slow
def test_same_seed_same_results(mapped, short_run, tmp_path):
    first = mapped("on")
    again_run = simulate_scenario(short_scenario(), tmp_path / "again")
    assert again_run.faults == short_run.faults
    config = load_config(TELEMAX_CONFIG, ["validation.mode=on"])
    again = run_map(again_run.run_dir, config, tmp_path / "map")
    assert without_timings(again.metrics) == without_timings(first.metrics)
    for name in ("trajectory.tum", "validation.csv", "config.yaml"):
        assert (again.out_dir / name).read_bytes() == (first.out_dir / name).read_bytes(), name

    # A different seed is a different run (the comparison above can fail).
    other = short_scenario().model_copy(update={"seed": 4})
    other_run = simulate_scenario(other, tmp_path / "other")
    quick = load_config(TELEMAX_CONFIG, ["validation.mode=on", "output.plots=false"])
    other_map = run_map(other_run.run_dir, quick, tmp_path / "other_map")
    assert other_map.metrics["ate_rmse_m"] != first.metrics["ate_rmse_m"]


# --- atomic output ---------------------------------------------------------------


def test_run_failing_after_read_leaves_no_folder(short_run, tmp_path):
    config = load_config(TELEMAX_CONFIG, ["keyframes.period_s=1000"])
    out = tmp_path / "results" / "map"
    with pytest.raises(GslamError, match="fewer than 2 keyframes"):
        run_map(short_run.run_dir, config, out)
    assert not out.exists()
    assert not (tmp_path / "results").exists() or listing(tmp_path / "results") == set()


def quick_config():
    return load_config(TELEMAX_CONFIG, ["output.plots=false"])


@pytest.mark.slow
@pytest.mark.parametrize("error", [RuntimeError("disk full"), KeyboardInterrupt()])
def test_run_dying_while_writing_leaves_no_folder(short_run, tmp_path, monkeypatch, error):
    import slam.outputs.pointcloud

    def die(*args, **kwargs):
        raise error

    monkeypatch.setattr(slam.outputs.pointcloud, "write_ply", die)
    out = tmp_path / "map"
    with pytest.raises(type(error)):
        run_map(short_run.run_dir, quick_config(), out)
    assert listing(tmp_path) == set()  # neither the folder nor its temporary sibling


@pytest.mark.slow
def test_failed_rerun_keeps_the_old_folder_and_a_rerun_replaces_it(short_run, tmp_path, monkeypatch):
    import slam.outputs.pointcloud

    out = tmp_path / "map"
    run_map(short_run.run_dir, quick_config(), out)
    (out / "notes.txt").write_text("the user's\n")
    before = listing(out)

    real = slam.outputs.pointcloud.write_ply

    def die(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(slam.outputs.pointcloud, "write_ply", die)
    with pytest.raises(RuntimeError):
        run_map(short_run.run_dir, quick_config(), out)
    assert listing(out) == before  # the earlier result, untouched
    assert listing(tmp_path) == {"map"}  # and no temporary folder left

    monkeypatch.setattr(slam.outputs.pointcloud, "write_ply", real)
    run_map(short_run.run_dir, quick_config(), out)
    assert listing(out) == MAP_FILES - {"trajectory.png", "map.png"} | {"notes.txt"}  # the map's files replaced
    assert (out / "notes.txt").read_text() == "the user's\n"
    assert listing(tmp_path) == {"map"}
