"""CARMEN with the laser cut to 4 m over stretches (``gslam inject``):
gated against ungated, the robust kernels and two oracles.

    python -m scripts.bench carmen_cuts [--data DIR] [--logs intel freiburg-079 aces]
                                        [--config configs/datasets/carmen.yaml] [--out runs/bench_carmen_cuts]

1. The observers of ``--config`` are calibrated (:func:`slam.commands.calibrate.calibrate`,
   whole runs, robust statistics) on the four tuning logs (fhw,
   freiburg-101, seattle, belgioioso), untouched. The scan check's
   thresholds are physical (the simulator's fault definition); on the
   tuning logs the share of their scans it flags is reported.
2. Each report log gets three laser cuts (``laser_cut@T0:T1,range_m=4``),
   each a tenth of its duration, starting at 20, 50 and 80 % of it. The
   injector labels scan matching (SM_DIST, SM_LAT, SM_YAW) wrong on each
   cut scan that keeps too few returns or leaves a direction unconstrained.
3. The log is mapped uncut and ungated (what removing the cuts would give);
   the injected log ungated, with each robust kernel of
   ``configs/variants.yaml`` (huber, cauchy, dcs, gnc_tls, gnc_gm), with
   two oracles, and gated: with the config's hand-set relation observers,
   with the calibrated ones, with the scan check alone and with the
   calibrated observers plus the scan check. The *interval oracle* gates
   scan matching on the pipeline's true intervals (the labels, plus where
   KISS-ICP's motion is off the reference, ``slam.gating.truth``); the *label
   oracle* excludes exactly the scan-matching motions that start or end at
   a labelled scan.

Reported: the ATE RMSE against the corrected poses (m) and its ratio to
the injected log's ungated one, the mean translation error of the motion
between consecutive scans inside the cut stretches (cm); for the gated maps the alarm fraction, the
*labelled-scan recall* (labelled scans and modalities whose scan-matching
motion into the scan was gated), the share of unlabelled scans gated, and
the pipeline's per-step SM recall over its true intervals. Writes
``carmen_cuts.md`` and ``carmen_cuts.csv``.
"""

from __future__ import annotations

import argparse
import dataclasses
import io
import logging
import tempfile
import time
from pathlib import Path

import numpy as np

from scripts.bench.common import KERNELS, carmen_log, csv_text, publish, quiet_logging
from slam.commands.calibrate import calibrate
from slam.commands.compare import load_variants
from slam.config import load_config, validation_sections
from slam.frontend.kiss import scan_quality
from slam.commands.inject import inject
from slam.results.atomic import write_text
from slam.readers.datasets import data_root
from slam.readers.read import read_recording
from slam.recording import interpolate_poses, relative_poses
from slam.pipeline.folder import MappingPipeline
from validation.observers.checks import ScanDegeneracyCheck, unary_checks

log = logging.getLogger(__name__)
ROOT = Path(__file__).resolve().parents[2]
TUNING = ("fhw", "freiburg-101", "seattle", "belgioioso")
STARTS = (0.2, 0.5, 0.8)
LENGTH = 0.1
RANGE_M = 4.0
SM = ("SM_DIST", "SM_LAT", "SM_YAW")  # the scan-matching factor's x, y, yaw
GATED = ["validation.mode=on", "validation.observers.scan.enabled=false"]
CHECK = ["validation.mode=on", "validation.observers.scan.enabled=true"]


def cut_spans(path: Path, config) -> list[tuple[float, float]]:
    """The cut stretches (s): a tenth of the log from each of ``STARTS``."""
    d = read_recording(path, config.input).duration
    return [(round(s * d, 1), round((s + LENGTH) * d, 1)) for s in STARTS]


def cuts(spans: list[tuple[float, float]]) -> list[str]:
    return [f"laser_cut@{a:.1f}:{b:.1f},range_m={RANGE_M:g}" for a, b in spans]


def labelled_scans(t: np.ndarray, faults: dict) -> np.ndarray:
    """(n, 3) bool: scan i inside a labelled interval of SM_DIST, SM_LAT, SM_YAW."""
    out = np.zeros((len(t), len(SM)), dtype=bool)
    for j, comp in enumerate(SM):
        for a, b in faults.get(comp, []):
            out[:, j] |= (t >= a - 1e-6) & (t <= b + 1e-6)
    return out


