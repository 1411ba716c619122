"""Real recordings with injected faults: gated against ungated, every robust
kernel and the oracles, per log and fault kind.

    python -m scripts.bench real_faults [--data DIR] [--logs intel freiburg-079 aces csail husky broad-02 ...]
                                        [--faults cut2 cut3 cut4 slip yaw_slip gyro_bias dipole]
                                        [--placements 0.2 0.5 0.8 [--placements ...]] [--length 0.1]
                                        [--config configs/datasets/carmen.yaml] [--out runs/bench_real_faults] [--jobs N]
    python -m scripts.bench real_faults --rows RUN1/real_faults.csv [RUN2/real_faults.csv ...]

The CARMEN report logs (intel, freiburg-079, aces, csail: the config was
chosen on the others, docs/loops.md; ``--tuning`` runs those, fhw,
freiburg-101, seattle and belgioioso, into ``real_faults_tuning.md``) are
mapped as recorded, then once per
fault kind with that fault injected by ``gslam inject`` at each placement
(a share of the log's duration), each stretch ``--length`` of it long.
Each fault kind is mapped once per set of placements (``--placements``,
given once per set; by default :data:`PLACEMENT_SETS`, three sets); a row
then holds the median over the sets of each method's figure (and of each
ratio), the counts summed, and says how many sets: which loops the maps
find swings a single placement's ATE by several times, so one set can rank
two methods by chance. The worst set is reported beside the median
(``gated / best kernel, worst set``). The faults:

* ``cut2``, ``cut3``, ``cut4``: the laser cut to 2, 3 and 4 m (a laser that
  sees too little, the paper's open yard);
* ``slip``: the wheels slip, the odometry's distance increments times 1.5;
* ``yaw_slip``: the odometry's turns times 1.5.

The Husky bag (``husky``, ``configs/datasets/husky.yaml``: wheel odometry,
gyro, the IMU's heading and GPS, no laser) takes the faults its sensors can
have, each in three stretches of 20 s after the first 180 s its config
learnt its observers from and after the AHRS heading's own drift
(``HUSKY_STRETCHES_S``): ``slip`` and ``yaw_slip`` as above, ``gyro_bias``
(2 deg/s) and ``dipole`` (a magnet beside the path, seen by the IMU's
heading); no GPS multipath, as its config keeps the fixes out of the graph.
Every method there also meets the bag's own fault, the AHRS heading that
walks off at 195 s and stays off (``judges.REAL_FAULT_FROM_S``). It has no ground truth: its ATE is
against its own GPS fixes as recorded (``judges.ate_vs_gps``), there is no
tight oracle, and its alarm fraction as recorded is the share of judged
steps blaming a sensor that the judges do not accuse
(``husky_faults.judged_alarms``; the bag's compass does go wrong by itself).
With faults injected, a blame of that compass after it goes wrong counts
as right in the step precision against the stretches (:func:`own_faults`);
the alarm fraction there is every step's, the bag's own fault's included.

The undisturbed BROAD trials (``broad-NN``, ``configs/datasets/broad.yaml``:
a hand-held IMU's gyro and magnetometer, the heading only; ``BROAD_REPORT``,
``BROAD_TUNING`` with ``--tuning``) take ``gyro_bias`` (2 deg/s) and
``dipole`` (a magnet 2 m from the IMU, in its magnetometer's field) at the
placements above; they are compared by the heading RMSE (deg) against the
optical heading.

Each injected log is mapped ungated, gated (offline, the paper's centred
windows), gated causally, with each robust kernel of ``configs/variants.yaml``
and with three oracles, each knowing something of the truth:

* the *tight oracle* excludes every measurement off the ground truth by
  more than ``validation.oracle_k_sigma`` of its sigmas, injected or not
  (none on the Husky bag, which has no ground truth);
* the *interval oracle* gates each component over its true intervals: the
  labels ``gslam inject`` wrote (a cut scan that leaves a direction free,
  a slip beyond 12 % of the motion, a compass off by 5 deg) and, with
  ground truth, wherever the scan matcher's motion over 1 s is off it
  (``evaluation.sm_output_faults``, ``slam.gating.truth``);
* the *stretch oracle* gates the injected sensor over each injected
  stretch whole (:func:`stretch_faults`), right or wrong.

Reported per log and fault kind: each method's ATE (m) against the log's
corrected poses; gated against the best kernel and against the interval
and stretch oracles; per step, the precision and recall of the gated blame
against the labels (the steps an injected fault harmed), and its precision
against the injected stretches whole (:func:`validation.metrics.stretch_precision`:
a sensor blamed within its injected stretch is right, whether or not that
step was harmed); the injected stretches found (one of the injected sensor's components blamed,
in the diagnosis the gating acts on, somewhere within the stretch) and the labelled intervals
detected (every interval of the interval oracle's labels, the scan
matcher's own errors of the log as recorded among them, each within its
span); the mean detection delay (s). For the logs as recorded:
the gated ATE against the ungated and the alarm fraction. A summary line
holds each figure against its target. Writes ``real_faults.md`` (and
``docs/results/real_faults.md``) and ``real_faults.csv``.

A whole run takes hours: runs of some logs each (``--logs``, each with its
own ``--out``, side by side or on several machines) make one page with
``--rows`` and their CSVs, which names each run's logs and commit. So do
runs of further placement sets of the same logs: each maps the logs as
recorded again, and those rows count once where both runs measured the same.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
import statistics
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from scripts.bench.common import (
    HUSKY_BAG, KERNELS, ROWS_MEASURED, carmen_log, commit, csv_text, include_in_readme, publish, quiet_logging, table,
)
from scripts.bench.husky_faults import judged_alarms
from scripts.bench.judges import REAL_FAULT_FROM_S, ate_vs_gps, gps_wanders
from slam.commands.compare import load_variants
from slam.commands.inject import inject
from slam.commands.inject.spec import parse_fault
from slam.config import load_config
from slam.errors import GslamError
from slam.pipeline.folder import MappingPipeline
from slam.readers.datasets import data_root
from slam.readers.read import read_recording
from slam.results.atomic import write_text
from validation.metrics import stretch_precision, stretches_found

log = logging.getLogger(__name__)
ROOT = Path(__file__).resolve().parents[2]
REPORT_LOGS = ("intel", "freiburg-079", "aces", "csail")
TUNING_LOGS = ("fhw", "freiburg-101", "seattle", "belgioioso")
FAULTS = {  # kind: the gslam inject spec after "KIND@T0:T1,"
    "cut2": "laser_cut@{a:.1f}:{b:.1f},range_m=2",
    "cut3": "laser_cut@{a:.1f}:{b:.1f},range_m=3",
    "cut4": "laser_cut@{a:.1f}:{b:.1f},range_m=4",
    "slip": "slip@{a:.1f}:{b:.1f},scale=1.5",
    "yaw_slip": "slip@{a:.1f}:{b:.1f},scale=1.0,yaw_scale=1.5",
}
HUSKY = "husky"
HUSKY_CONFIG = ROOT / "configs/datasets/husky.yaml"
HUSKY_FAULTS = {
    "slip": FAULTS["slip"],
    "yaw_slip": FAULTS["yaw_slip"],
    "gyro_bias": "gyro_bias@{a:.1f}:{b:.1f},bias_deg_s=2",
    "dipole": "dipole@{a:.1f}:{b:.1f},target=heading",
}
# No multipath: the Husky config keeps the GPS out of the graph (its fixes
# are the reference), so fixes 8 m off change no map (measured: every
# method's ATE as on the bag as recorded).
HUSKY_STRETCHES_S = ((230.0, 250.0), (290.0, 310.0), (350.0, 370.0))
"""After the 180 s the Husky config learnt from and the AHRS heading's own
drift (195-215 s, ``judges.REAL_DRIFT``), before the bag's end (395 s)."""
BROAD_CONFIG = ROOT / "configs/datasets/broad.yaml"
BROAD_FAULTS = {
    "gyro_bias": HUSKY_FAULTS["gyro_bias"],
    "dipole": "dipole@{a:.1f}:{b:.1f},target=magnetometer",
}
BROAD_REPORT = ("broad-02", "broad-06", "broad-08", "broad-15")
BROAD_TUNING = ("broad-01", "broad-04", "broad-10")
"""The undisturbed BROAD trials (a hand-held IMU in a motion-capture room),
split as slow and fast motions on both sides. Its config's observers were
chosen on all thirteen trials, the disturbed ones among them
(``scripts/bench/broad.py``), so no BROAD row is unseen by it; the faults
injected here are not the trials' own."""
GATED = ("gated", "gated_causal")
ORACLES = ("oracle", "interval_oracle", "stretch_oracle")
METHODS = ("ungated", *GATED, *KERNELS, *ORACLES)
STRETCH_ORACLE = ["validation.mode=interval_oracle", "evaluation.sm_output_faults=false"]
"""The stretch oracle: the interval oracle on the injected stretches alone
(:func:`stretch_faults`), not on the labels or the scan matcher's errors."""
PLACEMENT_SETS = ((0.2, 0.5, 0.8), (0.1, 0.4, 0.7), (0.15, 0.45, 0.75))
"""The default sets of placements: shares of a log's duration where its
three stretches start, each a tenth of it long (the last ending before
the log does, or it is not injected)."""

