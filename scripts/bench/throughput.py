"""Throughput of ``gslam map`` on a simulated mission (default: the Telemax
lab run), against the target "at least 50x faster than real time".

    python -m scripts.bench throughput [--repeats N] [--out DIR] [--scenario PATH]
                                       [--config PATH] [--cli-repeats N] [--isam2]

The scenario is simulated once (fixed seed) into a temporary folder. Each
variant (gating off, gating on, gating off without plots, optionally iSAM2)
is then mapped ``repeats`` times in this process through the library
(:func:`slam.pipeline.run_map`), after one warm-up run that pays the lazy
imports (reported apart), and ``cli_repeats`` times (default once) as the
full ``gslam map`` command in a subprocess, whose wall time includes
interpreter start-up and every import. Variants take turns, so a burst of
load from elsewhere hits them alike. Plots are on as a user would run it;
the no-plots variant shows what they cost. The cold cost of each heavy
import is measured in fresh interpreters.

Per variant: median, min and max of the wall time (including writing the
result folder), the real-time factor (data seconds / wall seconds) and the
pipeline's own split (``metrics.json`` ``timings_s``): read, front-end
(KISS-ICP), validation, graph build, optimisation, write; "other" is the
rest of ``runtime_s`` (keyframes, measurements, evaluation). Back-end is
validation + graph build + optimisation. All times are wall-clock seconds;
the machine is shared, hence medians.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import logging
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

from slam.config import load_config
from slam.errors import GslamError
from slam.io.atomic import write_text
from slam.pipeline import run_map
from validation.errors import ValidationError

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
TARGET_RTF = 50.0
SEED = 1
STEPS = ("read", "frontend", "validation", "graph_build", "optimise", "other", "write")
PACKAGES = ("numpy", "gtsam", "kiss-icp", "open3d", "matplotlib", "rosbags")
# What a cold `gslam map` imports on its way (lazily, step by step): label -> statement.
COLD_IMPORTS = {
    "gtsam": "import gtsam",
    "kiss-icp": "import kiss_icp.kiss_icp",
    "rosbags": "import rosbags.highlevel, rosbags.typesys",
    "validation": "import validation.validator",
    "matplotlib (plots)": "import slam.plots",
    "open3d (map.ply)": "import slam.io.pointcloud as p; p.import_open3d()",
    "all of the pipeline": "import slam.cli, slam.pipeline, slam.io.readers, slam.frontend, slam.backend, "
    "kiss_icp.kiss_icp, validation.validator, slam.plots, slam.evaluation, slam.io.pointcloud as p; p.import_open3d()",
}


@dataclass(frozen=True)
class Variant:
    """One way of running ``gslam map``: ``--gating`` plus ``--set`` overrides."""

    name: str
    gating: str
    sets: tuple[str, ...] = ()

    def overrides(self) -> list[str]:
        return [f"validation.mode={self.gating}", *self.sets]


@dataclass
class Sample:
    """One timed run. ``wall_s``: around the whole map call (library) or the
    whole subprocess (CLI); ``steps_s``: the pipeline's split, seconds."""

    variant: str
    mode: str  # "library", "library-warmup" or "cli"
    repeat: int
    wall_s: float
    runtime_s: float
    duration_s: float
    steps_s: dict[str, float]

    @property
    def rtf(self) -> float:
        return self.duration_s / self.wall_s


@dataclass
class BenchResult:
    """Every sample, the machine, the Markdown report and where it was written."""

    machine: dict[str, str]
    samples: list[Sample]
    overhead_s: dict[str, float]
    markdown: str
    files: list[Path] = field(default_factory=list)


