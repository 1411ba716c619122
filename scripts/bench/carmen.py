"""Maps of the field's standard 2D laser logs, against their corrected
reference, the published systems and the peer a user would try first.

    python -m scripts.bench carmen [--logs intel freiburg-079 ...] [--config configs/datasets/carmen.yaml]
                                   [--kiss-slam PATH] [--missions hall corridor ...] [--mission-seeds 1-2]
                                   [--root DIR] [--set KEY=VALUE ...]

Every log is mapped as a user maps it: ``gslam map LOG --config CONFIG``,
timed as a process. Against the log's corrected poses (a good SLAM result,
not independent ground truth), at the scan times:

* ATE: RMSE of the positions after an SE(2) alignment (m);
* mean relative error of consecutive scans, translation (m) and rotation
  (deg), and over 10 m of reference path (evo-style pairs);
* the loop constraints kept and how many are wrong: more than 0.15 m or
  3 deg off the reference (as Hess et al. 2016 count them), in the
  directions the constraint pins (it claims nothing along a corridor's free
  axis). A wrong one is *confirmed* when the reference agrees with its own
  scans there: point-to-line ICP of the loop's scan against the carrier
  scan and its two neighbours, all placed by the reference, started at the
  reference's pose, stays within 0.15 m and 3 deg of it. Where that ICP
  moves the reference's pose further, the reference is off there too and
  the loop cannot be judged by it.

Beside it: the raw odometry, KISS-ICP as the pipeline runs it (seeded by the
odometry), and kiss-slam in its default and indoor settings
(:mod:`scripts.bench.peers`), measured the same way; the published
figures of Cartographer (Hess et al. 2016, Table II) and graph mapping
(Kümmerle et al. 2009), whose relative errors are on manually verified
relations, so a scale rather than the same measurement.

The simulated missions (``--missions``) are mapped by ``gslam map --gating
on`` with ``configs/telemax.yaml`` and by kiss-slam on the same scans,
against the simulator's ground truth.

The shipped CARMEN config was chosen on fhw, freiburg-101, seattle,
belgioioso and infinite-corridor (tuning logs); intel, freiburg-079, aces
and csail are reported on; orebro (no odometry) is neither.
"""

from __future__ import annotations

import argparse
import csv
import json
import logging
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scripts.bench.common import CONFIGS, REPO, carmen_log, include_in_readme, publish, simulated, table
from scripts.bench.peers import PeerRun, export_scans, kiss_slam
from slam.config import load_config
from slam.outputs.evaluation import ate, rpe
from slam.frontend.kiss import run_frontend
from validation.base.geometry import between, wrap_angle
from slam.results.atomic import atomic_path
from slam.readers.datasets import data_root
from slam.readers.read import read_recording
from slam.outputs.tum import read_tum
from slam.recording import interpolate_poses, relative_poses
from slam.recording import Recording, Trajectory

log = logging.getLogger(__name__)

LOGS = ("intel", "freiburg-079", "aces", "csail", "fhw", "freiburg-101", "seattle", "belgioioso", "orebro",
        "infinite-corridor")
TUNING = ("fhw", "freiburg-101", "seattle", "belgioioso", "infinite-corridor")
REPORTED = ("intel", "freiburg-079", "aces", "csail")
# Mean translational relative error (m) as published: Cartographer (Hess et
# al. 2016, Table II) and graph mapping (Kümmerle et al. 2009, Table I).
CARTOGRAPHER_M = {"intel": 0.0229, "freiburg-079": 0.0452, "aces": 0.0375, "csail": 0.0319}
GRAPH_MAPPING_M = {"intel": 0.031, "freiburg-079": 0.056, "aces": 0.044, "csail": 0.004}
WRONG_M, WRONG_DEG = 0.15, 3.0
WINDOW_M = 10.0
MISSIONS = ("telemax_lab", "hall", "corridor")


@dataclass
class Errors:
    ate_m: float
    step_m: float
    step_deg: float
    window_m: float
    window_deg: float


@dataclass
class Loops:
    kept: int = 0
    wrong: int = 0
    confirmed: int = 0  # wrong where the reference agrees with its own scans

    @property
    def precision(self) -> float:
        return 1.0 - self.wrong / self.kept if self.kept else float("nan")

    @property
    def confirmed_precision(self) -> float:
        return 1.0 - self.confirmed / self.kept if self.kept else float("nan")


