"""BROAD, leave-one-trial-out with ``gslam calibrate``: every trial mapped
with observers learnt from the other twelve.

    python -m scripts.bench broad_loto [--data DIR] [--config configs/datasets/broad.yaml]
                                       [--false-alarm 0.005] [--out runs/bench_broad_loto]

For each observer set of ``SETS`` (the shipped trend relation,
magnetometer check and field-gyro check; the same without the field-gyro
check; the same with an offset or a cusum relation of compass against gyro
beside them) and each of the 13 shared trials, the
observers are calibrated (:func:`slam.commands.calibrate.learn`: whole runs, robust
statistics, ``--false-alarm`` of the steps) on the *other twelve* trials,
magnet trials included, and the held-out trial is mapped with them, gating
on. Reported per trial, against the reader's label (the magnetometer's
heading more than 20 deg off the optical heading; :mod:`slam.readers.broad`):
the alarm fraction, the false-alarm fraction and the per-step recall of
``metrics.json``; and the recall against the label of the magnetometer as
recorded, 12 ms late (``mag_lag_s`` 0), which the lag's own error in fast
turns lengthens. Nothing is chosen by hand: the figures are those of the
calibration.

Writes ``broad_loto.md`` (the tables) and ``broad_loto.csv``.
"""

from __future__ import annotations

import argparse
import io
import logging
import sys
import tempfile
import time
from pathlib import Path


from scripts.bench.common import base_config, csv_text, publish, quiet_logging
from slam.commands.calibrate import learn, load_run
from slam.config import load_config, validation_sections
from slam.results.atomic import write_text
from slam.readers.broad import MAG_LAG_S, read_broad
from slam.readers.datasets import data_root
from slam.pipeline.folder import run_map
from validation.metrics import validation_metrics

log = logging.getLogger(__name__)
ROOT = Path(__file__).resolve().parents[2]

COMPASS_GYRO = {"stream_a": "gyro_yaw", "stream_b": "compass_yaw", "window_s": 2.0, "sigma_floor": 0.05}
SETS = {
    "trend": ([], ()),
    "trend without field-gyro": ([], ("field_gyro",)),
    "trend + offset": ([{"name": "yaw_compass_gyro_off", "kind": "offset", **COMPASS_GYRO, "level_window_s": 30.0,
                         "threshold": 5, "max_counter": 25}], ()),
    "trend + cusum": ([{"name": "yaw_compass_gyro_cusum", "kind": "cusum", **COMPASS_GYRO, "threshold": 2,
                        "max_counter": 22}], ()),
}
"""Per set: relations added to the config's, each with the model line it
needs (the compass against the gyro), and the config's checks turned off."""


def kind_of(name: str) -> str:
    number = int(name[:2])
    if number <= 21:
        return "undisturbed"
    if "stationary_magnet" in name:
        return "stationary magnet"
    if "attached_magnet" in name:
        return "attached magnet"
    return "motion"


def run_set(name: str, added: list[dict], off: tuple[str, ...], trials: list[Path], config_path: Path,
            false_alarm: float, folder: Path) -> list[dict]:
    base = base_config(config_path, added, folder, off)
    config = load_config(base)
    vcfg, _ = validation_sections(config)
    loaded = {t: load_run(t, config, vcfg, None) for t in trials}
    rows = []
    for held in trials:
        t0 = time.perf_counter()
        res = learn([loaded[t] for t in trials if t != held], config, false_alarm)
        learnt = folder / f"{held.stem}_{len(rows)}.yaml"
        learnt.write_text(res.text)
        cfg = load_config(learnt, ["validation.mode=on", "output.plots=false"])
        mapped = run_map(held, cfg, folder / f"map_{held.stem}", force=True)
        m, v = mapped.metrics, mapped.validation
        unlagged = validation_metrics(v.step_t, v.results, v.actions, {"IMU_YAW": _faults(held, 0.0)},
                                      validation_sections(cfg)[0].model.sensors)
        rel = {r: c.relation for r, c in res.choices.items() if c is not None}
        rows.append({
            "set": name, "trial": held.stem, "kind": kind_of(held.stem),
            "labelled_s": sum(b - a for a, b in _faults(held)),
            "alarm_fraction": m["alarm_fraction"], "false_alarm_fraction": m["false_alarm_fraction"],
            "recall": m["isolation_recall"], "precision": m["isolation_precision"],
            "labelled_s_unlagged": sum(b - a for a, b in _faults(held, 0.0)),
            "recall_unlagged": unlagged["isolation_recall"],
            "parameters": "; ".join(_short(r) for r in rel.values()),
            "seconds": round(time.perf_counter() - t0, 1),
        })
        log.info("%s %s: %s", name, held.stem, rows[-1])
    return rows


