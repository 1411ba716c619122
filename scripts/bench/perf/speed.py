"""``gslam map --gating on`` as a user runs it, against KISS-ICP alone, both
as cold processes on the same bag: the ``speed`` section of the ``perf``
bench.

Inputs (simulated once, seed 5): ``lab`` is telemax_lab (220.6 s, 2,207
scans); ``loop`` is telemax_loop with ``--laps`` laps. Programs, each a
fresh interpreter, compared like with like:

* ``gslam`` (``frontend.threads: 1``, the default: the same poses on every
  run) against ``kiss 1 thread`` (``python -m scripts.bench.kiss_only RUN
  --threads 1``: rosbags' AnyReader on the LaserScan topic, KissICP's
  default config on one thread);
* ``gslam all cores`` (``--set frontend.threads=0``) against ``kiss``
  (KISS-ICP's default: all cores);
* ``gslam no loops`` (``--set submaps.enabled=false --set
  loops.enabled=false``) against ``kiss 1 thread``: the pipeline without
  the scan-to-submap constraints and loop closing the config turns on,
  what the ratio of 1.15 was set for;
* ``gslam`` against ``gslam no outputs`` (``--set output.grid=false --set
  output.mcap=false``, the map's figure kept): what the occupancy grid and
  ``run.mcap`` cost as a user pays for them, target at most 1.10;
* with ``--before DIR``, ``before``: the default command with the code of
  another checkout (``git archive COMMIT | tar -x -C DIR``), against
  ``kiss 1 thread``, and whether both wrote the same bytes.

The programs take turns within each round, so load from elsewhere hits
them alike, and each round gives its own ratio of a gslam program to its
peer; the ratio reported is the median of those per-round ratios. Also per
program: the median and worst wall time, the CPU time (user + sys of the
process and its children), the real-time factor, the pipeline's own split
from ``metrics.json`` (``start-up`` is the wall time outside
``runtime_s``) and the load average around the runs. Targets: a ratio of
at most 1.15 with one thread, 1.3 with all cores, 1.10 for the outputs.
"""

from __future__ import annotations

import csv
import io
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from scripts.bench.common import simulated, table
from slam.errors import GslamError
from slam.results.atomic import write_text