@dataclass
class Row:
    name: str
    method: str
    errors: Errors | None
    wall_s: float | None = None
    duration_s: float | None = None
    loops: Loops | None = None
    closures: int | None = None
    note: str = ""
    extra: dict = field(default_factory=dict)


def errors_of(est: Trajectory, ref: Trajectory) -> Errors:
    """The errors of the module docstring, of ``est`` at its own times."""
    ref_at = interpolate_poses(ref, est.t)
    p = np.column_stack([est.x, est.y, est.yaw])
    e = relative_poses(relative_poses(ref_at[:-1], ref_at[1:]), relative_poses(p[:-1], p[1:]))
    window = rpe(est, ref, WINDOW_M)
    return Errors(ate(est, ref, align=True).rmse_m, float(np.mean(np.hypot(e[:, 0], e[:, 1]))),
                  float(np.degrees(np.mean(np.abs(wrap_angle(e[:, 2]))))),
                  float(np.mean(window.trans_errors_m)) if len(window.trans_errors_m) else float("nan"),
                  float(np.mean(window.rot_errors_deg)) if len(window.rot_errors_deg) else float("nan"))


def gslam_map(source: Path, config: Path, out: Path, extra: list[str]) -> tuple[dict, Trajectory, float]:
    """``gslam map`` as a process: its metrics, trajectory (times from the
    recording's start) and wall time."""
    cmd = [str(Path(sys.executable).parent / "gslam"), "-q", "map", str(source), "--config", str(config), "--out", str(out), *extra]
    start = time.perf_counter()
    done = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: {done.stderr.strip()}")
    metrics = json.loads((out / "metrics.json").read_text())
    return metrics, out, wall


def trajectories(out: Path) -> tuple[Trajectory, Trajectory]:
    """The estimate and the reference of a map result, on one time base."""
    ref, t0 = read_tum(out / "groundtruth.tum")
    est, _ = read_tum(out / "trajectory.tum", t0)
    return est, ref


def judge_loops(out: Path, rec: Recording, config) -> Loops:
    """The kept loops of a map result against the reference; see the module docstring."""
    from slam.matching.icp import refine
    from slam.matching.points import point_map
    from slam.submaps.scans import ScanPoints

    path = out / "loops.csv"
    if not path.is_file():
        return Loops()
    rows = [r for r in csv.DictReader(path.open()) if r["decision"] == "accepted"]
    result = Loops(kept=len(rows))
    if not rows:
        return result
    ref, t0 = read_tum(out / "groundtruth.tum")
    scan_of = {float(t): k for k, t in enumerate(np.round(rec.scans.t, 4))}
    fe = config.frontend
    points = None
    for r in rows:
        ti, tj = float(r["t_i"]), float(r["t_j"])
        gi, gj = interpolate_poses(ref, np.array([ti, tj]))
        truth = between(gi, gj)
        delta = np.array([float(r["dx_m"]), float(r["dy_m"]), np.radians(float(r["dyaw_deg"]))])
        err = between(truth, delta)
        for v in filter(None, r.get("free", "").split(";")):
            u = np.array([float(x) for x in v.split()])
            err = err - u * (u @ err)
        if np.hypot(err[0], err[1]) <= WRONG_M and abs(err[2]) <= np.radians(WRONG_DEG):
            continue
        result.wrong += 1
        i, j = scan_of.get(round(ti, 4)), scan_of.get(round(tj, 4))
        if i is None or j is None:
            continue
        if points is None:
            points = ScanPoints(rec.scans, fe.min_range_m, fe.max_range_m, 0.05)
        near = [k for k in (i - 1, i, i + 1) if 0 <= k < len(rec.scans) and k != j]
        poses = interpolate_poses(ref, rec.scans.t[near])
        pts, nrm = [], []
        for k, p in zip(near, poses):
            rel = between(gi, p)
            c, s = np.cos(rel[2]), np.sin(rel[2])
            pts.append(points.points[k] @ np.array([[c, s], [-s, c]]) + rel[:2])
            nrm.append(points.normals[k] @ np.array([[c, s], [-s, c]]))
        pts, nrm = np.concatenate(pts), np.concatenate(nrm)
        keep = np.linalg.norm(nrm, axis=1) > 0.5
        icp = refine(points.points[j], point_map(pts[keep], nrm[keep]), truth)
        moved = between(truth, icp.pose)
        if np.hypot(moved[0], moved[1]) <= WRONG_M and abs(moved[2]) <= np.radians(WRONG_DEG):
            result.confirmed += 1
    return result


