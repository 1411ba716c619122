"""Relative errors on the CARMEN logs against their corrected reference, in
the spirit of Kümmerle et al., "On measuring the accuracy of SLAM
algorithms" (Autonomous Robots 2009).

    python -m scripts.bench carmen [--root DIR] [--logs intel freiburg-079 aces]
                                   [--config configs/datasets/carmen.yaml] [--out carmen.md]

For each log and each method the relative pose error ``E = inverse(d_ref)
d_est`` of the displacement ``d`` between two scans is summarised as mean
+- standard deviation of its translation (m) and rotation (deg), over
consecutive scan pairs and over 10 m windows of reference path (evo-style
pairs, :func:`slam.evaluation.rpe`), plus the SE(2)-aligned ATE RMSE (m).

Methods: the raw odometry recovered by the reader; KISS-ICP alone as the
pipeline runs it (its own constant-velocity prediction); KISS-ICP seeded
with the odometry step as its prediction; the pipeline's graph (odometry +
scan matching, the given config without loop closing); the same graph with
the config's loop closing (its ``loops`` section, enabled). Times are
wall-clock seconds.

The published anchors are Kümmerle et al.'s (2009) translational errors on
manually verified relations (not consecutive scans, not 10 m windows), for
scan matching without loop closure and for graph-based mapping, so they are
a scale, not the same measurement. The reference here is itself a SLAM
result, not independent ground truth.
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scripts.bench.common import publish
from slam.config import PipelineConfig, load_config
from slam.evaluation import ate, rpe
from slam.frontend import ScanMatcher, run_frontend, scan_points
from slam.geometry import wrap_angle
from slam.io.carmen import read_carmen
from slam.io.atomic import write_text
from slam.io.datasets import data_root
from slam.measurements import interpolate_poses, relative_poses
from slam.pipeline import MappingPipeline
from slam.recording import Recording, Scans, Trajectory

log = logging.getLogger(__name__)

# Kümmerle et al. 2009 ("On measuring the accuracy of SLAM algorithms",
# Autonomous Robots 27), absolute translational error on manually verified
# relations, m (mean +- std): scan matching without loop closure, and
# graph-based mapping.
PUBLISHED_M = {"intel": (0.220, 0.296), "freiburg-079": (0.258, 0.427), "aces": (0.173, 0.614)}
GRAPH_MAPPING_M = {"intel": (0.031, 0.026), "freiburg-079": (0.056, 0.042), "aces": (0.044, 0.044)}
WINDOW_M = 10.0


@dataclass
class Row:
    """Errors of one method on one log; (mean, std) pairs."""

    log: str
    method: str
    step_trans_m: tuple[float, float]
    step_rot_deg: tuple[float, float]
    window_trans_m: tuple[float, float]
    window_rot_deg: tuple[float, float]
    ate_m: float
    time_s: float


def _poses(traj: Trajectory) -> np.ndarray:
    return np.column_stack([traj.x, traj.y, traj.yaw])


def _stats(values: np.ndarray) -> tuple[float, float]:
    return (float(np.mean(values)), float(np.std(values))) if len(values) else (float("nan"), float("nan"))


def evaluate(log_name: str, method: str, est: Trajectory, ref: Trajectory, time_s: float) -> Row:
    """Relative errors of ``est`` against ``ref`` (same scan times)."""
    ref_at = interpolate_poses(ref, est.t)
    p = _poses(est)
    err = relative_poses(relative_poses(ref_at[:-1], ref_at[1:]), relative_poses(p[:-1], p[1:]))
    window = rpe(est, ref, WINDOW_M)
    return Row(
        log_name,
        method,
        _stats(np.hypot(err[:, 0], err[:, 1])),
        _stats(np.degrees(np.abs(wrap_angle(err[:, 2])))),
        _stats(window.trans_errors_m),
        _stats(window.rot_errors_deg),
        ate(est, ref, align=True).rmse_m,
        time_s,
    )


def seeded_kiss_icp(scans: Scans, odometry: Trajectory, config: PipelineConfig) -> Trajectory:
    """KISS-ICP with the odometry step as its prediction instead of its
    constant-velocity model (the thinned logs turn up to 30 deg between
    scans, which that model cannot predict)."""
    matcher = ScanMatcher(config.frontend, scans.range_max)
    odo = interpolate_poses(odometry, scans.t)
    steps = relative_poses(odo[:-1], odo[1:])
    out = np.zeros((len(scans), 3))
    for i in range(len(scans)):
        if i > 0:
            c, s = np.cos(steps[i - 1, 2]), np.sin(steps[i - 1, 2])
            delta = np.eye(4)
            delta[:2, :2] = [[c, -s], [s, c]]
            delta[:2, 3] = steps[i - 1, :2]
            matcher._icp.last_delta = delta
        pts = scan_points(scans.ranges[i], scans.angles, config.frontend.min_range_m, matcher.max_range)
        out[i] = matcher.register(pts)
    return Trajectory(t=scans.t.copy(), x=out[:, 0], y=out[:, 1], yaw=out[:, 2])


def bench_log(path: Path, config: PipelineConfig) -> list[Row]:
    """Every method on one log."""
    name = path.name.split("-corrected")[0]
    rec: Recording = read_carmen(path)
    ref = rec.groundtruth
    rows = [evaluate(name, "raw odometry", rec.odometry, ref, 0.0)]

    start = time.perf_counter()
    fe = run_frontend(rec.scans, config.frontend)
    rows.append(evaluate(name, "KISS-ICP alone", fe.poses, ref, time.perf_counter() - start))

    start = time.perf_counter()
    seeded = seeded_kiss_icp(rec.scans, rec.odometry, config)
    rows.append(evaluate(name, "KISS-ICP seeded by odometry", seeded, ref, time.perf_counter() - start))

    for method, loops in (("graph (odometry + scan matching)", False), ("graph + loop closing", True)):
        with tempfile.TemporaryDirectory() as tmp:
            cfg = config.model_copy(deep=True)
            cfg.output.plots = False
            cfg.loops.enabled = loops
            start = time.perf_counter()
            res = MappingPipeline(path, cfg, Path(tmp) / name, recording=rec).run()
            elapsed = time.perf_counter() - start
        rows.append(evaluate(name, method, res.trajectory, ref, elapsed))
    return rows


def markdown(rows: list[Row]) -> str:
    """The rows as a Markdown table, the published anchors beside every
    method: whether its consecutive-scan error is at or below the
    scan-matching anchor, and its 10 m error at or below the graph-mapping
    anchor."""
    head = (
        "| log | method | consecutive trans m | consecutive rot deg | 10 m trans m | 10 m rot deg "
        "| ATE m (aligned) | time s | published SM, m | consecutive ≤ SM | published graph mapping, m "
        "| 10 m ≤ graph mapping |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|"
    )
    lines = [head]
    for r in rows:
        pub, gm = PUBLISHED_M.get(r.log), GRAPH_MAPPING_M.get(r.log)
        anchor = f"{pub[0]:.3f} ± {pub[1]:.3f}" if pub else "–"
        below = ("yes" if r.step_trans_m[0] <= pub[0] else "no") if pub else "–"
        gm_anchor = f"{gm[0]:.3f} ± {gm[1]:.3f}" if gm else "–"
        gm_below = ("yes" if r.window_trans_m[0] <= gm[0] else "no") if gm else "–"
        lines.append(
            f"| {r.log} | {r.method} | {r.step_trans_m[0]:.3f} ± {r.step_trans_m[1]:.3f} "
            f"| {r.step_rot_deg[0]:.2f} ± {r.step_rot_deg[1]:.2f} "
            f"| {r.window_trans_m[0]:.3f} ± {r.window_trans_m[1]:.3f} "
            f"| {r.window_rot_deg[0]:.2f} ± {r.window_rot_deg[1]:.2f} "
            f"| {r.ate_m:.2f} | {r.time_s:.1f} | {anchor} | {below} | {gm_anchor} | {gm_below} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=None, help="data root (default: $GSLAM_DATA or ../shared/data)")
    parser.add_argument("--logs", nargs="+", default=["intel", "freiburg-079", "aces"])
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a config key (as gslam map --set), e.g. loops.query_spacing_m=3")
    parser.add_argument("--config", type=Path, default=Path(__file__).resolve().parents[2] / "configs/datasets/carmen.yaml")
    parser.add_argument("--out", type=Path, default=None, help="also write the table to this Markdown file")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    root = data_root() if args.root is None else args.root
    config = load_config(args.config, args.overrides)
    rows: list[Row] = []
    for name in args.logs:
        path = root / "carmen" / f"{name}-corrected.log.gz"
        if not path.is_file():
            print(f"{path}: not found; skipped", file=sys.stderr)
            continue
        rows.extend(bench_log(path, config))
    text = markdown(rows)
    if args.out is not None:
        write_text(args.out, text)
    publish("carmen", "Relative errors on the CARMEN logs against their corrected reference", text, argv)
    print(text)
    return 0