TARGETS = {"gated / best kernel, worst": 1.0, "gated / best kernel, worst set": 1.0,
           "gated / best kernel, geometric mean": 0.6,
           "gated / interval oracle, geometric mean": 1.5, "gated / stretch oracle, geometric mean": 1.5,
           "injected stretches found": 0.8, "labelled intervals detected": 0.8, "step precision": 0.7,
           "step precision, injected stretches": 0.7,
           "uninjected gated / ungated, worst": 1.05, "uninjected alarm fraction, worst": 0.02}


def fault_specs(kind: str, duration: float, placements: list[float], length: float,
                faults: dict[str, str] = FAULTS) -> list[str]:
    """The ``--fault`` specs of ``kind`` (in ``faults``) at each placement (share of ``duration``)."""
    return [faults[kind].format(a=p * duration, b=(p + length) * duration) for p in placements]


def stretch_faults(specs: list[str]) -> dict[str, list[tuple[float, float]]]:
    """The components each injected fault makes wrong, over its whole
    stretch: a cut laser every scan-matching modality, a slip the odometry's
    distance (or turn, with ``yaw_scale``), a gyro bias the gyro, a dipole
    the compass."""
    out: dict[str, list[tuple[float, float]]] = {}
    for spec in specs:
        f = parse_fault(spec)
        if f.kind == "laser_cut":
            comps = ["SM_DIST", "SM_LAT", "SM_YAW"]
        elif f.kind == "slip":
            comps = (["ODO_DIST"] if f.scale != 1.0 else []) + (["ODO_YAW"] if f.yaw_scale != 1.0 else [])
        else:
            comps = {"gyro_bias": ["IMU_GYRO"], "dipole": ["IMU_YAW"], "multipath": ["GPS"]}[f.kind]
        for c in comps:
            out.setdefault(c, []).append((f.start_s, f.end_s))
    return out


