"""Loop closing on the CARMEN logs kept for tuning: one line per log.

    python -m scripts.bench tune_loops [--logs fhw freiburg-101 seattle belgioioso] [--set KEY=VALUE ...]
                                 [--config configs/datasets/carmen.yaml] [--root DATA]

For each log, mapped with the config and the overrides: the loops found and
kept, how many of each are wrong against the log's corrected poses (more
than 0.15 m or 3 deg off), the loops' median error and median normalised
error (NEES, 3 dof: about 2.4 when their information is right), the mean
relative error over 10 m of path, the aligned ATE, and the loop stage's
time. The loop parameters of ``configs/datasets/carmen.yaml`` were chosen
with this script on the default logs; intel, freiburg-079 and aces are kept
for reporting (scripts/bench/carmen.py).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from scripts.bench.common import carmen_log
from slam.config import load_config
from slam.outputs.evaluation import ate, rpe
from slam.readers.datasets import data_root
from validation.base.geometry import between
from slam.recording import interpolate_poses
from slam.pipeline.core import Mapping
from slam.readers.read import read_recording

TUNING_LOGS = ["fhw", "freiburg-101", "seattle", "belgioioso"]


def tune_log(path: Path, config_path: Path, overrides: list[str]) -> str:
    cfg = load_config(config_path, ["output.plots=false", "output.progress=false", "loops.enabled=true", *overrides])
    p = Mapping(read_recording(path, cfg.input), cfg, source=path)
    p.match_scans()
    p.build_measurements()
    p.validate()
    p.judge_loops(p.find_loops())
    p.optimise()
    ref = interpolate_poses(p.recording.groundtruth, p.measurements.t)
    errors, nees, kept = [], [], []
    for v in p.loop_observation.verdicts:
        e = between(between(ref[v.loop.i], ref[v.loop.j]), v.loop.delta)
        errors.append((np.hypot(e[0], e[1]), np.degrees(abs(e[2]))))
        nees.append(float(e @ v.loop.information @ e))
        kept.append(v.accepted)
    err, kept = np.array(errors).reshape(-1, 2), np.array(kept, dtype=bool)
    wrong = (err[:, 0] > 0.15) | (err[:, 1] > 3.0)
    window = rpe(p.backend.trajectory, p.recording.groundtruth, 10.0)
    med = np.median(err, axis=0) if len(err) else (np.nan, np.nan)
    return (
        f"{path.name.split('-corrected')[0]}: loops {len(err)} kept {kept.sum()} wrong {wrong.sum()} wrong kept "
        f"{(wrong & kept).sum()} | error median {med[0]:.3f} m {med[1]:.2f} deg, NEES median "
        f"{np.median(nees) if nees else float('nan'):.1f} | 10 m: {np.mean(window.trans_errors_m):.3f} m "
        f"{np.mean(window.rot_errors_deg):.2f} deg | ATE {ate(p.backend.trajectory, p.recording.groundtruth, align=True).rmse_m:.2f} m "
        f"| loop stage {p.timings.loops_s:.2f} s"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", nargs="+", default=TUNING_LOGS)
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--config", type=Path, default=Path(__file__).resolve().parents[2] / "configs/datasets/carmen.yaml")
    ap.add_argument("--root", type=Path, default=None, help="data root (default: $GSLAM_DATA or ../shared/data)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.ERROR)
    root = data_root() if args.root is None else args.root
    for name in args.logs:
        path = carmen_log(root, name)
        if not path.is_file():
            print(f"{path}: not found; skipped", file=sys.stderr)
            continue
        print(tune_log(path, args.config, args.overrides), flush=True)
    return 0

