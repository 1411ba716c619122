"""The Husky bag (robot_localization's test1.bag): ungated vs gated mapping
with gyro, IMU yaw as compass and wheel odometry, GPS as the reference only
and, in a second variant, as a factor; against the robust kernels of
``configs/variants.yaml`` and the map without the compass.

    python -m scripts.bench husky [--bag PATH] [--config configs/datasets/husky.yaml]
                                  [--out runs/bench_husky]

The bag has no ground truth. GPS is the only reference:

* **ATE against GPS** (m): the estimate interpolated at each fix's time
  against the fix's east/north, RMSE over all fixes, SE(2)-aligned and
  unaligned (the graph starts at the first fix with the first compass
  heading, so both share the GPS frame). With GPS as a factor this measures
  the fit to the fixes it used, not an independent error.
* **GPS course**: the direction of travel between the fixes ``COURSE_LAG``
  apart (2 s), kept where the speed between them is at least
  ``MIN_SPEED_M_S``. A skid-steered Husky drives forward, so its heading
  should follow the course to within a few degrees on straight stretches.
* **Compass label**: "compass really wrong" where the IMU yaw differs from
  the GPS course by more than ``WRONG_DEG``. Against it: the fraction of
  course samples at which validation blames IMU_YAW (its most probable
  diagnosis contains it) that are labelled wrong (precision) and the
  fraction of labelled samples blamed (recall). The course is noisy at low
  speed and in turns, so the label is coarse.

Writes ``husky.md`` (the table), ``husky_heading.png`` (IMU yaw and the
estimated heading minus the GPS course over time, with the validator's
IMU_YAW alarms shaded) and ``husky_trajectories.png``, plus one result
folder per variant.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from scripts.bench.common import HUSKY_BAG, KERNELS, publish
from scripts.bench.judges import COURSE_LAG, MIN_SPEED_M_S, WRONG_DEG, Course, ate_vs_gps, gps_course, yaw_at
from slam.commands.compare import load_variants
from slam.config import PipelineConfig, load_config
from validation.base.geometry import wrap_angle
from slam.readers.datasets import data_root
from slam.readers.read import read_recording
from slam.pipeline.folder import MappingPipeline
from slam.recording import Recording

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]


@dataclass
class Row:
    variant: str
    ate_aligned_m: float
    ate_unaligned_m: float
    heading_rmse_deg: float
    compass_alarm_fraction: float | None
    precision: float | None
    recall: float | None
    runtime_s: float


def mounting_offset_deg(rec: Recording, course: Course, until_s: float = 120.0) -> float:
    """Circular mean of (IMU yaw - GPS course) over ``until_s`` s, deg: the
    calibration behind ``input.compass.mounting_yaw_deg`` (of the yaw read
    with the configured mounting, so 0 once it is set right)."""
    m = course.t < until_s
    d = yaw_at(rec.compass.t, rec.compass.yaw, course.t[m]) - course.yaw[m]
    return float(np.degrees(np.angle(np.mean(np.exp(1j * d)))))


def blamed_compass(outcome, at: np.ndarray) -> np.ndarray:
    """Whether IMU_YAW is in the most probable diagnosis at the validation
    step at or before each time of ``at``."""
    step = np.array(
        [bool(r.consistent and r.diagnoses and "IMU_YAW" in r.diagnoses[0]) for r in outcome.results]
    )
    k = np.clip(np.searchsorted(outcome.step_t, at, side="right") - 1, 0, len(step) - 1)
    return step[k]


def _ratio(a: int, b: int) -> float | None:
    return round(a / b, 3) if b else None


def run_variant(name: str, path: Path, config: PipelineConfig, rec: Recording, course: Course, out: Path) -> tuple[Row, object]:
    start = time.perf_counter()
    res = MappingPipeline(path, config, out / name, recording=rec).run()
    elapsed = time.perf_counter() - start
    aligned, unaligned = ate_vs_gps(res.trajectory, rec.gps)
    heading = yaw_at(res.trajectory.t, res.trajectory.yaw, course.t) - course.yaw
    alarm = precision = recall = None
    if res.validation is not None and res.validation.results is not None:
        wrong = np.abs(np.degrees(wrap_angle(yaw_at(rec.compass.t, rec.compass.yaw, course.t) - course.yaw))) > WRONG_DEG
        blamed = blamed_compass(res.validation, course.t)
        alarm = round(float(blamed_compass(res.validation, res.validation.step_t).mean()), 3)
        precision = _ratio(int((blamed & wrong).sum()), int(blamed.sum()))
        recall = _ratio(int((blamed & wrong).sum()), int(wrong.sum()))
    row = Row(name, aligned, unaligned, float(np.degrees(np.sqrt(np.mean(wrap_angle(heading) ** 2)))),
              alarm, precision, recall, elapsed)
    return row, res


def plot(out: Path, rec: Recording, course: Course, results: dict[str, object]) -> None:
    """Heading minus GPS course over time with IMU_YAW alarms; trajectories over GPS."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 5))
    ax = fig.add_subplot(1, 1, 1)
    d = np.degrees(wrap_angle(yaw_at(rec.compass.t, rec.compass.yaw, course.t) - course.yaw))
    ax.plot(course.t, d, ".", ms=3, color="tab:red", label="IMU yaw (compass) − GPS course")
    colours = {"ungated": "tab:blue", "gated": "tab:green"}
    for name, res in results.items():
        if name in colours:
            e = np.degrees(wrap_angle(yaw_at(res.trajectory.t, res.trajectory.yaw, course.t) - course.yaw))
            ax.plot(course.t, e, "-", lw=1, color=colours[name], label=f"estimate ({name}) − GPS course")
    gated = results.get("gated")
    if gated is not None and gated.validation is not None:
        v = gated.validation
        blamed = blamed_compass(v, v.step_t)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], blamed.astype(int), [0]])))
        for i, (a, b) in enumerate(zip(edges[::2], edges[1::2])):
            ax.axvspan(v.step_t[a], v.step_t[b - 1], color="orange", alpha=0.3, lw=0,
                       label="validator blames IMU_YAW" if i == 0 else None)
    ax.axhline(WRONG_DEG, color="grey", ls=":", lw=1)
    ax.axhline(-WRONG_DEG, color="grey", ls=":", lw=1, label=f"±{WRONG_DEG:.0f}° label threshold")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("heading − GPS course (deg)")
    ax.set_ylim(-60, 60)
    ax.set_title(f"{rec.name}: heading against the GPS course (fixes {COURSE_LAG} apart, ≥ {MIN_SPEED_M_S} m/s)")
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "husky_heading.png", dpi=120)

    fig = Figure(figsize=(7, 7))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(rec.gps.x, rec.gps.y, ".", ms=2, color="k", label="GPS fixes")
    for name, res in results.items():
        ax.plot(res.trajectory.x, res.trajectory.y, lw=1, label=name)
    ax.set_aspect("equal")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "husky_trajectories.png", dpi=120)