def bench_log(name: str, path: Path, config_path: Path, overrides: list[str], work: Path, peer: str | None) -> list[Row]:
    config = load_config(config_path, overrides)
    rec = read_recording(path, config.input)
    ref = rec.groundtruth
    rows = []
    if rec.odometry is not None:
        rows.append(Row(name, "raw odometry", errors_of(_at(rec.odometry, rec.scans.t), ref)))
    start = time.perf_counter()
    fe = run_frontend(rec.scans, config.frontend, odometry=rec.odometry)
    rows.append(Row(name, "KISS-ICP (seeded by odometry)", errors_of(fe.poses, ref), time.perf_counter() - start,
                    rec.duration))
    extra = [a for kv in overrides for a in ("--set", kv)]
    metrics, out, wall = gslam_map(path, config_path, work / "gslam" / name, extra)
    est, ref_tum = trajectories(out)
    rows.append(Row(name, "gated-slam", errors_of(est, ref_tum), wall, metrics["duration_s"],
                    judge_loops(out, rec, config), extra={"submaps": metrics.get("submaps")}))
    if peer is not None:
        folder = work / "ply" / name
        export_scans(rec.scans, folder, config.frontend.min_range_m, config.frontend.max_range_m)
        for setting in ("default", "indoor"):
            run = kiss_slam(peer, folder, rec.scans.t, work / "kiss_slam" / setting / name, setting)
            rows.append(_peer_row(name, f"kiss-slam ({setting})", run, ref, rec.duration))
    return rows


def bench_mission(scenario: str, seed: int, work: Path, peer: str | None) -> list[Row]:
    run = simulated(work / "sim", scenario, seed)
    name = f"{scenario} s{seed}"
    config_path = CONFIGS / "telemax.yaml"
    config = load_config(config_path)
    rec = read_recording(run, config.input)
    metrics, out, wall = gslam_map(run, config_path, work / "gslam" / f"{scenario}_s{seed}", ["--gating", "on"])
    est, ref = trajectories(out)
    loops = metrics.get("loops") or {}
    rows = [Row(name, "gated-slam (gated)", errors_of(est, ref), wall, metrics["duration_s"],
                Loops(loops.get("accepted", 0), loops.get("wrong_accepted", 0), loops.get("wrong_accepted", 0)))]
    if peer is not None:
        folder = work / "ply" / f"{scenario}_s{seed}"
        export_scans(rec.scans, folder, config.frontend.min_range_m, config.frontend.max_range_m)
        for setting in ("default", "indoor"):
            peer_run = kiss_slam(peer, folder, rec.scans.t, work / "kiss_slam" / setting / f"{scenario}_s{seed}", setting)
            rows.append(_peer_row(name, f"kiss-slam ({setting})", peer_run, rec.groundtruth, rec.duration))
    return rows


def _at(traj: Trajectory, t: np.ndarray) -> Trajectory:
    p = interpolate_poses(traj, t)
    return Trajectory(t=t.copy(), x=p[:, 0], y=p[:, 1], yaw=p[:, 2])


def _peer_row(name: str, method: str, run: PeerRun, ref: Trajectory, duration: float) -> Row:
    if run.trajectory is None:
        return Row(name, method, None, run.wall_s or None, duration, note=run.error)
    return Row(name, method, errors_of(run.trajectory, ref), run.wall_s, duration, closures=run.closures)


def _f(x: float | None, digits: int) -> str | None:
    return None if x is None or not np.isfinite(x) else f"{x:.{digits}f}"


def _pct(x: float) -> str | None:
    return None if not np.isfinite(x) else f"{100 * x:.1f} %"


