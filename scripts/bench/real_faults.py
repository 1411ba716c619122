"""Real recordings with injected faults: gated against ungated, every robust
kernel and the oracles, per log and fault kind.

    python -m scripts.bench real_faults [--data DIR] [--logs intel freiburg-079 aces csail]
                                        [--faults cut2 cut3 cut4 slip yaw_slip]
                                        [--placements 0.2 0.5 0.8] [--length 0.1]
                                        [--config configs/datasets/carmen.yaml] [--out runs/bench_real_faults] [--jobs N]

The CARMEN report logs (intel, freiburg-079, aces, csail: the config was
chosen on the others, docs/loops.md; ``--tuning`` runs those, fhw,
freiburg-101, seattle and belgioioso, into ``real_faults_tuning.md``) are
mapped as recorded, then once per
fault kind with that fault injected by ``gslam inject`` at each placement
(a share of the log's duration), each stretch ``--length`` of it long:

* ``cut2``, ``cut3``, ``cut4``: the laser cut to 2, 3 and 4 m (a laser that
  sees too little, the paper's open yard);
* ``slip``: the wheels slip, the odometry's distance increments times 1.5;
* ``yaw_slip``: the odometry's turns times 1.5.

Each injected log is mapped ungated, gated (offline, the paper's centred
windows), gated causally, with each robust kernel of ``configs/variants.yaml``
and with the two oracles: the tight oracle gates the steps whose sensor
output is labelled wrong, the interval oracle the whole stretches.

Reported per log and fault kind: each method's ATE (m) against the log's
corrected poses; gated against the best kernel and against the interval
oracle; per step, the precision and recall of the gated blame; the fault
stretches detected; the mean detection delay (s). For the logs as recorded:
the gated ATE against the ungated and the alarm fraction. A summary line
holds each figure against its target. Writes ``real_faults.md`` (and
``docs/results/real_faults.md``) and ``real_faults.csv``.
"""

from __future__ import annotations

import argparse
import logging
import math
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from scripts.bench.common import KERNELS, csv_text, include_in_readme, publish, quiet_logging, table
from slam.commands.compare import load_variants
from slam.commands.inject import inject
from slam.config import load_config
from slam.errors import GslamError
from slam.pipeline.folder import MappingPipeline
from slam.readers.datasets import data_root
from slam.readers.read import read_recording
from slam.results.atomic import write_text

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
GATED = ("gated", "gated_causal")
ORACLES = ("oracle", "interval_oracle")
METHODS = ("ungated", *GATED, *KERNELS, *ORACLES)
TARGETS = {"gated / best kernel, worst": 1.0, "gated / best kernel, geometric mean": 0.6,
           "gated / interval oracle, geometric mean": 1.5, "stretches detected": 0.8, "step precision": 0.7,
           "uninjected gated / ungated, worst": 1.05, "uninjected alarm fraction, worst": 0.02}


def fault_specs(kind: str, duration: float, placements: list[float], length: float) -> list[str]:
    """The ``--fault`` specs of ``kind`` at each placement (share of ``duration``)."""
    return [FAULTS[kind].format(a=p * duration, b=(p + length) * duration) for p in placements]


def run_method(path: Path, config: Path, overrides: list[str], out: Path, recording=None, frontend=None):
    """One mapping in-process; returns (result, pipeline) so the front-end can be reused."""
    cfg = load_config(config, [*overrides, "output.plots=false", "output.grid=false", "output.mcap=false"])
    pipe = MappingPipeline(path, cfg, out, recording=recording, frontend=frontend)
    return pipe.run(), pipe


def method_row(name: str, fault: str, method: str, result, seconds: float) -> dict:
    m = result.metrics
    row = {"log": name, "fault": fault, "method": method, "ate_m": round(m["ate_rmse_m"], 3),
           "seconds": round(seconds, 1)}
    if m.get("validation_steps"):
        delays = [d for d in (m.get("detection_delay_s") or {}).values() if d is not None]
        row.update(alarm_fraction=m.get("alarm_fraction"), precision=m.get("isolation_precision"),
                   recall=m.get("isolation_recall"), detected=m.get("faults_detected"),
                   missed=m.get("faults_missed"),
                   delay_s=round(sum(delays) / len(delays), 2) if delays else None)
    return row


def run_unit(name: str, source: Path, kind: str | None, args: argparse.Namespace) -> list[dict]:
    """The rows of one log as recorded (``kind`` None: ungated and gated) or
    with one fault kind injected (every method, the scan matching shared)."""
    variants = load_variants(ROOT / "configs/variants.yaml")
    base = load_config(args.config)
    rows: list[dict] = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if kind is None:
            for method in ("ungated", "gated"):
                t0 = time.perf_counter()
                result, _ = run_method(source, args.config, variants[method], tmp / method)
                rows.append(method_row(name, "none", method, result, time.perf_counter() - t0))
            return rows
        duration = read_recording(source, base.input).duration
        specs = fault_specs(kind, duration, args.placements, args.length)
        try:
            run = inject(source, specs, tmp / "injected", config=base.input).run_dir
        except GslamError as e:  # a fault the log cannot take (a slip without raw odometry)
            log.info("%s %s: not injected (%s)", name, kind, e)
            return rows
        rec, frontend = read_recording(run, base.input), None
        for method in METHODS:
            t0 = time.perf_counter()
            result, pipe = run_method(run, args.config, variants[method], tmp / method,
                                      recording=rec, frontend=frontend)
            frontend = pipe.frontend
            rows.append(method_row(name, kind, method, result, time.perf_counter() - t0))
    return rows


