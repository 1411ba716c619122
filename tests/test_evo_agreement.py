"""Our ATE / RPE agree with evo's command-line tools on the same TUM files.

evo is GPL-licensed, so the package never imports it; this test only runs
``evo_ape`` / ``evo_rpe`` as separate processes and reads the statistics
and per-pose error arrays they save (a zip of JSON and .npy files).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from slam.outputs.evaluation import ate, evaluate, rpe
from slam.outputs.tum import read_tum, write_tum
from slam.recording import Trajectory

def _evo_tool(name: str) -> str | None:
    """evo's console script: beside this interpreter (a virtualenv that is
    not activated), else on PATH."""
    here = Path(sys.executable).parent / name
    return str(here) if here.exists() else shutil.which(name)


EVO_APE, EVO_RPE = _evo_tool("evo_ape"), _evo_tool("evo_rpe")

pytestmark = pytest.mark.skipif(
    EVO_APE is None or EVO_RPE is None,
    reason="evo is not installed (test-only dependency: pip install evo)",
)

T0 = 1_700_000_000.0
RTOL = 1e-6


def _loop_with_drift(tmp_path: Path) -> tuple[Path, Path]:
    """A 126 m loop as the reference (10 Hz) and a dead-reckoned estimate
    with noisy increments, a heading bias and a scale error (5 Hz, stamps
    jittered by up to 3 ms, some poses missing)."""
    rng = np.random.default_rng(42)
    t = np.arange(0.0, 120.0, 0.1)
    speed = np.where((t > 30.0) & (t < 35.0), 0.0, 1.1)  # a stop: flat path length
    yaw_rate = 2 * np.pi / 110.0 + 0.05 * np.sin(0.3 * t)
    yaw = np.cumsum(yaw_rate) * 0.1
    x = np.cumsum(speed * np.cos(yaw)) * 0.1
    y = np.cumsum(speed * np.sin(yaw)) * 0.1
    ref = Trajectory(t=t, x=x, y=y, yaw=(yaw + np.pi) % (2 * np.pi) - np.pi)

    # Odometry increments in the body frame, corrupted, then re-integrated.
    step = np.hypot(np.diff(x), np.diff(y)) * 1.02 + rng.normal(0.0, 0.005, len(t) - 1)
    dyaw = np.diff(yaw) + 0.0003 + rng.normal(0.0, 0.002, len(t) - 1)
    est_yaw = np.concatenate([[yaw[0]], yaw[0] + np.cumsum(dyaw)])
    est_x = np.concatenate([[x[0]], x[0] + np.cumsum(step * np.cos(est_yaw[:-1]))])
    est_y = np.concatenate([[y[0]], y[0] + np.cumsum(step * np.sin(est_yaw[:-1]))])
    keep = np.arange(0, len(t), 2)
    keep = keep[rng.random(len(keep)) > 0.1]
    est = Trajectory(
        t=t[keep] + rng.uniform(-0.003, 0.003, len(keep)),
        x=est_x[keep],
        y=est_y[keep],
        yaw=(est_yaw[keep] + np.pi) % (2 * np.pi) - np.pi,
    )
    ref_path, est_path = tmp_path / "ref.tum", tmp_path / "est.tum"
    write_tum(ref_path, ref, T0)
    write_tum(est_path, est, T0)
    return ref_path, est_path


def _run_evo(jobs: dict[str, list[str]], tmp_path: Path) -> dict[str, tuple[dict, np.ndarray]]:
    """Run evo commands in parallel; (stats, per-pose errors) per job name."""
    env = dict(os.environ, MPLBACKEND="Agg")
    procs = {}
    for name, args in jobs.items():
        zip_path = tmp_path / f"{name}.zip"
        cmd = [*args, "--no_warnings", "--save_results", str(zip_path)]
        proc = subprocess.Popen(
            cmd, env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        procs[name] = (zip_path, proc)
    results = {}
    for name, (zip_path, proc) in procs.items():
        out, _ = proc.communicate(timeout=120)
        assert proc.returncode == 0, f"{name} failed:\n{out}"
        with zipfile.ZipFile(zip_path) as archive:
            stats = json.loads(archive.read("stats.json"))
            with archive.open("error_array.npy") as f:
                errors = np.load(f)
        results[name] = (stats, errors)
    return results


@pytest.mark.slow
def test_ate_and_rpe_agree_with_evo(tmp_path):
    ref_path, est_path = _loop_with_drift(tmp_path)
    ref, _ = read_tum(ref_path, t0=T0)
    est, _ = read_tum(est_path, t0=T0)
    files = ["tum", str(ref_path), str(est_path)]
    rpe_args = ["--delta_unit", "m", "--all_pairs", "--pairs_from_reference"]
    jobs = {"ape": [EVO_APE, *files], "ape_aligned": [EVO_APE, *files, "-a"]}
    for delta in (5, 20):
        rpe_cmd = [EVO_RPE, *files, "--delta", str(delta), *rpe_args]
        jobs[f"rpe_trans_{delta}"] = [*rpe_cmd, "-r", "trans_part"]
        jobs[f"rpe_rot_{delta}"] = [*rpe_cmd, "-r", "angle_deg"]
    evo = _run_evo(jobs, tmp_path)

    for name, align in (("ape", False), ("ape_aligned", True)):
        ours = ate(est, ref, align=align)
        stats, errors = evo[name]
        np.testing.assert_allclose(ours.errors_m, errors, rtol=RTOL, atol=1e-9)
        ours_stats = {"rmse": ours.rmse_m, "mean": ours.mean_m, "median": ours.median_m, "max": ours.max_m}
        for key, value in ours_stats.items():
            assert value == pytest.approx(stats[key], rel=RTOL), (name, key)

    metrics = evaluate(est, ref, deltas_m=[5.0, 20.0])
    for delta in (5, 20):
        ours = rpe(est, ref, float(delta))
        trans_stats, trans_errors = evo[f"rpe_trans_{delta}"]
        rot_stats, rot_errors = evo[f"rpe_rot_{delta}"]
        # Same pairs in the same order, so the error arrays match element-wise.
        np.testing.assert_allclose(ours.trans_errors_m, trans_errors, rtol=RTOL, atol=1e-9)
        np.testing.assert_allclose(ours.rot_errors_deg, rot_errors, rtol=RTOL, atol=1e-7)
        trans_pct, rot_deg_per_m = 100.0 * trans_stats["mean"] / delta, rot_stats["mean"] / delta
        assert metrics[f"rpe_trans_pct_{delta}m"] == pytest.approx(trans_pct, rel=RTOL)
        assert metrics[f"rpe_rot_deg_per_m_{delta}m"] == pytest.approx(rot_deg_per_m, rel=RTOL)
    assert metrics["ate_rmse_m"] == pytest.approx(evo["ape_aligned"][0]["rmse"], rel=RTOL)
    assert metrics["ate_rmse_unaligned_m"] == pytest.approx(evo["ape"][0]["rmse"], rel=RTOL)
    # The drift is real, so agreement is not agreement on zero.
    assert metrics["ate_rmse_unaligned_m"] > 1.0 and metrics["rpe_trans_pct"] > 0.5
