"""BROAD: the compass observers on every trial, with thresholds chosen on
the other trials (leave-one-trial-out).

    python -m scripts.bench broad [--data DIR] [--config configs/datasets/broad.yaml]
                                  [--workers 2] [--out runs/bench_broad]

The validator of ``configs/datasets/broad.yaml`` has two observers of the
compass (IMU_YAW): the trend relation ``yaw_compass_gyro`` (boundary b,
window w, threshold th) and the magnetometer check ``mag_plausible`` (field
strength and dip against the trial's first seconds, tolerances dB and ddip,
deviant for at least ``hold``). Against the reader's label "compass really
wrong" (the magnetometer's heading off the optical heading by more than
20 deg; :mod:`slam.readers.broad`), per validation step (10 Hz):

* **alarm fraction** and **false-alarm fraction** (alarms outside the
  label), as ``metrics.json`` defines them (:mod:`validation.metrics`). On
  undisturbed trials every alarm is false, except on trial 08, whose fast
  rotations push the undisturbed compass past 20 deg for 8.7 s.
* **recall / precision** per step, **detected** labelled intervals (an
  IMU_YAW diagnosis inside them) and the mean **delay** from an interval's
  start to that diagnosis.

**Selection.** Every combination of ``GRID`` is run on every trial once.
Parameters for a set of trials are chosen as: among the combinations whose
worst undisturbed trial of the set has a false-alarm fraction below
``MAX_TUNING_ALARM`` (1 %, half the 2 % target, as a margin for unseen
trials), the one with the highest mean recall on the set's magnet trials,
ties going to the shorter delay. Each trial is reported with the parameters
chosen on the *other* twelve, so no number in the table was tuned on the
trial it describes. The parameters chosen on all trials are the ones
``configs/datasets/broad.yaml`` ships; the script says if they differ.

Each trial is also mapped (heading only) ungated, gated with its held-out
parameters and with the oracle (the label), and the heading RMSE against
the optical truth is reported.

Writes ``broad.md`` (the tables), ``broad_grid.csv`` (every combination on
every trial) and ``broad_trials.csv``.
"""

from __future__ import annotations

import argparse
import copy
import itertools
import logging
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from scripts.bench.common import csv_text, publish
from slam.config import PipelineConfig, load_config
from slam.results.atomic import write_text
from slam.readers.datasets import data_root
from slam.readers.read import read_recording
from slam.graph.measurements import FACTOR_DOFS
from slam.pipeline.folder import MappingPipeline
from slam.recording import Recording
from validation.config import parse_sections
from validation.validator import run_validation

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
MAGNET_TRIALS = ("28", "29", "32", "33")
UNDISTURBED_TRIALS = ("01", "02", "04", "06", "08", "10", "15")
MAX_TUNING_ALARM = 0.01
GRID = {
    "boundary": (0.2, 0.3, 0.5),             # rad/s
    "window_s": (1.0, 2.0),
    "threshold": (5, 10),                    # steps at 10 Hz
    "tolerance_uT": (4.0, 6.0, 8.0),
    "tolerance_dip_deg": (4.0, 8.0, 12.0),
    "hold_s": (0.0, 0.5, 1.0),
}
RELATION = "yaw_compass_gyro"
MODES = ("off", "on", "oracle")


@dataclass(frozen=True)
class Params:
    boundary: float
    window_s: float
    threshold: int
    tolerance_uT: float
    tolerance_dip_deg: float
    hold_s: float

    def apply(self, validation: dict) -> dict:
        """A copy of the ``validation`` section with these parameters."""
        v = copy.deepcopy(validation)
        v["mode"] = "on"
        for rel in v["observers"]["relations"]:
            if rel["name"] == RELATION:
                rel.update(boundary=self.boundary, window_s=self.window_s, threshold=self.threshold,
                           max_counter=self.threshold + 20)
        mag = v["observers"].setdefault("magnetometer", {})
        mag.update(tolerance_T=self.tolerance_uT * 1e-6, tolerance_dip_deg=self.tolerance_dip_deg, hold_s=self.hold_s)
        return v

    def matches(self, validation: dict) -> bool:
        """Whether a ``validation`` section already holds these parameters."""
        return self.apply(validation) == {**copy.deepcopy(validation), "mode": "on"}

    def text(self) -> str:
        return (f"b = {self.boundary:g} rad/s, w = {self.window_s:g} s, th = {self.threshold} "
                f"(max_counter {self.threshold + 20}), dB = {self.tolerance_uT:g} uT, "
                f"ddip = {self.tolerance_dip_deg:g} deg, hold = {self.hold_s:g} s")