def label_oracle_faults(t: np.ndarray, labels: np.ndarray) -> dict:
    """Intervals from the scan before to the scan after each labelled scan:
    the oracle then excludes both scan-matching motions touching it."""
    out = {}
    for j, comp in enumerate(SM):
        idx = np.flatnonzero(labels[:, j])
        out[comp] = [(float(t[max(i - 1, 0)]), float(t[min(i + 1, len(t) - 1)])) for i in idx]
    return out


def scan_figures(result, labels: np.ndarray) -> dict:
    """Labelled-scan recall and the share of unlabelled scans gated, from the
    scan-matching weights of the keyframes (one per scan on these logs)."""
    v = result.validation
    if v is None:
        return {}
    kt, st = result.trajectory.t, result.recording.scans.t
    k = np.clip(np.searchsorted(kt, st - 1e-6), 0, len(kt) - 1)
    on_scan = np.abs(kt[k] - st) < 1e-6
    gated = (v.weights["scan_matching"][k] > 1.0) & on_scan[:, None]
    clean = ~labels.any(axis=1) & on_scan
    n_lab = int(labels.sum())
    return {"scan_recall": round(float((gated & labels).sum()) / n_lab, 3) if n_lab else None,
            "labelled": n_lab, "unlabelled_gated": round(float(gated[clean].any(axis=1).mean()), 4)}


def cut_step_error(result, spans: list[tuple[float, float]]) -> float:
    """Mean translation error (m) of the estimate's motion between
    consecutive keyframes inside the cut stretches ``spans`` (s), against
    the reference: the local effect of the cuts, which the ATE of a
    drifting chain hides."""
    est, ref = result.trajectory, result.recording.groundtruth
    t = est.t
    inside = np.zeros(len(t), dtype=bool)
    for a, b in spans:
        inside |= (t >= a) & (t <= b)
    pair = np.flatnonzero(inside[:-1] & inside[1:])
    e = np.column_stack([est.x, est.y, est.yaw])
    g = interpolate_poses(ref, t)
    d = relative_poses(e[pair], e[pair + 1]) - relative_poses(g[pair], g[pair + 1])
    return float(np.mean(np.hypot(d[:, 0], d[:, 1])))


def row(name: str, method: str, result, labels: np.ndarray, spans, ungated: float | None, seconds: float) -> dict:
    m = result.metrics
    ate = m["ate_rmse_m"]
    out = {"log": name, "method": method, "ate_m": round(ate, 3),
           "ate_ratio": round(ate / ungated, 3) if ungated else None,
           "cut_step_error_cm": round(100 * cut_step_error(result, spans), 2), "seconds": round(seconds, 1)}
    if m.get("validation_steps"):
        out.update(alarm_fraction=m["alarm_fraction"], recall=m["isolation_recall"],
                   false_alarm_fraction=m["false_alarm_fraction"],
                   detected=m["faults_detected"], missed=m["faults_missed"])
        out.update(scan_figures(result, labels))
    return out