def injected_stretches(specs: list[str]) -> list[tuple[list[str], float, float]]:
    """Each injected fault's components (:func:`stretch_faults`) and its
    stretch, whole: the faults a user injected, counted one by one."""
    out = []
    for spec in specs:
        f = parse_fault(spec)
        out.append((list(stretch_faults([spec])), f.start_s, f.end_s))
    return out


def own_faults(name: str) -> list[tuple[list[str], float, float]]:
    """The faults log ``name`` has by itself, as stretches: a blame of them
    is right (the Husky bag's AHRS heading, off from ``REAL_FAULT_FROM_S``
    to its end), though they are not counted among the injected ones found."""
    return [(["IMU_YAW"], REAL_FAULT_FROM_S, math.inf)] if name == HUSKY else []


def is_broad(name: str) -> bool:
    return name.startswith("broad-")


def log_faults(name: str) -> dict[str, str]:
    """The fault kinds log ``name`` can take: its sensors'."""
    return HUSKY_FAULTS if name == HUSKY else BROAD_FAULTS if is_broad(name) else FAULTS


def log_config(name: str, args: argparse.Namespace) -> Path:
    return HUSKY_CONFIG if name == HUSKY else BROAD_CONFIG if is_broad(name) else args.config


def log_source(name: str, data: Path) -> Path:
    """The recording of log ``name`` under the data folder ``data``."""
    if name == HUSKY:
        return data / HUSKY_BAG
    if is_broad(name):
        found = sorted((data / "broad").glob(f"{name.removeprefix('broad-')}_*.mat"))
        return found[0] if found else data / "broad" / f"{name.removeprefix('broad-')}_*.mat"
    return carmen_log(data, name)