@dataclass
class TrialResult:
    trial: str
    kind: str
    params: str
    duration_s: float
    labelled_s: float
    alarm_fraction: float
    false_alarm_fraction: float
    precision: float | None
    recall: float | None
    detected: int
    intervals: int
    delay_s: float | None
    yaw_rmse_off_deg: float = float("nan")
    yaw_rmse_on_deg: float = float("nan")
    yaw_rmse_oracle_deg: float = float("nan")


def kind_of(trial: str) -> str:
    number = trial[:2]
    if number in MAGNET_TRIALS:
        return "magnet"
    if number in UNDISTURBED_TRIALS:
        return "undisturbed"
    return "other disturbance"


def validate(rec: Recording, validation: dict, gating: dict, keyframe_period_s: float) -> dict:
    """Validation alone (no graph), on the keyframe times ``gslam map`` uses."""
    vcfg, gcfg = parse_sections(validation, gating)
    keyframes = np.arange(rec.gyro.t[0], rec.gyro.t[-1], keyframe_period_s)
    return run_validation(rec, None, keyframes, vcfg, gcfg, FACTOR_DOFS, rec.faults, rec.magnetic_reference).metrics


# Worker state for the grid: each process reads the trials once.
_WORKER: dict = {}


def _init_worker(paths: list[Path], config_path: Path) -> None:
    logging.getLogger("slam").setLevel(logging.WARNING)
    config = load_config(config_path)
    _WORKER.update(config=config, recordings={p.stem: read_recording(p, config.input) for p in paths})


def _grid_row(params: Params) -> dict[str, dict]:
    config = _WORKER["config"]
    validation = params.apply(config.validation)
    out = {}
    for name, rec in _WORKER["recordings"].items():
        m = validate(rec, validation, config.gating, config.keyframes.period_s)
        out[name] = {
            "alarm_fraction": m["alarm_fraction"],
            "false_alarm_fraction": m["false_alarm_fraction"],
            "precision": m["isolation_precision"],
            "recall": m["isolation_recall"],
            "detected": m["faults_detected"],
            "delay_s": m["detection_delay_s"].get("IMU_YAW"),
        }
    return out


