"""CARMEN with the laser cut to 4 m over stretches (``gslam inject``):
gated against ungated and the robust kernels.

    python scripts/bench_carmen_cuts.py [--data DIR] [--logs intel freiburg-079 aces]
                                        [--config configs/datasets/carmen.yaml] [--out runs/bench_carmen_cuts]

1. The observers of ``--config`` are calibrated (:func:`slam.calibrate.calibrate`,
   whole runs, robust statistics) on the four tuning logs (fhw,
   freiburg-101, seattle, belgioioso), untouched.
2. Each report log gets three laser cuts (``laser_cut@T0:T1,range_m=4``),
   each a tenth of its duration, starting at 20, 50 and 80 % of it. The
   injector labels scan matching (SM_DIST, SM_LAT, SM_YAW) wrong where a cut
   scan keeps too few returns or leaves a direction unconstrained.
3. The injected log is mapped ungated, with each robust kernel of
   ``configs/variants.yaml`` (huber, cauchy, dcs, gnc_tls, gnc_gm), gated
   with the config's hand-set observers and gated with the calibrated ones.

Reported: the ATE RMSE against the corrected poses (m), and for the gated
maps the alarm fraction, the per-step recall of the scan-matching
components, the labelled intervals detected, and the false-alarm fraction.
Writes ``carmen_cuts.md`` and ``carmen_cuts.csv``.
"""

from __future__ import annotations

import argparse
import csv
import io
import logging
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from slam.calibrate import calibrate  # noqa: E402
from slam.compare import load_variants  # noqa: E402
from slam.config import load_config  # noqa: E402
from slam.inject import inject  # noqa: E402
from slam.io.atomic import write_text  # noqa: E402
from slam.io.datasets import data_root  # noqa: E402
from slam.io.readers import read_recording  # noqa: E402
from slam.pipeline import run_map  # noqa: E402

log = logging.getLogger("bench_carmen_cuts")
ROOT = Path(__file__).resolve().parents[1]
TUNING = ("fhw", "freiburg-101", "seattle", "belgioioso")
KERNELS = ("huber", "cauchy", "dcs", "gnc_tls", "gnc_gm")
STARTS = (0.2, 0.5, 0.8)
LENGTH = 0.1
RANGE_M = 4.0


def cuts(path: Path, config) -> list[str]:
    rec = read_recording(path, config.input)
    d = rec.duration
    return [f"laser_cut@{s * d:.1f}:{(s + LENGTH) * d:.1f},range_m={RANGE_M:g}" for s in STARTS]


def row(name: str, method: str, m: dict, seconds: float) -> dict:
    out = {"log": name, "method": method, "ate_m": round(m["ate_rmse_m"], 3), "seconds": round(seconds, 1)}
    if m.get("validation_steps"):
        out.update(alarm_fraction=m["alarm_fraction"], recall=m["isolation_recall"],
                   precision=m["isolation_precision"], false_alarm_fraction=m["false_alarm_fraction"],
                   detected=m["faults_detected"], missed=m["faults_missed"])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--logs", nargs="+", default=["intel", "freiburg-079", "aces"])
    ap.add_argument("--config", type=Path, default=ROOT / "configs/datasets/carmen.yaml")
    ap.add_argument("--out", type=Path, default=ROOT / "runs/bench_carmen_cuts")
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for noisy in ("slam", "validation"):
        logging.getLogger(noisy).setLevel(logging.ERROR)
    root = (args.data or data_root()) / "carmen"
    args.out.mkdir(parents=True, exist_ok=True)
    variants = load_variants(ROOT / "configs/variants.yaml")
    base = load_config(args.config)
    rows = []
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        calibrated = calibrate([root / f"{n}-corrected.log.gz" for n in TUNING], args.config, tmp / "cal.yaml").out
        for name in args.logs:
            source = root / f"{name}-corrected.log.gz"
            run = inject(source, cuts(source, base), tmp / f"{name}_cut", config=base.input).run_dir
            methods = {"ungated": (args.config, variants["ungated"])}
            methods.update({k: (args.config, variants[k]) for k in KERNELS})
            methods["gated (hand-set)"] = (args.config, ["validation.mode=on"])
            methods["gated (calibrated)"] = (calibrated, ["validation.mode=on"])
            for method, (cfg_path, overrides) in methods.items():
                t0 = time.perf_counter()
                cfg = load_config(cfg_path, [*overrides, "output.plots=false"])
                m = run_map(run, cfg, tmp / f"{name}_{len(rows)}").metrics
                rows.append(row(name, method, m, time.perf_counter() - t0))
                log.info("%s", rows[-1])
    text = table(rows)
    write_text(args.out / "carmen_cuts.md", text)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=sorted({k for r in rows for k in r}), lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    write_text(args.out / "carmen_cuts.csv", buf.getvalue())
    print(text)
    print(f"{time.perf_counter() - t_all:.0f} s")


def _f(x, digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def table(rows: list[dict]) -> str:
    out = io.StringIO()
    out.write("| log | method | ATE m | alarm fraction | SM recall | intervals detected | false alarms |\n")
    out.write("|---|---|---|---|---|---|---|\n")
    for r in rows:
        det = f"{r['detected']}/{r['detected'] + r['missed']}" if r.get("detected") is not None else "–"
        out.write(f"| {r['log']} | {r['method']} | {r['ate_m']:.2f} | {_f(r.get('alarm_fraction'))} | "
                  f"{_f(r.get('recall'), 2)} | {det} | {_f(r.get('false_alarm_fraction'))} |\n")
    return out.getvalue()


if __name__ == "__main__":
    main()