def error(row: dict) -> float:
    """The figure a row's methods are compared by: a BROAD trial's heading
    RMSE (deg; it estimates the heading only), else the ATE (m)."""
    return row["yaw_rmse_deg"] if is_broad(row["log"]) else row["ate_m"]


def injected_specs(name: str, kind: str, duration: float, args: argparse.Namespace) -> list[str]:
    if name == HUSKY:
        return [HUSKY_FAULTS[kind].format(a=a, b=b) for a, b in HUSKY_STRETCHES_S]
    return fault_specs(kind, duration, args.placements, args.length, log_faults(name))


def run_method(path: Path, config: Path, overrides: list[str], out: Path, recording=None, frontend=None):
    """One mapping in-process; returns (result, pipeline) so the front-end can be reused."""
    cfg = load_config(config, [*overrides, "output.plots=false", "output.grid=false", "output.mcap=false"])
    pipe = MappingPipeline(path, cfg, out, recording=recording, frontend=frontend)
    return pipe.run(), pipe


def method_row(name: str, fault: str, method: str, result, seconds: float, gps=None,
               stretches: list[tuple[list[str], float, float]] | None = None) -> dict:
    """One method's figures; ``gps``: the reference of a log without
    ground truth (the fixes as recorded); ``stretches``: the injected ones
    (:func:`injected_stretches`), counted where the validator found them."""
    m = result.metrics
    ate_m = ate_vs_gps(result.trajectory, gps)[0] if gps is not None else m["ate_rmse_m"]
    row = {"log": name, "fault": fault, "method": method, "ate_m": round(ate_m, 3),
           "seconds": round(seconds, 1)}
    if is_broad(name):
        row["yaw_rmse_deg"] = round(m["yaw_rmse_deg"], 3)
    if m.get("validation_steps"):
        delays = [d for d in (m.get("detection_delay_s") or {}).values() if d is not None]
        row.update(alarm_fraction=m.get("alarm_fraction"), precision=m.get("isolation_precision"),
                   recall=m.get("isolation_recall"), detected=m.get("faults_detected"),
                   missed=m.get("faults_missed"),
                   delay_s=round(sum(delays) / len(delays), 2) if delays else None)
    v = result.validation
    if stretches and v is not None and getattr(v, "step_t", None) is not None:
        right, blamed = stretch_precision(v.step_t, v.results, v.actions, [*stretches, *own_faults(name)], v.sensors)
        row.update(stretches_found=stretches_found(v.step_t, v.results, v.actions, stretches, v.sensors),
                   stretches=len(stretches), stretch_precision=round(right / blamed, 4) if blamed else None)
    return row


def run_unit(name: str, source: Path, kind: str | None, args: argparse.Namespace,
             placements: list[float] | None = None) -> list[dict]:
    """The rows of one log as recorded (``kind`` None: ungated and gated) or
    with one fault kind injected at ``placements`` (default
    ``args.placements``; every method, the scan matching shared)."""
    if placements is not None:
        args = argparse.Namespace(**{**vars(args), "placements": placements})
    variants = load_variants(ROOT / "configs/variants.yaml")
    config = log_config(name, args)
    base = load_config(config)
    recorded = read_recording(source, base.input)
    gps = recorded.gps if recorded.groundtruth is None else None
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if kind is None:
            for method in ("ungated", "gated"):
                t0 = time.perf_counter()
                result, _ = run_method(source, config, variants[method], tmp / method, recording=recorded)
                rows.append(method_row(name, "none", method, result, time.perf_counter() - t0, gps))
            if gps is not None:  # no truth of the recording's own faults: the judges'
                rows[-1]["alarm_fraction"] = round(judged_alarms(result.validation, [], gps_wanders(recorded))[0], 4)
            return rows
        specs = injected_specs(name, kind, recorded.duration, args)
        try:
            run = inject(source, specs, tmp / "injected", config=base.input).run_dir
        except GslamError as e:  # a fault the log cannot take (a slip without raw odometry)
            log.info("%s %s: not injected (%s)", name, kind, e)
            return rows
        rec, frontend = read_recording(run, base.input), None
        variants["stretch_oracle"] = STRETCH_ORACLE
        for method in METHODS:
            if method == "oracle" and rec.groundtruth is None:
                continue  # the tight oracle needs ground truth
            t0 = time.perf_counter()
            given = dataclasses.replace(rec, faults=stretch_faults(specs)) if method == "stretch_oracle" else rec
            result, pipe = run_method(run, config, variants[method], tmp / method,
                                      recording=given, frontend=frontend)
            frontend = pipe.frontend
            rows.append(method_row(name, kind, method, result, time.perf_counter() - t0, gps,
                                   injected_stretches(specs) if method in GATED else None))
    if name != HUSKY:  # the Husky bag's stretches are its own
        for r in rows:
            r["placements"] = " ".join(f"{p:g}" for p in args.placements)
    return rows