def markdown(rows: list[Row]) -> str:
    def f(v: float | None, fmt: str) -> str:
        return "–" if v is None else format(v, fmt)

    lines = [
        "| variant | ATE vs GPS aligned m | ATE vs GPS unaligned m | heading − course RMSE deg "
        "| IMU_YAW alarm fraction | precision | recall | time s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.variant} | {r.ate_aligned_m:.2f} | {r.ate_unaligned_m:.2f} | {r.heading_rmse_deg:.1f} "
            f"| {f(r.compass_alarm_fraction, '.3f')} | {f(r.precision, '.2f')} | {f(r.recall, '.2f')} | {r.runtime_s:.2f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", type=Path, default=None, help="default: DATA/rosbag/test1_husky_2015.bag")
    parser.add_argument("--config", type=Path, default=ROOT / "configs/datasets/husky.yaml")
    parser.add_argument("--out", type=Path, default=ROOT / "runs/bench_husky")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    path = args.bag or data_root() / HUSKY_BAG
    if not path.is_file():
        print(f"{path}: not found (set GSLAM_DATA to the data folder)", file=sys.stderr)
        return 1
    base = load_config(args.config, ["output.progress=false"])
    rec = read_recording(path, base.input)
    course = gps_course(rec.gps)
    print(f"IMU yaw - GPS course over the first 120 s (with the configured mounting): "
          f"{mounting_offset_deg(rec, course):+.1f} deg; {len(course.t)} course samples")
    args.out.mkdir(parents=True, exist_ok=True)
    rows, results = [], {}
    variants = {
        "ungated": [],
        "gated": ["validation.mode=on"],
        "ungated + GPS factor": ["backend.factors.gps.enabled=true"],
        "gated + GPS factor": ["backend.factors.gps.enabled=true", "validation.mode=on"],
        # The alternatives a user tries first: the robust kernels of `gslam
        # compare` (configs/variants.yaml), and the map without the compass.
        **load_variants(ROOT / "configs/variants.yaml", list(KERNELS)),
        "without the compass": ["backend.factors.compass.enabled=false"],
    }
    for name, overrides in variants.items():
        cfg = load_config(args.config, ["output.progress=false", *overrides])
        row, res = run_variant(name, path, cfg, rec, course, args.out)
        rows.append(row)
        results[name] = res
    plot(args.out, rec, course, results)
    table = markdown(rows)
    (args.out / "husky.md").write_text(table + "\n")
    publish("husky", "The Husky bag: ungated and gated against GPS", table, argv)
    print(table)
    print(f"wrote {args.out}")
    return 0