def _f(x, digits: int = 2) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def summarise(rows: list[dict]) -> tuple[str, dict]:
    """The per (log, fault) table and the figures held against ``TARGETS``."""
    by = {}
    for r in rows:
        by.setdefault((r["log"], r["fault"]), {})[r["method"]] = r
    out, vs_kernel, vs_oracle, detected, total, tp_prec = [], [], [], 0, 0, []
    clean_ratio, clean_alarm = [], []
    for (name, fault), m in by.items():
        if fault == "none":
            ratio = m["gated"]["ate_m"] / m["ungated"]["ate_m"]
            clean_ratio.append(ratio)
            clean_alarm.append(m["gated"].get("alarm_fraction") or 0.0)
            out.append([name, "none (as recorded)", _f(m["ungated"]["ate_m"], 3), _f(m["gated"]["ate_m"], 3),
                        "–", "–", "–", "–", _f(ratio), "–", _f(m["gated"].get("alarm_fraction"), 3), "–", "–", "–",
                        "–"])
            continue
        best_kernel = min(KERNELS, key=lambda k: m[k]["ate_m"])
        g = m["gated"]
        r_kernel = g["ate_m"] / m[best_kernel]["ate_m"]
        r_oracle = g["ate_m"] / m["interval_oracle"]["ate_m"]
        vs_kernel.append(r_kernel)
        vs_oracle.append(r_oracle)
        if g.get("detected") is not None:
            detected += g["detected"]
            total += g["detected"] + g["missed"]
        if g.get("precision") is not None:
            tp_prec.append(g["precision"])
        out.append([name, fault, _f(m["ungated"]["ate_m"], 3), _f(g["ate_m"], 3), _f(m["gated_causal"]["ate_m"], 3),
                    f"{best_kernel} {_f(m[best_kernel]['ate_m'], 3)}", _f(m["oracle"]["ate_m"], 3),
                    _f(m["interval_oracle"]["ate_m"], 3), _f(r_kernel), _f(r_oracle),
                    _f(g.get("alarm_fraction"), 3), _f(g.get("precision")), _f(g.get("recall")),
                    f"{g['detected']}/{g['detected'] + g['missed']}" if g.get("detected") is not None else "–",
                    _f(g.get("delay_s"), 1)])
    gmean = (lambda xs: math.exp(sum(map(math.log, xs)) / len(xs)) if xs else None)
    figures = {"gated / best kernel, worst": max(vs_kernel, default=None),
               "gated / best kernel, geometric mean": gmean(vs_kernel),
               "gated / interval oracle, geometric mean": gmean(vs_oracle),
               "stretches detected": detected / total if total else None,
               "step precision": sorted(tp_prec)[len(tp_prec) // 2] if tp_prec else None,
               "uninjected gated / ungated, worst": max(clean_ratio, default=None),
               "uninjected alarm fraction, worst": max(clean_alarm, default=None)}
    header = ["log", "fault", "ungated", "gated", "gated causal", "best kernel", "tight oracle", "interval oracle",
              "gated / best kernel", "gated / interval oracle", "alarm fraction", "step precision", "step recall",
              "stretches detected", "delay s"]
    text = "ATE RMSE in m against the corrected poses.\n\n" + table(header, out)
    summary = [[k, _f(v), ("≤ " if "detected" not in k and "precision" not in k else "≥ ") + f"{TARGETS[k]:g}",
                "–" if v is None else ("met" if (v >= TARGETS[k] if ("detected" in k or "precision" in k)
                                                 else v <= TARGETS[k]) else "missed")]
               for k, v in figures.items()]
    text += "\nAgainst the targets (step precision: the median over log and fault kind):\n\n"
    text += table(["figure", "measured", "target", ""], summary)
    return text, figures


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None, help="the data folder (default: GSLAM_DATA or ../shared/data)")
    ap.add_argument("--logs", nargs="+", default=None, help="default: the report logs (the tuning logs with --tuning)")
    ap.add_argument("--tuning", action="store_true",
                    help="the tuning logs, written to real_faults_tuning.md: what the config was chosen on")
    ap.add_argument("--faults", nargs="+", default=list(FAULTS), choices=list(FAULTS))
    ap.add_argument("--placements", nargs="+", type=float, default=[0.2, 0.5, 0.8])
    ap.add_argument("--length", type=float, default=0.1, help="each stretch, as a share of the log's duration")
    ap.add_argument("--config", type=Path, default=ROOT / "configs/datasets/carmen.yaml")
    ap.add_argument("--out", type=Path, default=ROOT / "runs/bench_real_faults")
    ap.add_argument("--jobs", type=int, default=1, help="processes, one log and fault kind each (default 1)")
    args = ap.parse_args(argv)
    if args.logs is None:
        args.logs = list(TUNING_LOGS if args.tuning else REPORT_LOGS)
    quiet_logging()
    root = (args.data or data_root()) / "carmen"
    t_all = time.perf_counter()
    units = [(name, root / f"{name}-corrected.log.gz", kind) for name in args.logs for kind in (None, *args.faults)]
    with ProcessPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        futures = [pool.submit(run_unit, name, source, kind, args) for name, source, kind in units]
        rows = []
        for (name, _, kind), future in zip(units, futures):
            rows += future.result()
            log.info("%s %s: done, %.0f s in", name, kind or "as recorded", time.perf_counter() - t_all)
    text, _ = summarise(rows)
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