SUMMED = ("detected", "missed", "stretches_found", "stretches")
"""Counts a row over several placement sets sums; its other figures are medians."""


def over_placements(rows: list[dict]) -> list[dict]:
    """One row per log, fault and method: the rows of several placement sets
    (``placements``) as one, each figure the median over the sets (of those
    that have it) and each count of :data:`SUMMED` their sum, with the
    number of sets in ``sets``; the errors of each set are kept as
    ``set_errors`` so that ratios are taken set by set."""
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault((r["log"], r["fault"], r["method"]), []).append(r)
    out = []
    for group in groups.values():
        if len(group) == 1:
            out.append({**group[0], "sets": 1, "set_errors": {group[0].get("placements"): error(group[0])}})
            continue
        row = {"log": group[0]["log"], "fault": group[0]["fault"], "method": group[0]["method"], "sets": len(group),
               "set_errors": {r.get("placements"): error(r) for r in group}}
        for key in sorted({k for r in group for k in r} - {"log", "fault", "method", "placements", "commit"}):
            values = [r[key] for r in group if isinstance(r.get(key), (int, float))]
            if not values:
                continue
            row[key] = sum(values) if key in SUMMED else statistics.median(values)
        out.append(row)
    return out


def ratio(a: dict, b: dict) -> float:
    """``a``'s error over ``b``'s: of a single run, or the median over the
    placement sets both were mapped at of the ratio set by set."""
    sets = [k for k in a.get("set_errors", {}) if k in b.get("set_errors", {})]
    if len(sets) <= 1:
        return error(a) / error(b)
    return statistics.median([a["set_errors"][k] / b["set_errors"][k] for k in sets])


def read_rows(path: Path) -> list[dict]:
    """The rows of a CSV this bench wrote (:func:`csv_text`), each value as
    it was: an integer, a number, text, or None where the cell is empty."""
    import csv

    def value(text: str):
        if text == "":
            return None
        for kind in (int, float):
            try:
                return kind(text)
            except ValueError:
                pass
        return text

    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = [{k: value(v) for k, v in row.items()} for row in csv.DictReader(f)]
    except (OSError, UnicodeDecodeError, csv.Error) as e:
        raise SystemExit(f"{path}: cannot read the rows ({e})")
    missing = {"log", "fault", "method", "ate_m"} - set(rows[0] if rows else ())
    if not rows or missing:
        raise SystemExit(f"{path}: expected the rows of real_faults (columns log, fault, method, ate_m, ...)")
    return rows


