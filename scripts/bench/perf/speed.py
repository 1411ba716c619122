"""``gslam map --gating on`` as a user runs it, against KISS-ICP alone, both
as cold processes on the same bag: the ``speed`` section of the ``perf``
bench.

Inputs: ``lab`` is telemax_lab (simulated once, seed 5; 220.6 s, 2,207
scans); ``loop`` is telemax_loop with ``--laps`` laps; ``carmen`` is every
CARMEN log in the data folder's ``carmen`` (``$GSLAM_DATA``, else
``../shared/data``) whose stamps are real (not synthesised by the reader),
mapped with ``configs/datasets/carmen.yaml`` as the ``carmen`` bench maps
them. Programs, each a fresh interpreter, compared like with like:

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
* ``kiss-slam`` (``--kiss-slam``, its own environment:
  :mod:`scripts.bench.peers`): the laser SLAM a KISS-ICP user tries first,
  in its default setting, on the same scans written once as PLY files
  (the writing not timed), against which ``gslam`` is compared;
* with ``--before DIR``, ``before``: the default command with the code of
  another checkout (``git archive COMMIT | tar -x -C DIR``), against
  ``kiss 1 thread``, and whether both wrote the same bytes.

Every program runs with Python's bytecode cached, as on a user's machine
after the first run (the interpreter writes it unless told not to): the
caches go to the bench's ``--out``/pycache (``PYTHONPYCACHEPREFIX``, so
nothing is written beside the code), ``PYTHONDONTWRITEBYTECODE`` is
dropped, and each program runs once, untimed, on the first input before
the rounds. A host that forbids the caches otherwise has every gslam
process compile the project's modules again: 0.7 s of 9.9 s on
telemax_lab on a 2-core EPYC.

The programs take turns within each round, so load from elsewhere hits
them alike, and each round gives its own ratio of a gslam program to its
peer; the ratio reported is the median of those per-round ratios. Also per
program: the median and worst wall time, the CPU time (user + sys of the
process and its children), the real-time factor, the pipeline's own split
from ``metrics.json`` (``start-up`` is the wall time outside
``runtime_s``) and the load average around the runs. Targets: a ratio of
at most 1.5 with one thread, 1.3 with all cores, 1.15 without submaps and
loops, 1.10 for the outputs; below 1 against kiss-slam; a real-time factor
of at least 80 on the simulated runs and 60 on the logs (issue 37).
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

import numpy as np

from scripts.bench.common import simulated, table
from slam.errors import GslamError
from slam.results.atomic import write_text

ROOT = Path(__file__).resolve().parents[3]
SEED = 5
CARMEN_CONFIG = ROOT / "configs" / "datasets" / "carmen.yaml"
PEERS = {"gslam": "kiss 1 thread", "gslam all cores": "kiss", "gslam no loops": "kiss 1 thread", "before": "kiss 1 thread"}
"""The program each gslam program is compared with."""
TARGETS = {"gslam": 1.5, "gslam all cores": 1.3, "gslam no loops": 1.15}
AGAINST_KISS_SLAM = ("gslam", "kiss-slam", 1.0)
"""Program, peer and the target of their ratio (below it)."""
RTF_TARGETS = {"simulated": 80.0, "carmen": 60.0}
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


BYTECODE_ENV: dict[str, str] = {}
"""Where the timed programs keep their bytecode (``PYTHONPYCACHEPREFIX``),
set by the perf bench for all its sections; empty: as this process."""


def timed_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """The timed programs' environment: this one, with bytecode cached
    (:data:`BYTECODE_ENV`), and ``extra``."""
    env = {k: v for k, v in os.environ.items() if not (BYTECODE_ENV and k == "PYTHONDONTWRITEBYTECODE")}
    return {**env, **BYTECODE_ENV, **(extra or {})}


def _timed(cmd: list[str], env: dict[str, str] | None = None, cwd: Path = ROOT) -> tuple[float, float]:
    """Wall and CPU seconds (user + sys of the child and its children) of ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env if env is not None else timed_env(), capture_output=True, text=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise GslamError(f"{' '.join(cmd)}: exit {proc.returncode}: {last}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


@dataclass
class Input:
    """One input of the section: the run or log, the config it is mapped
    with and the ``gslam map`` arguments beside it, its data span (s), and
    the programs timed on it; ``scans``: the PLY folder kiss-slam reads."""

    name: str
    path: Path
    config: Path
    args: tuple[str, ...]
    duration_s: float
    programs: list[str]
    kind: str = "simulated"
    scans: Path | None = None


def carmen_inputs() -> list[tuple[str, Path]]:
    """The CARMEN logs whose stamps are real (the reader synthesised none)."""
    from slam.config import load_config
    from slam.readers.datasets import data_root
    from slam.readers.read import read_recording

    folder = data_root() / "carmen"
    logs = sorted(folder.glob("*.log.gz"))
    if not logs:
        raise GslamError(f"--inputs carmen: no CARMEN log (*.log.gz) in {folder} (set GSLAM_DATA to the data folder)")
    cfg = load_config(CARMEN_CONFIG)
    out = []
    for path in logs:
        if not read_recording(path, cfg.input).stamps_synthesised:
            out.append((path.name.split("-corrected")[0], path))
    return out


def export_for_kiss_slam(path: Path, config: Path, folder: Path) -> Path:
    """The scans of ``path`` as PLY files in ``folder`` (once), as the
    ``carmen`` bench hands them to kiss-slam."""
    from scripts.bench.peers import export_scans
    from slam.config import load_config
    from slam.readers.read import read_recording

    if not (folder / "done").exists():
        cfg = load_config(config)
        rec = read_recording(path, cfg.input)
        shutil.rmtree(folder, ignore_errors=True)
        export_scans(rec.scans, folder, cfg.frontend.min_range_m, cfg.frontend.max_range_m)
        np.save(folder / "t.npy", rec.scans.t)
        (folder / "done").write_text("")
    return folder


def run_kiss(name: str, program: str, run: Path, rnd: int, threads: int, duration_s: float) -> Sample:
    load = os.getloadavg()[0]
    wall, cpu = _timed([sys.executable, "-m", "scripts.bench.kiss_only", str(run), "--threads", str(threads)])
    return Sample(name, program, rnd, wall, cpu, load, duration_s=duration_s)


def run_kiss_slam(name: str, executable: str, scans: Path, work: Path, rnd: int, duration_s: float) -> Sample:
    """kiss-slam (its default setting) on the PLY scans, as a process."""
    from scripts.bench.peers import kiss_slam

    load = os.getloadavg()[0]
    shutil.rmtree(work, ignore_errors=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    run = kiss_slam(executable, scans.resolve(), np.load(scans / "t.npy"), work.resolve(), "default")  # it runs in work
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.error:
        raise GslamError(f"kiss-slam on {scans}: {run.error}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return Sample(name, "kiss-slam", rnd, run.wall_s, cpu, load, duration_s=duration_s)


def run_gslam(name: str, program: str, code: Path, run: Path, config: Path, out: Path, rnd: int, keep: Path | None,
              sets: tuple[str, ...] = (), args: tuple[str, ...] = ("--gating", "on")) -> Sample:
    env = timed_env({"PYTHONPATH": str(code)})
    cmd = [sys.executable, "-m", "slam.cli", "-q", "map", str(run), "--config", str(config), "--out", str(out),
           *args, *(a for s in sets for a in ("--set", s))]
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


def _paired(samples: list[Sample], inp: str, prog: str, peer_name: str | None) -> list[float]:
    """Per round of ``inp``: ``prog``'s wall time over ``peer_name``'s in that round."""
    peer = {s.round: s for s in samples if s.input == inp and s.program == peer_name}
    return [s.wall_s / peer[s.round].wall_s for s in samples
            if s.input == inp and s.program == prog and s.round in peer]


def report(samples: list[Sample], programs: list[str], identity: dict[str, list[str]], note: str,
           kinds: dict[str, str] | None = None) -> str:
    kinds = kinds or {}
    head = ["input", "program", "n", "wall median [s]", "wall worst [s]", "CPU median [s]", "RTF median",
            "peer", "ratio to peer (median of rounds)", "worst round ratio", "load avg (min-max)"]
    rows, verdicts = [], []
    for inp in dict.fromkeys(s.input for s in samples):
        for prog in programs:
            group = [s for s in samples if s.input == inp and s.program == prog]
            if not group:
                continue
            walls = [s.wall_s for s in group]
            ratios = _paired(samples, inp, prog, PEERS.get(prog))
            loads = [s.load_before for s in group]
            rows.append([inp, prog, len(group), f"{_med(walls):.2f}", f"{max(walls):.2f}",
                         f"{_med([s.cpu_s for s in group]):.2f}", f"{_med([s.rtf for s in group]):.0f}x",
                         PEERS.get(prog), f"{_med(ratios):.2f}" if ratios else None,
                         f"{max(ratios):.2f}" if ratios else None, f"{min(loads):.1f}-{max(loads):.1f}"])
            if prog in TARGETS and ratios and kinds.get(inp, "simulated") == "simulated":  # the targets of the robot's runs
                r = _med(ratios)
                verdicts.append(f"- {inp}, {prog} against {PEERS[prog]}: {r:.2f} "
                                f"({'within' if r <= TARGETS[prog] else 'above'} the target {TARGETS[prog]})")
        prog, peer_name, target = AGAINST_KISS_SLAM
        ratios = _paired(samples, inp, prog, peer_name)
        if ratios:
            r = _med(ratios)
            verdicts.append(f"- {inp}, {prog} against {peer_name}: {r:.2f} (worst round {max(ratios):.2f}; "
                            f"{'below' if r < target else 'not below'} the target {target:g})")
        rtf = [s.rtf for s in samples if s.input == inp and s.program == "gslam"]
        if rtf:
            kind = kinds.get(inp, "simulated")
            verdicts.append(f"- {inp}, gslam real-time factor {_med(rtf):.0f}x "
                            f"({'at least' if _med(rtf) >= RTF_TARGETS[kind] else 'below'} the target "
                            f"{RTF_TARGETS[kind]:.0f}x)")
        with_out, without, target = OUTPUTS
        costs = _paired(samples, inp, with_out, without)
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


def warm_up(item: Input, kiss_threads: dict[str, int], code: dict[str, Path | None],
            gslam_sets: dict[str, tuple[str, ...]], out: Path) -> None:
    """Each program of ``item`` once, untimed: its bytecode cached
    (:data:`BYTECODE_ENV`), as after a user's first run."""
    for prog in item.programs:
        if prog in kiss_threads:
            run_kiss(item.name, prog, item.path, 0, kiss_threads[prog], item.duration_s)
        elif prog in code:
            run_gslam(item.name, prog, code[prog], item.path, item.config, out / "tmp_map", 0, None,
                      gslam_sets[prog], item.args)
    print(f"{item.name}: each program run once, untimed, its bytecode cached", flush=True)


def speed_section(out: Path, repeats: int, inputs: list[str], laps: int, config: Path,
                  before: Path | None = None, kiss_slam: str | None = None) -> str:
    """Time every program on every input, ``repeats`` rounds; the section's
    Markdown (``out`` keeps the inputs, the last results and samples.csv).
    ``kiss_slam``: its executable (None: not timed)."""
    if repeats < 1:
        raise GslamError("--repeats: expected at least 1")
    out.mkdir(parents=True, exist_ok=True)
    kiss_threads = {"kiss 1 thread": 1, "kiss": 0}
    gslam_sets = {"gslam": (), "gslam all cores": ("frontend.threads=0",), "before": (),
                  "gslam no outputs": ("output.grid=false", "output.mcap=false"),
                  "gslam no loops": ("submaps.enabled=false", "loops.enabled=false")}
    if kiss_slam is not None and shutil.which(kiss_slam) is None:
        raise GslamError(f"--kiss-slam {kiss_slam}: not found (see scripts/bench/peers.py; 'none' leaves it out)")
    peer = ["kiss-slam"] if kiss_slam else []
    simulated_programs = ["kiss 1 thread", "gslam", "kiss", "gslam all cores", "gslam no outputs",
                          "gslam no loops"] + peer + (["before"] if before else [])
    carmen_programs = ["kiss 1 thread", "gslam"] + peer + (["before"] if before else [])
    code = {"gslam": ROOT, "gslam all cores": ROOT, "gslam no outputs": ROOT, "gslam no loops": ROOT,
            "before": before.resolve() if before else None}
    todo: list[Input] = []
    for inp in inputs:
        if inp == "carmen":
            for name, path in carmen_inputs():
                from slam.config import load_config
                from slam.readers.read import read_recording

                duration = read_recording(path, load_config(CARMEN_CONFIG).input).duration
                todo.append(Input(name, path, CARMEN_CONFIG, (), duration, carmen_programs, "carmen"))
        else:
            run = simulated(out / "inputs", "telemax_lab" if inp == "lab" else "telemax_loop", SEED,
                            None if inp == "lab" else laps)
            todo.append(Input(inp, run, config.resolve(), ("--gating", "on"), data_span(run), simulated_programs))
    if kiss_slam:
        for item in todo:
            item.scans = export_for_kiss_slam(item.path, item.config, out / "inputs" / f"ply_{item.name}")
    samples: list[Sample] = []
    identity: dict[str, list[str]] = {}
    programs_seen: list[str] = []
    warm_up(todo[0], kiss_threads, code, gslam_sets, out)
    loads_start = os.getloadavg()
    for item in todo:
        keep = {prog: out / f"result_{item.name}_{prog.replace(' ', '_')}" for prog in item.programs if prog in code}
        for k in keep.values():
            shutil.rmtree(k, ignore_errors=True)
        for rnd in range(1, repeats + 1):
            for prog in item.programs:
                if prog in kiss_threads:
                    s = run_kiss(item.name, prog, item.path, rnd, kiss_threads[prog], item.duration_s)
                elif prog == "kiss-slam":
                    s = run_kiss_slam(item.name, kiss_slam, item.scans, out / "kiss_slam", rnd, item.duration_s)
                else:
                    s = run_gslam(item.name, prog, code[prog], item.path, item.config, out / "tmp_map", rnd,
                                  keep[prog], gslam_sets[prog], item.args)
                samples.append(s)
                print(f"{item.name} round {rnd} {prog}: {s.wall_s:.2f} s (load {s.load_before:.1f})", flush=True)
        programs_seen += [p for p in item.programs if p not in programs_seen]
        if "before" in keep:
            identity[item.name] = same_outputs(keep["gslam"], keep["before"])
    loads_end = os.getloadavg()
    note = (f"Load average (1, 5, 15 min) {loads_start[0]:.1f}, {loads_start[1]:.1f}, {loads_start[2]:.1f} at the "
            f"start and {loads_end[0]:.1f}, {loads_end[1]:.1f}, {loads_end[2]:.1f} at the end; "
            f"{repeats} rounds, programs in turn on each input: {', '.join(programs_seen)}.")
    write_text(out / "samples.csv", samples_csv(samples))
    return report(samples, programs_seen, identity, note, {item.name: item.kind for item in todo})