def machine_info() -> dict[str, str]:
    """CPU model, cores, load, Python and the versions of the heavy packages."""
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.exists() else []
    cpu = next((ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")), "unknown")
    info = {"cpu": cpu, "cores": str(os.cpu_count()), "load_avg_1m": f"{os.getloadavg()[0]:.2f}",
            "python": platform.python_version()}
    for pkg in PACKAGES:
        try:
            info[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            info[pkg] = "not installed"
    return info


def _sample(variant: str, mode: str, repeat: int, wall_s: float, metrics: dict) -> Sample:
    t = metrics["timings_s"]
    steps = {k: float(t[k]) for k in STEPS if k in t}
    inside = sum(steps[k] for k in ("read", "frontend", "validation", "graph_build", "optimise", "write"))
    steps["other"] = max(0.0, float(metrics["runtime_s"]) - inside)  # keyframes, evaluation, bookkeeping
    return Sample(variant, mode, repeat, wall_s, float(metrics["runtime_s"]), float(metrics["duration_s"]), steps)


def _time_library(run_dir: Path, config_path: Path, v: Variant, out: Path, mode: str, repeat: int) -> Sample:
    config = load_config(config_path, v.overrides())
    start = time.perf_counter()
    res = run_map(run_dir, config, out)
    wall = time.perf_counter() - start
    shutil.rmtree(out, ignore_errors=True)
    return _sample(v.name, mode, repeat, wall, res.metrics)


def _gslam_command() -> list[str]:
    script = Path(sys.executable).parent / "gslam"
    return [str(script)] if script.exists() else [sys.executable, "-m", "slam.cli"]


def _time_cli(run_dir: Path, config_path: Path, v: Variant, out: Path, repeat: int) -> Sample:
    cmd = [*_gslam_command(), "map", str(run_dir), "--config", str(config_path), "--out", str(out),
           "--gating", v.gating]
    for s in v.sets:
        cmd += ["--set", s]
    start = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise GslamError(f"{' '.join(cmd)}: exit {proc.returncode}: {last}")
    metrics = json.loads((out / "metrics.json").read_text())
    shutil.rmtree(out, ignore_errors=True)
    return _sample(v.name, "cli", repeat, wall, metrics)


def import_costs() -> dict[str, float]:
    """Seconds: python start-up, ``import numpy``, and each heavy import of
    the pipeline in a fresh interpreter, measured after numpy is loaded."""
    def child(code: str, before: str = "import numpy") -> float:
        timed = f"import time\n{before}\nt = time.perf_counter()\n{code}\nprint(time.perf_counter() - t)"
        proc = subprocess.run([sys.executable, "-c", timed], cwd=ROOT, capture_output=True, text=True, check=True)
        return float(proc.stdout.split()[-1])

    start = time.perf_counter()
    subprocess.run([sys.executable, "-c", "pass"], check=True)
    costs = {"python start-up": time.perf_counter() - start}
    costs["numpy"] = child("import numpy", before="")
    costs.update({label: child(code) for label, code in COLD_IMPORTS.items()})
    return costs


def bench_throughput(
    scenario: str | Path,
    config: str | Path,
    repeats: int = 5,
    out_dir: str | Path = "runs/bench_throughput",
    isam2: bool = False,
    cli_repeats: int = 1,
    seed: int = SEED,
) -> BenchResult:
    """Simulate ``scenario`` once, time ``gslam map`` with ``config`` per
    variant (``repeats`` library runs, ``cli_repeats`` CLI runs) and write
    ``throughput.md``, ``throughput.csv`` (summary) and ``samples.csv``
    (every run) into ``out_dir``."""
    from slam.sim import simulate

    scenario, config = Path(scenario).resolve(), Path(config).resolve()
    for p, what in ((scenario, "scenario"), (config, "config")):
        if not p.is_file():
            raise GslamError(f"{p}: {what} file not found")
    for n, flag in ((repeats, "--repeats"), (cli_repeats, "--cli-repeats")):
        if n < 1:
            raise GslamError(f"{flag} {n}: expected at least 1")
    load_config(config)  # a bad config fails here, in one line, before the simulation
    variants = [Variant("gating off", "off"), Variant("gating on", "on"),
                Variant("gating off, no plots", "off", ("output.plots=false",))]
    if isam2:
        variants.append(Variant("gating off, iSAM2", "off", ("backend.optimizer=isam2",)))

    machine = machine_info()
    samples: list[Sample] = []
    with tempfile.TemporaryDirectory(prefix="bench_throughput_") as tmp:
        run_dir = Path(tmp) / "run"
        sim = simulate(scenario, run_dir, seed=seed)
        log.info("simulated %s: %.1f s of data", scenario.name, sim.duration_s)
        # The first run in this process pays the lazy imports; kept apart.
        samples.append(_time_library(run_dir, config, variants[0], Path(tmp) / "warm", "library-warmup", 0))
        for r in range(1, max(repeats, cli_repeats) + 1):
            for v in variants:
                if r <= cli_repeats:
                    samples.append(_time_cli(run_dir, config, v, Path(tmp) / "cli", r))
                if r <= repeats:
                    samples.append(_time_library(run_dir, config, v, Path(tmp) / "lib", "library", r))
                log.info("round %d: %s done", r, v.name)
    overhead = import_costs()
    machine["load_avg_1m_after"] = f"{os.getloadavg()[0]:.2f}"
    markdown = render_markdown(samples, machine, overhead, scenario.name)
    result = BenchResult(machine, samples, overhead, markdown)
    out = Path(out_dir)
    for name, text in (("throughput.md", markdown), ("throughput.csv", summary_csv(samples)),
                       ("samples.csv", samples_csv(samples))):
        write_text(out / name, text)
        result.files.append(out / name)
    return result


def _groups(samples: list[Sample]) -> list[tuple[str, str, list[Sample]]]:
    keys: list[tuple[str, str]] = []
    for s in samples:
        if s.mode != "library-warmup" and (s.variant, s.mode) not in keys:
            keys.append((s.variant, s.mode))
    return [(v, m, [s for s in samples if s.variant == v and s.mode == m]) for v, m in keys]


def _stats(values: list[float]) -> tuple[float, float, float]:
    return statistics.median(values), min(values), max(values)


def _summary_row(group: list[Sample]) -> dict[str, float]:
    row: dict[str, float] = {"n": len(group)}
    for name, vals in (("wall_s", [s.wall_s for s in group]), ("rtf", [s.rtf for s in group])):
        row[f"{name}_median"], row[f"{name}_min"], row[f"{name}_max"] = _stats(vals)
    for k in STEPS:
        row[f"{k}_s"] = statistics.median(s.steps_s.get(k, 0.0) for s in group)
    row["backend_s"] = statistics.median(
        s.steps_s["validation"] + s.steps_s["graph_build"] + s.steps_s["optimise"] for s in group
    )
    row["duration_s"] = group[0].duration_s
    return row


def summary_csv(samples: list[Sample]) -> str:
    """One line per (variant, mode): medians, min/max of wall and RTF, split."""
    buf = io.StringIO()
    w = None
    for v, m, group in _groups(samples):
        row = {"variant": v, "mode": m, **{k: round(x, 4) for k, x in _summary_row(group).items()}}
        if w is None:
            w = csv.DictWriter(buf, fieldnames=list(row))
            w.writeheader()
        w.writerow(row)
    return buf.getvalue()


def samples_csv(samples: list[Sample]) -> str:
    """Every timed run, including the warm-up runs."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["variant", "mode", "repeat", "wall_s", "runtime_s", "duration_s", "rtf", *[f"{k}_s" for k in STEPS]])
    for s in samples:
        w.writerow([s.variant, s.mode, s.repeat, round(s.wall_s, 4), s.runtime_s, s.duration_s, round(s.rtf, 2),
                    *[round(s.steps_s.get(k, 0.0), 4) for k in STEPS]])
    return buf.getvalue()


def render_markdown(samples: list[Sample], machine: dict[str, str], overhead: dict[str, float], scenario: str) -> str:
    """The report: machine, table of medians (min-max), verdict against the target."""
    lines = [f"# gslam map throughput on {scenario}", ""]
    lines.append("Machine: " + ", ".join(f"{k} {v}" for k, v in machine.items()))
    lines.append("")
    lines.append("library: in-process runs after one warm-up run; cli: `gslam map` subprocesses (start-up and "
                 "imports included). Median (min-max) over n runs; step columns are medians. Times in s; "
                 "RTF = data s / wall s; back-end = validation + graph build + optimise.")
    lines.append("")
    head = ["variant", "mode", "n", "wall s (min-max)", "RTF (min-max)", "read", "front-end", "validation",
            "graph build", "optimise", "other", "write", "back-end"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    verdicts = []
    for v, m, group in _groups(samples):
        r = _summary_row(group)
        cells = [v, m, str(r["n"]),
                 f"{r['wall_s_median']:.2f} ({r['wall_s_min']:.2f}-{r['wall_s_max']:.2f})",
                 f"{r['rtf_median']:.0f} ({r['rtf_min']:.0f}-{r['rtf_max']:.0f})",
                 *[f"{r[f'{k}_s']:.3f}" for k in STEPS], f"{r['backend_s']:.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
        ok = "meets" if r["rtf_median"] >= TARGET_RTF else "MISSES"
        rtf_runtime = statistics.median(s.duration_s / s.runtime_s for s in group)
        verdicts.append(f"- {v} ({m}): {r['rtf_median']:.0f}x real time on {r['duration_s']:.1f} s of data "
                        f"- {ok} the {TARGET_RTF:.0f}x target (metrics.json realtime_factor, which leaves "
                        f"out interpreter start-up and imports: {rtf_runtime:.0f}x)")
    warm = [s for s in samples if s.mode == "library-warmup"]
    lines += ["", f"Target: at least {TARGET_RTF:.0f}x faster than real time.", *verdicts, ""]
    lines.append("Cold costs in a fresh interpreter (s; each import after numpy): "
                 + ", ".join(f"{k} {v:.2f}" for k, v in overhead.items())
                 + "; first in-process run " + ", ".join(f"({s.variant}) {s.wall_s:.2f}" for s in warm) + ".")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5, help="in-process runs per variant (default 5)")
    p.add_argument("--out", default="runs/bench_throughput", help="report folder (default runs/bench_throughput)")
    p.add_argument("--scenario", default=str(ROOT / "configs/scenarios/telemax_lab.yaml"), help="scenario YAML")
    p.add_argument("--config", default=str(ROOT / "configs/telemax.yaml"), help="pipeline config YAML")
    p.add_argument("--cli-repeats", type=int, default=1, help="gslam map subprocess runs per variant (default 1)")
    p.add_argument("--isam2", action="store_true", help="also time backend.optimizer=isam2")
    p.add_argument("-v", "--verbose", action="store_true", help="log each run")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        res = bench_throughput(args.scenario, args.config, args.repeats, args.out, args.isam2, args.cli_repeats)
    except (GslamError, ValidationError) as e:
        print(f"bench throughput: error: {e}", file=sys.stderr)
        return 1
    print(res.markdown)
    print("wrote " + ", ".join(str(f) for f in res.files))
    return 0