def median(xs: list[float]) -> float | None:
    """The middle value of ``xs`` (the upper one of an even count); None when empty."""
    return sorted(xs)[len(xs) // 2] if xs else None


def _f(x, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def vs_best_kernel_sets(m: dict[str, dict]) -> list[float]:
    """Gated against the best kernel of each placement set that has every
    kernel (of the single run where there are no sets)."""
    g = m["gated"]
    sets = [s for s in g.get("set_errors", {}) if all(s in m[k].get("set_errors", {}) for k in KERNELS)]
    if len(sets) <= 1:
        return [error(g) / min(error(m[k]) for k in KERNELS)]
    return [g["set_errors"][s] / min(m[k]["set_errors"][s] for k in KERNELS) for s in sets]


def vs_best_kernel(m: dict[str, dict]) -> tuple[str, float]:
    """The robust kernel of the lowest (median) error among methods ``m``,
    and gated against the best kernel: of a single run, or the median over
    the placement sets of gated against that set's best kernel."""
    return min(KERNELS, key=lambda k: error(m[k])), statistics.median(vs_best_kernel_sets(m))


def figures(by: dict[tuple[str, str], dict[str, dict]]) -> dict[str, float | None]:
    """The figures held against ``TARGETS``, over the (log, fault) groups ``by``."""
    vs_kernel, vs_oracle, vs_stretch, precision, clean_ratio, clean_alarm = [], [], [], [], [], []
    in_stretch, worst_set = [], []
    detected = total = found = injected = 0
    for (_, fault), m in by.items():
        g = m["gated"]
        if fault == "none":
            clean_ratio.append(ratio(g, m["ungated"]))
            clean_alarm.append(g.get("alarm_fraction") or 0.0)
            continue
        vs_kernel.append(vs_best_kernel(m)[1])
        worst_set.append(max(vs_best_kernel_sets(m)))
        vs_oracle.append(ratio(g, m["interval_oracle"]))
        if "stretch_oracle" in m:
            vs_stretch.append(ratio(g, m["stretch_oracle"]))
        if g.get("detected") is not None:
            detected += g["detected"]
            total += g["detected"] + g["missed"]
        if g.get("stretches"):
            found += g["stretches_found"]
            injected += g["stretches"]
        if g.get("precision") is not None:
            precision.append(g["precision"])
        if g.get("stretch_precision") is not None:
            in_stretch.append(g["stretch_precision"])
    gmean = (lambda xs: math.exp(sum(map(math.log, xs)) / len(xs)) if xs else None)
    return {"gated / best kernel, worst": max(vs_kernel, default=None),
            "gated / best kernel, worst set": max(worst_set, default=None),
            "gated / best kernel, geometric mean": gmean(vs_kernel),
            "gated / interval oracle, geometric mean": gmean(vs_oracle),
            "gated / stretch oracle, geometric mean": gmean(vs_stretch),
            "injected stretches found": found / injected if injected else None,
            "labelled intervals detected": detected / total if total else None,
            "step precision": median(precision),
            "step precision, injected stretches": median(in_stretch),
            "uninjected gated / ungated, worst": max(clean_ratio, default=None),
            "uninjected alarm fraction, worst": max(clean_alarm, default=None)}


AT_LEAST = ("injected stretches found", "labelled intervals detected", "step precision",
            "step precision, injected stretches")
"""The figures whose target is a floor; every other one's is a ceiling."""


def _met(key: str, value: float | None) -> str:
    if value is None:
        return "–"
    return "met" if (value >= TARGETS[key] if key in AT_LEAST else value <= TARGETS[key]) else "missed"


def summarise(rows: list[dict]) -> tuple[str, dict]:
    """The per (log, fault) table and the figures held against ``TARGETS``:
    over every row, and over the CARMEN logs and the Husky bag apart where
    both are there."""
    by = {}
    for r in over_placements(rows):
        by.setdefault((r["log"], r["fault"]), {})[r["method"]] = r
    sets = max((r["sets"] for m in by.values() for r in m.values()), default=1)
    out = []
    for (name, fault), m in by.items():
        g = m["gated"]
        if fault == "none":
            out.append([name, "none (as recorded)", _f(error(m["ungated"]), 3), _f(error(g), 3),
                        "–", "–", "–", "–", "–", _f(ratio(g, m["ungated"])), "–", "–",
                        _f(g.get("alarm_fraction"), 3), "–", "–", "–", "–", "–", "–"])
            continue
        best_kernel, vs_kernel = vs_best_kernel(m)
        tight, stretch = m.get("oracle"), m.get("stretch_oracle")
        fault_sets = fault if g["sets"] == 1 else f"{fault} ({g['sets']} sets)"
        out.append([name, fault_sets, _f(error(m["ungated"]), 3), _f(error(g), 3), _f(error(m["gated_causal"]), 3),
                    f"{best_kernel} {_f(error(m[best_kernel]), 3)}", _f(error(tight), 3) if tight else "–",
                    _f(error(m["interval_oracle"]), 3), _f(error(stretch), 3) if stretch else "–",
                    _f(vs_kernel), _f(ratio(g, m["interval_oracle"])),
                    _f(ratio(g, stretch)) if stretch else "–",
                    _f(g.get("alarm_fraction"), 3), _f(g.get("precision")), _f(g.get("recall")),
                    _f(g.get("stretch_precision")),
                    f"{g['stretches_found']}/{g['stretches']}" if g.get("stretches") else "–",
                    f"{g['detected']}/{g['detected'] + g['missed']}" if g.get("detected") is not None else "–",
                    _f(g.get("delay_s"), 1)])
    every = figures(by)
    kind = (lambda name: "Husky" if name == HUSKY else "BROAD" if is_broad(name) else "CARMEN")
    groups = {g: {k: v for k, v in by.items() if kind(k[0]) == g} for g in ("CARMEN", "Husky", "BROAD")}
    groups = {g: figures(part) for g, part in groups.items() if part}
    groups = groups if len(groups) > 1 else {}
    header = ["log", "fault", "ungated", "gated", "gated causal", "best kernel", "tight oracle", "interval oracle",
              "stretch oracle", "gated / best kernel", "gated / interval oracle", "gated / stretch oracle",
              "alarm fraction", "step precision", "step recall", "step precision, injected stretches",
              "injected stretches found", "labelled intervals detected", "delay s"]
    text = "ATE RMSE in m against the corrected poses"
    text += (" (the Husky bag's against its own GPS fixes, as recorded)" if any(k[0] == HUSKY for k in by) else "")
    if any(is_broad(k[0]) for k in by):
        text += "; the BROAD trials' heading RMSE in deg against the optical heading (a hand-held IMU: the heading is all it estimates)"
    if sets > 1:
        text += (f"; with faults injected at up to {sets} sets of placements, each figure the median over the sets "
                 "(a ratio, the median of the ratios set by set; gated against the best kernel, against each set's "
                 "best), the counts summed")
    text += ".\n\n" + table(header, out)
    digits = (lambda k: 3 if "alarm" in k else 2)  # an alarm fraction near its 2 % target reads as itself
    summary = [[k, _f(v, digits(k)), *(_f(f[k], digits(k)) for f in groups.values()),
                ("≥ " if k in AT_LEAST else "≤ ") + f"{TARGETS[k]:g}", _met(k, v)]
               for k, v in every.items()]
    text += ("\nAgainst the targets (step precision: the median over log and fault kind; against the labels, "
             "the steps an injected fault harmed, and against the injected stretches, whole):\n\n")
    text += table(["figure", "measured" + (", every log" if groups else ""), *groups, "target", ""], summary)
    return text, every


def measured_where(rows: list[dict]) -> str:
    """Where rows read back were measured: `` at commit C``, or with rows
    of several commits, each commit and its logs."""
    at: dict[str, list[str]] = {}
    for r in rows:
        if r.get("commit"):
            logs = at.setdefault(str(r["commit"]), [])
            if r["log"] not in logs:
                logs.append(r["log"])
    if len(at) <= 1:
        return "".join(f" at commit {c}" for c in at)
    return (" at commits " + "; ".join(f"{c} ({', '.join(logs)})" for c, logs in sorted(at.items()))
            + ", one run per commit, their rows put together,")


def read_back(paths: list[Path]) -> tuple[list[dict], str]:
    """The rows of the CSVs earlier runs wrote, put together, and the
    sentence that says where they were measured (each run's logs and
    commit): runs of some logs each, on one machine or several, make one
    page. A row two runs both mapped (a log as recorded, which every run
    maps once) is kept once where its figures are the same in both, the
    time and commit aside: the same measurement made again. With other
    figures, or a file given twice, it is refused: it would count twice."""
    if len(set(paths)) < len(paths):
        twice = next(p for p in paths if paths.count(p) > 1)
        raise SystemExit(f"{twice}: given twice; expected each run's rows once")
    runs = [(path, read_rows(path)) for path in paths]
    if len(runs) == 1:
        path, rows = runs[0]
        return rows, (f"{ROWS_MEASURED} an earlier run of this bench{measured_where(rows)}"
                      f" and read back from its `{path.name}`; this command summarised them.")
    seen: dict[tuple, tuple[Path, dict]] = {}
    kept, again = [], 0
    for path, rows in runs:
        for r in rows:
            key = (r["log"], r["fault"], r["method"], str(r.get("placements")))
            if key in seen:
                first_path, first = seen[key]
                if _figures(first) != _figures(r):
                    raise SystemExit(f"{path}: {' '.join(key[:3])} at placements {key[3]} is also in {first_path} "
                                     "with other figures; expected each row in one run")
                again += 1
                continue
            seen[key] = path, r
            kept.append(r)
    each = "; ".join(f"{', '.join(dict.fromkeys(r['log'] for r in rows))}{measured_where(rows)} (`{path}`)"
                     for path, rows in runs)
    repeated = (f" {again} rows mapped again by a later run, with the same figures (the time aside), are counted "
                "once." if again else "")
    return kept, (f"{ROWS_MEASURED} {len(runs)} earlier runs of this bench, their rows put together: {each}; "
                  f"this command summarised them.{repeated}")


def _figures(row: dict) -> dict:
    """A row's figures: all but how long it took and the commit it ran at."""
    return {k: v for k, v in row.items() if k not in ("seconds", "commit")}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None, help="the data folder (default: GSLAM_DATA or ../shared/data)")
    ap.add_argument("--logs", nargs="+", default=None,
                    help="default: the CARMEN report logs, the Husky bag and the BROAD report trials "
                         "(the CARMEN and BROAD tuning ones with --tuning)")
    ap.add_argument("--tuning", action="store_true",
                    help="the tuning logs, written to real_faults_tuning.md: what the config was chosen on")
    kinds = list(dict.fromkeys([*FAULTS, *HUSKY_FAULTS, *BROAD_FAULTS]))
    ap.add_argument("--faults", nargs="+", default=kinds, choices=kinds,
                    help="each log takes the kinds its sensors can have (default: all)")
    ap.add_argument("--placements", nargs="+", type=float, action="append", default=None,
                    help="shares of the log's duration where the stretches start, one set each time it is "
                         "given; each fault kind is mapped once per set (default: "
                         + "; ".join(" ".join(f"{p:g}" for p in ps) for ps in PLACEMENT_SETS) + ")")
    ap.add_argument("--length", type=float, default=0.1, help="each stretch, as a share of the log's duration")
    ap.add_argument("--config", type=Path, default=ROOT / "configs/datasets/carmen.yaml")
    ap.add_argument("--out", type=Path, default=ROOT / "runs/bench_real_faults")
    ap.add_argument("--jobs", type=int, default=1, help="processes, one log and fault kind each (default 1)")
    ap.add_argument("--rows", type=Path, nargs="+", default=None,
                    help="summarise the rows earlier runs wrote (their real_faults.csv or real_faults_tuning.csv, "
                         "e.g. one run per log) rather than mapping again; the page says so")
    args = ap.parse_args(argv)
    placement_sets = args.placements or [list(ps) for ps in PLACEMENT_SETS]
    args.placements = placement_sets[0]
    if args.logs is None:
        args.logs = list((*TUNING_LOGS, *BROAD_TUNING) if args.tuning else (*REPORT_LOGS, HUSKY, *BROAD_REPORT))
    quiet_logging()
    t_all = time.perf_counter()
    if args.rows is not None:
        rows, read_from = read_back(args.rows)
    else:
        data = args.data or data_root()
        units = [(name, log_source(name, data), kind, placements)
                 for name in args.logs for kind in (None, *(k for k in args.faults if k in log_faults(name)))
                 for placements in (placement_sets[:1] if kind is None or name == HUSKY else placement_sets)]
        with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            futures = [pool.submit(run_unit, name, source, kind, args, placements)
                       for name, source, kind, placements in units]
            rows = []
            for (name, _, kind, _), future in zip(units, futures):
                rows += future.result()
                log.info("%s %s: done, %.0f s in", name, kind or "as recorded", time.perf_counter() - t_all)
        measured_at = commit()
        rows = [{**r, "commit": measured_at} for r in rows]
    text, _ = summarise(rows)
    if args.rows is not None:
        text = read_from + "\n\n" + text
    page = "real_faults_tuning" if args.tuning else "real_faults"
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / f"{page}.md", text)
    write_text(args.out / f"{page}.csv", csv_text(rows, sorted({k for r in rows for k in r})))
    title = "Real recordings with injected faults: gated against the kernels and the oracles"
    publish(page, title + (", on the tuning logs" if args.tuning else ""), text, argv, bench="real_faults")
    if not args.tuning:
        include_in_readme("real_faults")
    print(text)
    print(f"{time.perf_counter() - t_all:.0f} s")
    return 0
