"""Performance of ``gslam map``: one bench, one page (``docs/results/perf.md``).

    python -m scripts.bench perf [--sections speed ratio growth isam2 diagnosis] [--quick]
                                 [--repeats N] [--out DIR] [--cache DIR] ...

Sections:

* ``speed`` (:mod:`.speed`): ``gslam map --gating on`` as a process against
  KISS-ICP alone as a process, like with like: one thread against one
  thread (the default, bit-identical) and all cores against KISS-ICP's
  default (``frontend.threads: 0``); and against kiss-slam (``--kiss-slam``);
  on telemax_lab, the looping run and every CARMEN log with real stamps;
  paired ratios, medians.
* ``ratio``, ``growth``, ``isam2``, ``diagnosis`` (:mod:`.stages`): in one
  process, the pipeline against KISS-ICP alone and its split into stages;
  growth of time and memory with the run's length; iSAM2's latency per
  keyframe; the diagnosis' time per step.

``--quick`` runs fewer repeats and shorter runs (what ``python -m
scripts.bench all --quick`` uses); the page says which command wrote it.
The page holds every section: a run of some of them writes its own page
to ``--out`` and leaves ``docs/results/perf.md`` as it was.
"""

from __future__ import annotations

import argparse
import logging
import os
import time
from pathlib import Path

from scripts.bench.common import REPO, publish, stamped
from scripts.bench.perf.speed import BYTECODE_ENV, speed_section
from scripts.bench.perf.stages import (
    Report,
    _child_map,
    bench_cli,
    bench_diagnosis,
    bench_growth,
    bench_isam2,
    bench_ratio,
)
from slam.errors import GslamError
from slam.results.atomic import write_text

log = logging.getLogger(__name__)
SECTIONS = ("speed", "ratio", "growth", "isam2", "diagnosis")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m scripts.bench perf", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sections", nargs="+", default=list(SECTIONS), choices=SECTIONS)
    ap.add_argument("--quick", action="store_true", help="fewer repeats and shorter runs")
    ap.add_argument("--out", type=Path, default=REPO / "runs" / "bench_perf", help="work folder")
    ap.add_argument("--cache", type=Path, default=REPO / "runs" / "bench_cache",
                    help="simulated runs, made once (the 2 h run is ~1.5 GB)")
    ap.add_argument("--repeats", type=int, default=None, help="rounds of speed and ratio (default 5; quick 3)")
    ap.add_argument("--cli-repeats", type=int, default=None)
    ap.add_argument("--inputs", nargs="+", choices=["lab", "loop", "carmen"], default=None,
                    help="speed's inputs (default lab loop carmen; quick lab); carmen: every CARMEN log with real stamps")
    ap.add_argument("--kiss-slam", default="kiss_slam_pipeline",
                    help="kiss-slam's executable (its own environment: scripts/bench/peers.py); 'none' leaves it out")
    ap.add_argument("--laps", type=int, default=7, help="laps of speed's looping run (default 7: 29.5 min)")
    ap.add_argument("--config", type=Path, default=REPO / "configs" / "telemax.yaml")
    ap.add_argument("--before", type=Path, default=None, help="another checkout's code to time as 'before' in speed")
    ap.add_argument("--growth-laps", type=int, nargs="+", default=None, help="default 1 3 10 29; quick 1 3 10")
    ap.add_argument("--growth-repeats", type=int, default=None)
    ap.add_argument("--isam2-laps", type=int, default=None, help="default 29; quick 3")
    ap.add_argument("--isam2-repeats", type=int, default=None)
    ap.add_argument("--child-map", nargs=2, metavar=("RUN", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child_map:
        _child_map(*args.child_map)
        return 0
    quick = args.quick
    for flag in ("repeats", "cli_repeats", "growth_repeats", "isam2_repeats", "isam2_laps", "laps"):
        if getattr(args, flag) is not None and getattr(args, flag) < 1:
            raise GslamError(f"--{flag.replace('_', '-')}: expected at least 1")
    repeats = args.repeats or (3 if quick else 5)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    for name in ("slam", "validation"):
        logging.getLogger(name).setLevel(logging.WARNING)
    args.out.mkdir(parents=True, exist_ok=True)
    args.cache.mkdir(parents=True, exist_ok=True)
    BYTECODE_ENV["PYTHONPYCACHEPREFIX"] = str((args.out / "pycache").resolve())  # every timed process's
    report = Report()
    started = time.perf_counter()
    work = args.out / "work"
    sections = {
        "speed": lambda: report.markdown.extend([
            "## gslam map against KISS-ICP alone, as processes", "",
            speed_section(args.out / "speed", repeats, args.inputs or (["lab"] if quick else ["lab", "loop", "carmen"]),
                          args.laps, args.config, args.before, None if args.kiss_slam == "none" else args.kiss_slam)]),
        "ratio": lambda: (bench_ratio(report, args.cache, work, repeats),
                          bench_cli(report, args.cache, work, args.cli_repeats or (1 if quick else 3))),
        "growth": lambda: bench_growth(report, args.cache, work, args.growth_laps or ([1, 3, 10] if quick else [1, 3, 10, 29]),
                                       args.growth_repeats or (1 if quick else 3)),
        "isam2": lambda: bench_isam2(report, args.cache, work, args.isam2_laps or (3 if quick else 29),
                                     args.isam2_repeats or (1 if quick else 3)),
        "diagnosis": lambda: bench_diagnosis(report, args.cache, work, repeats),
    }
    for name in args.sections:
        log.info("section %s", name)
        sections[name]()
    report.markdown.append(f"Benchmark wall time {time.perf_counter() - started:.0f} s; load average "
                           f"{os.getloadavg()[0]:.1f} at the end.")
    write_text(args.out / "perf.csv", report.csv_text())
    text = "\n".join(report.markdown) + "\n"
    write_page(text, argv, args.sections, args.out)
    print(text)
    return 0


def write_page(text: str, argv: list[str] | None, sections: list[str], out: Path) -> Path:
    """docs/results/perf.md when every section ran; otherwise OUT/perf.md,
    so that a run of one section does not replace the others' figures."""
    title = "Performance of gslam map"
    if set(sections) >= set(SECTIONS):
        return publish("perf", title, text, argv)
    path = out / "perf.md"
    write_text(path, stamped(title, text, argv, "perf"))
    log.info("wrote %s (sections %s only; docs/results/perf.md holds every section and is left as it was)",
             path, " ".join(sections))
    return path