def check_flag_rates(paths: list[Path], config) -> dict[str, float]:
    """Share of the scans of ``paths`` (uncut) the scan check flags, per modality."""
    cfg = load_config(config, CHECK)
    checks = [c for c in unary_checks(validation_sections(cfg)[0].observers) if isinstance(c, ScanDegeneracyCheck)]
    flagged, total = np.zeros(len(checks)), 0
    for p in paths:
        rec = read_recording(p, cfg.input)
        q = scan_quality(rec.scans, cfg.frontend)
        flagged += [c.flags(q).sum() for c in checks]
        total += len(q.t)
    return {c.component: round(float(f) / total, 4) for c, f in zip(checks, flagged)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--logs", nargs="+", default=["intel", "freiburg-079", "aces"])
    ap.add_argument("--config", type=Path, default=ROOT / "configs/datasets/carmen.yaml")
    ap.add_argument("--out", type=Path, default=ROOT / "runs/bench_carmen_cuts")
    args = ap.parse_args(argv)
    quiet_logging()
    root = args.data or data_root()
    args.out.mkdir(parents=True, exist_ok=True)
    variants = load_variants(ROOT / "configs/variants.yaml")
    base = load_config(args.config)
    rows = []
    t_all = time.perf_counter()
    tuning = [carmen_log(root, n) for n in TUNING]
    rates = check_flag_rates(tuning, args.config)
    log.info("scan check on the tuning logs' scans (uncut): %s", rates)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        calibrated = calibrate(tuning, args.config, tmp / "cal.yaml").out
        for name in args.logs:
            source = carmen_log(root, name)
            spans = cut_spans(source, base)
            run = inject(source, cuts(spans), tmp / f"{name}_cut", config=base.input).run_dir
            rec = read_recording(run, base.input)
            labels = labelled_scans(rec.scans.t, rec.faults)
            oracle_rec = dataclasses.replace(rec, faults=label_oracle_faults(rec.scans.t, labels))
            methods = {"uncut, ungated": (source, args.config, variants["ungated"], None),
                       "ungated": (run, args.config, variants["ungated"], rec)}
            methods.update({k: (run, args.config, variants[k], rec) for k in KERNELS})
            methods["interval oracle"] = (run, args.config, variants["interval_oracle"], rec)
            methods["label oracle"] = (run, args.config, [*variants["interval_oracle"], "evaluation.sm_output_faults=false"],
                                       oracle_rec)
            methods["gated (hand-set)"] = (run, args.config, GATED, rec)
            methods["gated (calibrated)"] = (run, calibrated, GATED, rec)
            methods["gated (scan check)"] = (run, args.config, [*CHECK, "validation.observers.relations=[]"], rec)
            methods["gated (calibrated + scan check)"] = (run, calibrated, CHECK, rec)
            ungated, frontend = None, None
            for method, (path, cfg_path, overrides, recording) in methods.items():
                t0 = time.perf_counter()
                cfg = load_config(cfg_path, [*overrides, "output.plots=false"])
                pipe = MappingPipeline(path, cfg, tmp / f"{name}_{len(rows)}", recording=recording,
                                       frontend=frontend if recording is not None else None)
                result = pipe.run()
                if recording is not None:
                    frontend = pipe.frontend
                rows.append(row(name, method, result, labels, spans, ungated, time.perf_counter() - t0))
                if method == "ungated":
                    ungated = result.metrics["ate_rmse_m"]
                    rows[-1]["ate_ratio"] = 1.0
                log.info("%s", rows[-1])
    text = table(rows, rates)
    write_text(args.out / "carmen_cuts.md", text)
    publish("carmen_cuts", "CARMEN with the laser cut to 4 m: gated against ungated, the kernels and the oracles", text, argv)
    write_text(args.out / "carmen_cuts.csv", csv_text(rows, sorted({k for r in rows for k in r})))
    print(text)
    print(f"{time.perf_counter() - t_all:.0f} s")
    return 0


def _f(x, digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def table(rows: list[dict], rates: dict[str, float]) -> str:
    out = io.StringIO()
    out.write("Scan check on the tuning logs' own scans (uncut), share flagged: "
              + ", ".join(f"{c} {v:.4f}" for c, v in rates.items()) + "\n\n")
    out.write("| log | method | ATE m | ATE / ungated | step error in the cuts, cm | alarm fraction "
              "| labelled-scan recall | unlabelled scans gated | SM recall per step | intervals detected |\n")
    out.write("|---|---|---|---|---|---|---|---|---|---|\n")
    for r in rows:
        det = f"{r['detected']}/{r['detected'] + r['missed']}" if r.get("detected") is not None else "–"
        out.write(f"| {r['log']} | {r['method']} | {r['ate_m']:.2f} | {_f(r.get('ate_ratio'), 2)} | "
                  f"{r['cut_step_error_cm']:.1f} | "
                  f"{_f(r.get('alarm_fraction'))} | {_f(r.get('scan_recall'), 2)} | {_f(r.get('unlabelled_gated'))} | "
                  f"{_f(r.get('recall'), 2)} | {det} |\n")
    return out.getvalue()