def run_grid(paths: list[Path], config_path: Path, workers: int) -> dict[Params, dict[str, dict]]:
    """Every combination of GRID on every trial."""
    combos = [Params(*values) for values in itertools.product(*GRID.values())]
    t0 = time.perf_counter()
    if workers > 1:
        import multiprocessing

        ctx = multiprocessing.get_context("spawn")
        with ctx.Pool(workers, initializer=_init_worker, initargs=(paths, config_path)) as pool:
            rows = pool.map(_grid_row, combos, chunksize=max(1, len(combos) // (8 * workers)))
    else:
        _init_worker(paths, config_path)
        rows = [_grid_row(c) for c in combos]
    log.info("grid: %d combinations x %d trials in %.0f s", len(combos), len(paths), time.perf_counter() - t0)
    return dict(zip(combos, rows))


def choose(grid: dict[Params, dict[str, dict]], trials: list[str]) -> Params:
    """The selection rule of the module docstring on ``trials``."""
    undisturbed = [n for n in trials if kind_of(n) == "undisturbed"]
    magnets = [n for n in trials if kind_of(n) == "magnet"]
    best, best_key = None, None
    for params, row in grid.items():
        if max(row[n]["false_alarm_fraction"] for n in undisturbed) >= MAX_TUNING_ALARM:
            continue
        recall = float(np.mean([row[n]["recall"] or 0.0 for n in magnets]))
        delays = [row[n]["delay_s"] for n in magnets if row[n]["delay_s"] is not None]
        key = (round(recall, 6), -float(np.mean(delays)) if delays else -np.inf)
        if best_key is None or key > best_key:
            best, best_key = params, key
    if best is None:
        raise SystemExit(f"bench broad: no combination keeps the undisturbed trials below {MAX_TUNING_ALARM:.0%}")
    return best


def heading_rmse(path: Path, rec: Recording, config: PipelineConfig, mode: str, params: Params, out: Path) -> float:
    validation = params.apply(config.validation)
    validation["mode"] = mode
    cfg = config.model_copy(update={"validation": validation, "output": config.output.model_copy(update={"plots": False})})
    result = MappingPipeline(path, cfg, out / f"{path.stem}_{mode}", recording=rec).run()
    return result.metrics["yaw_rmse_deg"]


def _f(v, fmt: str) -> str:
    return "–" if v is None else format(v, fmt)


def markdown(rows: list[TrialResult], shipped: Params, choices: dict[str, Params]) -> str:
    lines = [
        "| trial | kind | labelled s | alarm fraction | false alarms | precision | recall | detected | delay s "
        "| heading RMSE ungated / gated / oracle (deg) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.trial[:2]} {r.trial[3:].replace('_', ' ')} | {r.kind} | {r.labelled_s:.1f} | {r.alarm_fraction:.3f} "
            f"| {r.false_alarm_fraction:.3f} | {_f(r.precision, '.2f')} | {_f(r.recall, '.2f')} "
            f"| {r.detected}/{r.intervals} | {_f(r.delay_s, '.2f')} "
            f"| {r.yaw_rmse_off_deg:.1f} / {r.yaw_rmse_on_deg:.1f} / {r.yaw_rmse_oracle_deg:.1f} |"
        )
    undisturbed = [r for r in rows if r.kind == "undisturbed"]
    magnets = [r for r in rows if r.kind == "magnet"]
    distinct = sorted({p.text() for p in choices.values()})
    lines += [
        "",
        f"Undisturbed trials: false-alarm fraction max {max(r.false_alarm_fraction for r in undisturbed):.3f}, "
        f"median {np.median([r.false_alarm_fraction for r in undisturbed]):.3f}. "
        f"Magnet trials: recall {', '.join(f'{r.trial[:2]} {r.recall:.2f}' for r in magnets)}; "
        f"intervals detected {sum(r.detected for r in magnets)}/{sum(r.intervals for r in magnets)}.",
        "",
        f"Parameters chosen on all trials (shipped): {shipped.text()}.",
        f"Held-out choices ({len(distinct)} distinct): " + "; ".join(distinct) + ".",
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None, help="folder of BROAD .mat trials (default: DATA_ROOT/broad)")
    ap.add_argument("--config", type=Path, default=ROOT / "configs/datasets/broad.yaml")
    ap.add_argument("--workers", type=int, default=2, help="processes for the grid")
    ap.add_argument("--out", type=Path, default=Path("runs/bench_broad"))
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for name in ("slam", "validation"):
        logging.getLogger(name).setLevel(logging.WARNING)

    folder = args.data or data_root() / "broad"
    paths = sorted(folder.glob("*.mat"))
    kinds = {kind_of(p.stem) for p in paths}
    if not {"undisturbed", "magnet"} <= kinds:
        print(f"bench broad: need undisturbed and magnet BROAD trials (*.mat) in {folder}; set GSLAM_DATA or pass --data",
              file=sys.stderr)
        return 2
    config = load_config(args.config)
    args.out.mkdir(parents=True, exist_ok=True)
    names = [p.stem for p in paths]

    grid = run_grid(paths, args.config, args.workers)
    write_text(args.out / "broad_grid.csv", csv_text([
        {**asdict(params), "trial": name, **metrics} for params, row in grid.items() for name, metrics in row.items()
    ]))
    shipped = choose(grid, names)
    if not shipped.matches(config.validation):
        log.warning("%s: its observer parameters differ from the ones chosen on all trials: %s", args.config, shipped.text())
    choices = {name: choose(grid, [n for n in names if n != name]) for name in names}

    rows = []
    for path in paths:
        rec = read_recording(path, config.input)
        params = choices[path.stem]
        m = grid[params][path.stem]
        intervals = rec.faults.get("IMU_YAW", [])
        row = TrialResult(
            trial=path.stem, kind=kind_of(path.stem), params=params.text(), duration_s=round(rec.duration, 1),
            labelled_s=round(sum(b - a for a, b in intervals), 1), alarm_fraction=m["alarm_fraction"],
            false_alarm_fraction=m["false_alarm_fraction"], precision=m["precision"], recall=m["recall"],
            detected=m["detected"], intervals=len(intervals), delay_s=m["delay_s"],
        )
        for mode in MODES:
            setattr(row, f"yaw_rmse_{mode}_deg", round(heading_rmse(path, rec, config, mode, params, args.out), 2))
        rows.append(row)
        log.info("%s", row)

    write_text(args.out / "broad_trials.csv", csv_text([asdict(r) for r in rows]))
    text = markdown(rows, shipped, choices)
    write_text(args.out / "broad.md", text)
    publish("broad", "BROAD: the compass observers, thresholds chosen leave-one-trial-out", text, argv)
    print(text)
    return 0