def headline(rows: list[Row]) -> str:
    ours = [r for r in rows if r.method == "gated-slam"]
    body = []
    for r in ours:
        e, lp = r.errors, r.loops
        role = "reported" if r.name in REPORTED else "tuning" if r.name in TUNING else "–"
        body.append([r.name, role, _f(e.ate_m, 3), _f(e.step_m, 4), _f(e.step_deg, 2), _f(GRAPH_MAPPING_M.get(r.name), 3),
                     _f(CARTOGRAPHER_M.get(r.name), 4), _f(e.window_m, 3), lp.kept, lp.wrong, _pct(lp.precision),
                     lp.confirmed, _pct(lp.confirmed_precision), _f(r.wall_s, 1),
                     _f(r.duration_s / r.wall_s if r.wall_s else None, 0)])
    return table(["log", "role", "ATE m", "consecutive m", "consecutive deg", "graph mapping m", "Cartographer m",
                  "10 m window m", "loops kept", "wrong", "precision", "confirmed wrong", "precision (confirmed)",
                  "time s", "× real time"], body)


def comparison(rows: list[Row]) -> str:
    body = []
    for r in rows:
        e = r.errors
        body.append([r.name, r.method, _f(e.ate_m, 3) if e else None, _f(e.step_m, 4) if e else None,
                     _f(e.step_deg, 2) if e else None, _f(e.window_m, 3) if e else None,
                     _f(e.window_deg, 2) if e else None, r.loops.kept if r.loops else r.closures, _f(r.wall_s, 1),
                     r.note or None])
    return table(["run", "method", "ATE m", "consecutive m", "consecutive deg", "10 m window m", "10 m window deg",
                  "loops kept", "time s", "note"], body)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=None, help="data root (default: $GSLAM_DATA or ../shared/data)")
    parser.add_argument("--logs", nargs="+", default=list(LOGS), choices=LOGS)
    parser.add_argument("--config", type=Path, default=CONFIGS / "datasets" / "carmen.yaml")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                        help="override a config key of the logs' config (as gslam map --set)")
    parser.add_argument("--kiss-slam", default="kiss_slam_pipeline",
                        help="kiss-slam's executable (its own venv: see scripts/bench/peers.py); 'none' skips it")
    parser.add_argument("--missions", nargs="*", default=list(MISSIONS), help="simulated scenarios to map too")
    parser.add_argument("--mission-seeds", default="1-2", help="seeds of the missions, e.g. 1-2")
    parser.add_argument("--work", type=Path, default=None, help="keep the result folders here (default: temporary)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    root = data_root() if args.root is None else args.root
    peer = None if args.kiss_slam == "none" else args.kiss_slam
    first, _, last = args.mission_seeds.partition("-")
    seeds = range(int(first), int(last or first) + 1)
    with tempfile.TemporaryDirectory(prefix="bench_carmen_") as tmp:
        work = args.work if args.work is not None else Path(tmp)
        rows: list[Row] = []
        for name in args.logs:
            path = carmen_log(root, name)
            if not path.is_file():
                print(f"{path}: not found; skipped", file=sys.stderr)
                continue
            print(f"== {name}", flush=True)
            rows.extend(bench_log(name, path, args.config, args.overrides, work, peer))
        missions: list[Row] = []
        for scenario in args.missions:
            for seed in seeds:
                print(f"== {scenario} seed {seed}", flush=True)
                missions.extend(bench_mission(scenario, seed, work, peer))
        intel = work / "gslam" / "intel" / "map.png"
        if intel.is_file():  # the README's picture, from this run
            with atomic_path(REPO / "docs" / "figures" / "intel_map.png") as tmp_png:
                tmp_png.write_bytes(intel.read_bytes())
    text = ("## gated-slam on the logs\n\n"
            f"Config `{args.config.relative_to(REPO) if args.config.is_relative_to(REPO) else args.config}`"
            f"{' with ' + ', '.join(args.overrides) if args.overrides else ''}. Relative errors are means; "
            "\"graph mapping\" and \"Cartographer\" are the published means on verified relations.\n\n"
            + headline(rows)
            + "\n## Against the alternatives, measured the same way\n\n" + comparison(rows))
    if missions:
        text += ("\n## Simulated missions (ground truth; `configs/telemax.yaml`, gated)\n\n" + comparison(missions))
    publish("carmen", "Maps of the standard 2D laser logs and the simulated missions", text, argv)
    include_in_readme("carmen")
    print(text)
    return 0
