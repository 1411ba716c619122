"""``gslam map --gating on`` as a user runs it, against KISS-ICP alone, both
as cold processes on the same bag.

    python -m scripts.bench speed [--repeats 5] [--inputs lab loop] [--laps 7]
                                  [--out runs/bench_speed] [--before DIR] [--config PATH]
                                  [--kiss-threads N]

Inputs (simulated once into ``OUT/inputs``, seed 5): ``lab`` is
telemax_lab (220.6 s, 2,207 scans); ``loop`` is telemax_loop with
``--laps`` laps (7: 29.5 min). Programs, each a fresh interpreter:

* ``kiss``: ``scripts/bench/kiss_only.py`` (rosbags' AnyReader on the LaserScan
  topic, message by message, KissICP's default config; ``--kiss-threads 1``
  registers on one thread, as gslam's front-end does);
* ``gslam``: ``python -m slam.cli -q map RUN --config CONFIG --out TMP
  --gating on`` with this checkout's code;
* ``before`` (with ``--before DIR``): the same command with the code of
  another checkout ``DIR`` (e.g. ``git archive COMMIT | tar -x -C DIR``),
  for a before/after on the same machine in the same session.

The programs take turns (kiss, gslam, before, kiss, gslam, ...), so load
from elsewhere hits them alike, and each round gives its own ratio. The
report has per program the median and worst wall time, the CPU time
(user + sys of the process and its children) and the real-time factor;
the ratio gslam / kiss as the median of the per-round ratios and as the
ratio of the medians; the pipeline's own split from ``metrics.json``
(``timings_s``; ``start-up`` is the process wall time outside
``runtime_s``: interpreter, imports, config, renaming the result into
place); the load average around each run; and, with ``--before``, whether
both versions wrote the same bytes (``metrics.json`` without its timings).

Writes ``OUT/bench_speed.md`` and ``OUT/samples.csv``. Targets: ratio at
most 1.3 on both inputs, at least 100x real time on ``lab``.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SEED = 5
TARGET_RATIO = 1.3
TARGET_RTF = 100.0
STEPS = ("read", "prepare", "frontend", "frontend_wait", "validation", "loops", "graph_build", "optimise", "write", "plots_wait")
TIMING_KEYS = ("runtime_s", "realtime_factor", "timings_s", "validation_time_s")


@dataclass
class Sample:
    """One cold run of one program on one input."""

    input: str
    program: str
    round: int
    wall_s: float
    cpu_s: float
    load_before: float
    duration_s: float = 0.0
    runtime_s: float = 0.0
    steps: dict[str, float] = field(default_factory=dict)

    @property
    def rtf(self) -> float:
        return self.duration_s / self.wall_s if self.wall_s else 0.0


def simulated(cache: Path, name: str, laps: int | None) -> Path:
    """telemax_lab (``laps`` None) or telemax_loop with ``laps`` laps, seed
    5, simulated into ``cache/name`` once."""
    from slam.sim import load_scenario, simulate_scenario

    out = cache / name
    if (out / "truth.json").exists():
        return out
    scenario = load_scenario(ROOT / "configs/scenarios" / ("telemax_lab.yaml" if laps is None else "telemax_loop.yaml"))
    tree = scenario.model_dump()
    tree["seed"] = SEED
    if laps is not None:
        tree["robot"]["laps"] = laps
    print(f"simulating {name} into {out}", flush=True)
    simulate_scenario(type(scenario).model_validate(tree), out)
    return out


def data_span(run: Path) -> float:
    return float(json.loads((run / "truth.json").read_text())["duration_s"])


def _timed(cmd: list[str], env: dict[str, str] | None = None, cwd: Path = ROOT) -> tuple[float, float]:
    """Wall and CPU seconds (user + sys of the child and its children) of ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise SystemExit(f"bench speed: {' '.join(cmd)}: exit {proc.returncode}: {last}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def run_kiss(name: str, run: Path, rnd: int, threads: int = 0) -> Sample:
    load = os.getloadavg()[0]
    wall, cpu = _timed([sys.executable, "-m", "scripts.bench.kiss_only", str(run), "--threads", str(threads)])
    return Sample(name, "kiss", rnd, wall, cpu, load, duration_s=data_span(run))


def run_gslam(name: str, program: str, code: Path, run: Path, config: Path, out: Path, rnd: int, keep: Path | None) -> Sample:
    env = {**os.environ, "PYTHONPATH": str(code)}
    cmd = [sys.executable, "-m", "slam.cli", "-q", "map", str(run), "--config", str(config), "--out", str(out),
           "--gating", "on"]
    load = os.getloadavg()[0]
    wall, cpu = _timed(cmd, env, cwd=code)  # python -m puts the working folder first on the path
    metrics = json.loads((out / "metrics.json").read_text())
    steps = {k: float(v) for k, v in metrics.get("timings_s", {}).items()}
    steps["start-up"] = wall - float(metrics["runtime_s"])
    sample = Sample(name, program, rnd, wall, cpu, load, float(metrics["duration_s"]), float(metrics["runtime_s"]), steps)
    if keep is not None and not keep.exists():
        shutil.move(str(out), str(keep))
    else:
        shutil.rmtree(out)
    return sample


def same_outputs(a: Path, b: Path) -> list[str]:
    """Lines saying how two map results differ (metrics.json without timings,
    the marker left out); empty if they are the same bytes."""
    names = sorted({p.name for p in a.iterdir()} | {p.name for p in b.iterdir()} - {".gslam-result.json"})
    out = []
    for n in names:
        pa, pb = a / n, b / n
        if n == ".gslam-result.json":
            continue
        if not pa.exists() or not pb.exists():
            out.append(f"{n}: only in {'the first' if pa.exists() else 'the second'}")
        elif n == "metrics.json":
            ma, mb = (json.loads(p.read_text()) for p in (pa, pb))
            for k in TIMING_KEYS:
                ma.pop(k, None), mb.pop(k, None)
            if ma != mb:
                keys = sorted(k for k in set(ma) | set(mb) if ma.get(k) != mb.get(k))
                out.append(f"metrics.json differs in {', '.join(keys)}")
        elif pa.read_bytes() != pb.read_bytes():
            out.append(f"{n} differs")
    return out


def _med(values: list[float]) -> float:
    return statistics.median(values) if values else float("nan")


def machine() -> str:
    cpu = platform.machine()
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                   if ln.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def report(samples: list[Sample], programs: list[str], identity: dict[str, list[str]], note: str) -> str:
    lines = ["# gslam map against KISS-ICP alone, cold processes", "", f"Machine: {machine()}. {note}", ""]
    head = ["input", "program", "n", "wall median [s]", "wall worst [s]", "CPU median [s]", "RTF median",
            "ratio to kiss (median of rounds)", "ratio of medians", "worst round ratio", "load avg (min-max)"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    verdicts = []
    for inp in dict.fromkeys(s.input for s in samples):
        kiss = {s.round: s for s in samples if s.input == inp and s.program == "kiss"}
        for prog in programs:
            group = [s for s in samples if s.input == inp and s.program == prog]
            if not group:
                continue
            walls = [s.wall_s for s in group]
            ratios = [s.wall_s / kiss[s.round].wall_s for s in group if s.round in kiss and prog != "kiss"]
            loads = [s.load_before for s in group]
            ratio_of_medians = _med(walls) / _med([s.wall_s for s in kiss.values()]) if prog != "kiss" else None
            cells = [inp, prog, str(len(group)), f"{_med(walls):.2f}", f"{max(walls):.2f}",
                     f"{_med([s.cpu_s for s in group]):.2f}", f"{_med([s.rtf for s in group]):.0f}x",
                     f"{_med(ratios):.2f}" if ratios else "-", f"{ratio_of_medians:.2f}" if ratio_of_medians else "-",
                     f"{max(ratios):.2f}" if ratios else "-", f"{min(loads):.1f}-{max(loads):.1f}"]
            lines.append("| " + " | ".join(cells) + " |")
            if prog == "gslam":
                r, rtf = _med(ratios), _med([s.rtf for s in group])
                verdicts.append(f"- {inp}: ratio {r:.2f} ({'meets' if r <= TARGET_RATIO else 'MISSES'} "
                                f"<= {TARGET_RATIO}); {rtf:.0f}x real time"
                                + (f" ({'meets' if rtf >= TARGET_RTF else 'MISSES'} >= {TARGET_RTF:.0f}x)"
                                   if inp == "lab" else ""))
    lines += ["", "Targets:", *verdicts, "", "Split of the gslam runs (medians, s; steps may overlap: the "
              "front-end runs in a second process while the first reads and prepares; `frontend_wait` and "
              "`plots_wait` are what the first process waited for them):", ""]
    keys = ["start-up", *STEPS]
    head = ["input", "program", *keys, "runtime_s", "wall"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for inp in dict.fromkeys(s.input for s in samples):
        for prog in programs:
            group = [s for s in samples if s.input == inp and s.program == prog and s.steps]
            if group:
                cells = [f"{_med([s.steps[k] for s in group if k in s.steps]):.3f}" if any(k in s.steps for s in group)
                         else "-" for k in keys]
                lines.append("| " + " | ".join([inp, prog, *cells, f"{_med([s.runtime_s for s in group]):.3f}",
                                                 f"{_med([s.wall_s for s in group]):.3f}"]) + " |")
    if identity:
        lines += ["", "Outputs of `gslam` against `before` (first round; metrics.json without timings):"]
        for inp, diffs in identity.items():
            lines.append(f"- {inp}: " + ("the same bytes" if not diffs else "; ".join(diffs)))
    return "\n".join(lines) + "\n"


def samples_csv(samples: list[Sample]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    keys = ["start-up", *STEPS]
    w.writerow(["input", "program", "round", "wall_s", "cpu_s", "load_before", "duration_s", "runtime_s", *keys])
    for s in samples:
        w.writerow([s.input, s.program, s.round, f"{s.wall_s:.4f}", f"{s.cpu_s:.4f}", f"{s.load_before:.2f}",
                    s.duration_s, s.runtime_s, *[f"{s.steps[k]:.4f}" if k in s.steps else "" for k in keys]])
    return buf.getvalue()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5, help="rounds per input (default 5)")
    p.add_argument("--inputs", nargs="+", choices=["lab", "loop"], default=["lab", "loop"])
    p.add_argument("--laps", type=int, default=7, help="laps of the looping run (default 7: 29.5 min)")
    p.add_argument("--out", type=Path, default=ROOT / "runs/bench_speed", help="report folder")
    p.add_argument("--config", type=Path, default=ROOT / "configs/telemax.yaml")
    p.add_argument("--before", type=Path, default=None, help="another checkout's code to time as 'before'")
    p.add_argument("--kiss-threads", type=int, default=0,
                   help="KISS-ICP alone's threads (default 0: all cores, its default; 1: as gslam's front-end)")
    args = p.parse_args(argv)
    if args.repeats < 1:
        raise SystemExit("bench speed: --repeats: expected at least 1")
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    programs = ["kiss", "gslam"] + (["before"] if args.before else [])
    code = {"gslam": ROOT, "before": args.before.resolve() if args.before else None}
    samples: list[Sample] = []
    identity: dict[str, list[str]] = {}
    loads_start = os.getloadavg()
    for inp in args.inputs:
        run = simulated(out / "inputs", "telemax_lab_seed5" if inp == "lab" else f"telemax_loop{args.laps}_seed5",
                        None if inp == "lab" else args.laps)
        keep = {prog: out / f"result_{inp}_{prog}" for prog in programs if prog != "kiss"}
        for k in keep.values():
            shutil.rmtree(k, ignore_errors=True)
        for rnd in range(1, args.repeats + 1):
            for prog in programs:
                if prog == "kiss":
                    s = run_kiss(inp, run, rnd, args.kiss_threads)
                else:
                    s = run_gslam(inp, prog, code[prog], run, args.config.resolve(), out / "tmp_map", rnd, keep[prog])
                samples.append(s)
                print(f"{inp} round {rnd} {prog}: {s.wall_s:.2f} s (load {s.load_before:.1f})", flush=True)
        if "before" in keep:
            identity[inp] = same_outputs(keep["gslam"], keep["before"])
    loads_end = os.getloadavg()
    note = (f"Load average (1, 5, 15 min) {loads_start[0]:.1f}, {loads_start[1]:.1f}, {loads_start[2]:.1f} at the "
            f"start and {loads_end[0]:.1f}, {loads_end[1]:.1f}, {loads_end[2]:.1f} at the end; "
            f"{args.repeats} rounds, programs in turn: {', '.join(programs)}. Command: "
            f"`python -m scripts.bench speed {' '.join(argv if argv is not None else sys.argv[1:])}`")
    text = report(samples, programs, identity, note)
    (out / "bench_speed.md").write_text(text)
    (out / "samples.csv").write_text(samples_csv(samples))
    print(text)
    return 0