_LABELS: dict[tuple[Path, float], list] = {}


def _faults(path: Path, mag_lag_s: float = MAG_LAG_S) -> list:
    """The reader's IMU_YAW label, with the magnetometer's lag removed
    (as the map reads it) or, with ``mag_lag_s`` 0, as recorded."""
    if (path, mag_lag_s) not in _LABELS:
        _LABELS[path, mag_lag_s] = read_broad(path, mag_lag_s=mag_lag_s).faults.get("IMU_YAW", [])
    return _LABELS[path, mag_lag_s]


def _short(rel) -> str:
    if rel.kind == "trend":
        return f"{rel.name}: b {rel.boundary:g}, w {rel.window_s:g}, th {rel.threshold}"
    return f"{rel.name}: sigma {rel.sigma_floor:.3g} x {rel.k_sigma:g}, w {rel.window_s:g}, th {rel.threshold}"


def _fmt(x) -> str:
    return "–" if x is None else f"{x:.3f}"


def tables(rows: list[dict]) -> str:
    out = io.StringIO()
    sets = list(dict.fromkeys(r["set"] for r in rows))
    out.write("| trial | labelled s (uncorrected) | " + " | ".join(f"{s}: alarms / recall (uncorrected)" for s in sets)
              + " |\n")
    out.write("|---|---|" + "---|" * len(sets) + "\n")
    for trial in dict.fromkeys(r["trial"] for r in rows):
        cells = []
        for s in sets:
            r = next(x for x in rows if x["set"] == s and x["trial"] == trial)
            cells.append(f"{_fmt(r['alarm_fraction'])} / {_fmt(r['recall'])} ({_fmt(r['recall_unlagged'])})")
        r = next(x for x in rows if x["trial"] == trial)
        out.write(f"| {trial} | {r['labelled_s']:.1f} ({r['labelled_s_unlagged']:.1f}) | " + " | ".join(cells) + " |\n")
    out.write("\n| set | worst undisturbed alarm fraction | attached-magnet recall (min) | "
              "stationary-magnet recall (min) | stationary-magnet recall, uncorrected label (min) |\n|---|---|---|---|---|\n")
    for s in sets:
        mine = [r for r in rows if r["set"] == s]
        und = max(r["alarm_fraction"] for r in mine if r["kind"] == "undisturbed")
        att = min(r["recall"] or 0.0 for r in mine if r["kind"] == "attached magnet")
        sta = min(r["recall"] or 0.0 for r in mine if r["kind"] == "stationary magnet")
        sta0 = min(r["recall_unlagged"] or 0.0 for r in mine if r["kind"] == "stationary magnet")
        out.write(f"| {s} | {und:.3f} | {att:.2f} | {sta:.2f} | {sta0:.2f} |\n")
    return out.getvalue()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--config", type=Path, default=ROOT / "configs/datasets/broad.yaml")
    ap.add_argument("--false-alarm", type=float, default=0.005)
    ap.add_argument("--only", default=None, help="comma-separated observer sets")
    ap.add_argument("--out", type=Path, default=ROOT / "runs/bench_broad_loto")
    args = ap.parse_args(argv)
    quiet_logging()
    trials = sorted((args.data or data_root()).joinpath("broad").glob("*.mat"))
    if not trials:
        sys.exit("no BROAD trials found")
    args.out.mkdir(parents=True, exist_ok=True)
    wanted = args.only.split(",") if args.only else list(SETS)
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for name in wanted:
            rows += run_set(name, *SETS[name], trials, args.config, args.false_alarm, Path(tmp))
    text = tables(rows)
    write_text(args.out / "broad_loto.md", text)
    publish("broad_loto", "BROAD: every trial mapped with observers calibrated on the other twelve", text, argv)
    write_text(args.out / "broad_loto.csv", csv_text(rows))
    print(text)
    print(f"{time.perf_counter() - t0:.0f} s")
    return 0