ROOT = Path(__file__).resolve().parents[3]
SEED = 5
PEERS = {"gslam": "kiss 1 thread", "gslam all cores": "kiss", "gslam no loops": "kiss 1 thread", "before": "kiss 1 thread"}
"""The program each gslam program is compared with."""
TARGETS = {"gslam": 1.15, "gslam all cores": 1.3, "gslam no loops": 1.15}
OUTPUTS = ("gslam", "gslam no outputs", 1.10)
"""Program, the same without the grid and run.mcap, and the target of their ratio."""
STEPS = ("read", "prepare", "frontend", "frontend_wait", "validation", "submaps", "loops", "graph_build", "optimise",
         "write", "grid", "mcap", "plots_wait")
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
        raise GslamError(f"{' '.join(cmd)}: exit {proc.returncode}: {last}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def run_kiss(name: str, program: str, run: Path, rnd: int, threads: int) -> Sample:
    load = os.getloadavg()[0]
    wall, cpu = _timed([sys.executable, "-m", "scripts.bench.kiss_only", str(run), "--threads", str(threads)])
    return Sample(name, program, rnd, wall, cpu, load, duration_s=data_span(run))


def run_gslam(name: str, program: str, code: Path, run: Path, config: Path, out: Path, rnd: int, keep: Path | None,
              sets: tuple[str, ...] = ()) -> Sample:
    env = {**os.environ, "PYTHONPATH": str(code)}
    cmd = [sys.executable, "-m", "slam.cli", "-q", "map", str(run), "--config", str(config), "--out", str(out),
           "--gating", "on", *(a for s in sets for a in ("--set", s))]
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




def samples_csv(samples: list[Sample]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    keys = ["start-up", *STEPS]
    w.writerow(["input", "program", "round", "wall_s", "cpu_s", "load_before", "duration_s", "runtime_s", *keys])
    for s in samples:
        w.writerow([s.input, s.program, s.round, f"{s.wall_s:.4f}", f"{s.cpu_s:.4f}", f"{s.load_before:.2f}",
                    s.duration_s, s.runtime_s, *[f"{s.steps[k]:.4f}" if k in s.steps else "" for k in keys]])
    return buf.getvalue()




def report(samples: list[Sample], programs: list[str], identity: dict[str, list[str]], note: str) -> str:
    head = ["input", "program", "n", "wall median [s]", "wall worst [s]", "CPU median [s]", "RTF median",
            "peer", "ratio to peer (median of rounds)", "worst round ratio", "load avg (min-max)"]
    rows, verdicts = [], []
    for inp in dict.fromkeys(s.input for s in samples):
        for prog in programs:
            group = [s for s in samples if s.input == inp and s.program == prog]
            if not group:
                continue
            peer = {s.round: s for s in samples if s.input == inp and s.program == PEERS.get(prog)}
            walls = [s.wall_s for s in group]
            ratios = [s.wall_s / peer[s.round].wall_s for s in group if s.round in peer]
            loads = [s.load_before for s in group]
            rows.append([inp, prog, len(group), f"{_med(walls):.2f}", f"{max(walls):.2f}",
                         f"{_med([s.cpu_s for s in group]):.2f}", f"{_med([s.rtf for s in group]):.0f}x",
                         PEERS.get(prog), f"{_med(ratios):.2f}" if ratios else None,
                         f"{max(ratios):.2f}" if ratios else None, f"{min(loads):.1f}-{max(loads):.1f}"])
            if prog in TARGETS and ratios:
                r = _med(ratios)
                verdicts.append(f"- {inp}, {prog} against {PEERS[prog]}: {r:.2f} "
                                f"({'within' if r <= TARGETS[prog] else 'above'} the target {TARGETS[prog]})")
        with_out, without, target = OUTPUTS
        bare = {s.round: s for s in samples if s.input == inp and s.program == without}
        costs = [s.wall_s / bare[s.round].wall_s for s in samples
                 if s.input == inp and s.program == with_out and s.round in bare]
        if costs:
            r = _med(costs)
            verdicts.append(f"- {inp}, the grid and run.mcap ({with_out} against {without}): {r:.2f} "
                            f"(worst round {max(costs):.2f}; {'within' if r <= target else 'above'} the target {target})")
    lines = [note, "", table(head, rows), *verdicts, "",
             "Split of the gslam runs (medians, s; steps may overlap: the front-end runs in a second process "
             "while the first reads and prepares; `frontend_wait` and `plots_wait` are what the first process "
             "waited for them):", ""]
    keys = ["start-up", *STEPS]
    split = []
    for inp in dict.fromkeys(s.input for s in samples):
        for prog in programs:
            group = [s for s in samples if s.input == inp and s.program == prog and s.steps]
            if group:
                split.append([inp, prog, *(f"{_med([s.steps[k] for s in group if k in s.steps]):.3f}"
                                          if any(k in s.steps for s in group) else None for k in keys),
                              f"{_med([s.runtime_s for s in group]):.3f}", f"{_med([s.wall_s for s in group]):.3f}"])
    lines.append(table(["input", "program", *keys, "runtime_s", "wall"], split))
    if identity:
        lines += ["Outputs of `gslam` against `before` (first round; metrics.json without timings):", ""]
        lines += [f"- {inp}: " + ("the same bytes" if not diffs else "; ".join(diffs)) for inp, diffs in identity.items()]
    return "\n".join(lines) + "\n"


def speed_section(out: Path, repeats: int, inputs: list[str], laps: int, config: Path,
                  before: Path | None = None) -> str:
    """Time every program on every input, ``repeats`` rounds; the section's
    Markdown (``out`` keeps the inputs, the last results and samples.csv)."""
    if repeats < 1:
        raise GslamError("--repeats: expected at least 1")
    out.mkdir(parents=True, exist_ok=True)
    kiss_threads = {"kiss 1 thread": 1, "kiss": 0}
    gslam_sets = {"gslam": (), "gslam all cores": ("frontend.threads=0",), "before": (),
                  "gslam no outputs": ("output.grid=false", "output.mcap=false"),
                  "gslam no loops": ("submaps.enabled=false", "loops.enabled=false")}
    programs = ["kiss 1 thread", "gslam", "kiss", "gslam all cores", "gslam no outputs", "gslam no loops"] + (
        ["before"] if before else [])
    code = {"gslam": ROOT, "gslam all cores": ROOT, "gslam no outputs": ROOT, "gslam no loops": ROOT,
            "before": before.resolve() if before else None}
    samples: list[Sample] = []
    identity: dict[str, list[str]] = {}
    loads_start = os.getloadavg()
    for inp in inputs:
        run = simulated(out / "inputs", "telemax_lab" if inp == "lab" else "telemax_loop", SEED,
                        None if inp == "lab" else laps)
        keep = {prog: out / f"result_{inp}_{prog.replace(' ', '_')}" for prog in programs if prog in code}
        for k in keep.values():
            shutil.rmtree(k, ignore_errors=True)
        for rnd in range(1, repeats + 1):
            for prog in programs:
                if prog in kiss_threads:
                    s = run_kiss(inp, prog, run, rnd, kiss_threads[prog])
                else:
                    s = run_gslam(inp, prog, code[prog], run, config.resolve(), out / "tmp_map", rnd, keep[prog],
                                  gslam_sets[prog])
                samples.append(s)
                print(f"{inp} round {rnd} {prog}: {s.wall_s:.2f} s (load {s.load_before:.1f})", flush=True)
        if "before" in keep:
            identity[inp] = same_outputs(keep["gslam"], keep["before"])
    loads_end = os.getloadavg()
    note = (f"Load average (1, 5, 15 min) {loads_start[0]:.1f}, {loads_start[1]:.1f}, {loads_start[2]:.1f} at the "
            f"start and {loads_end[0]:.1f}, {loads_end[1]:.1f}, {loads_end[2]:.1f} at the end; "
            f"{repeats} rounds, programs in turn: {', '.join(programs)}.")
    write_text(out / "samples.csv", samples_csv(samples))
    return report(samples, programs, identity, note)
