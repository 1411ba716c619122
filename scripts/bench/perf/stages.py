"""The in-process sections of the ``perf`` bench.

Sections (every figure is the median of ``--repeats`` runs unless stated):

* ``ratio``: on ``telemax_lab`` (seed 1), the full gated pipeline
  (:func:`slam.pipeline.folder.run_map` with ``--gating on``: read, KISS-ICP,
  validation, graph, optimisation, evaluation, writing with plots) against
  KISS-ICP alone (:class:`slam.frontend.kiss.ScanMatcher` over the same scans,
  points prepared the same way), taking turns in this one process, with
  and without plots; the real-time factor (data seconds per wall second) and
  the pipeline's split into reading, front-end, validation, graph building,
  optimisation, writing; and ``gslam map`` as a command (imports included).
* ``growth``: the looping scenario ``telemax_loop`` simulated with
  ``robot.laps`` laps (one lap about 4 min) into ``--cache`` once, then each
  mapped with gating on in a fresh subprocess: wall time of the command
  (imports included) and of ``run_map``, and peak resident memory
  (``ru_maxrss`` of that child); the cost per scan, against the shortest
  run's (target at most 1.1 for 10 laps against 1), and split by stage. A
  least-squares line through (data seconds, wall seconds) and (data
  seconds, peak MiB) gives the slope; the per-scan cost of the longest run
  over the shortest shows whether growth is linear.
* ``isam2``: the incremental back-end over the longest loop run, keyframes
  every 0.5 s: the latency of each keyframe's step (build its factors,
  ``ISAM2.update``, read back the pose), median and p99 over the 1,000
  keyframes around graph sizes of 1k and 10k, for several relinearisation
  settings; then with the run's loop closures (``configs/telemax.yaml``'s
  ``loops``), each added at the keyframe that closes it.
* ``diagnosis``: time per step of :class:`validation.diagnosis.reiter.Diagnoser`
  on the shipped 5-sensor model (the observations of the ``telemax_lab``
  run) and on synthetic models of 4, 8, 16 and 32 components; cold (each
  pattern seen for the first time) and memoised (the same patterns again).

The machine is shared with other work, so the report states its load and
compares variants measured side by side.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import os
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scripts.bench.common import simulated, table
from scripts.bench.perf.speed import timed_env
from slam.config import load_config

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[3]
CONFIG = ROOT / "configs" / "telemax.yaml"
MODEL = ROOT / "configs" / "validation" / "telemax_model.yaml"
SEED = 1
STAGES = ("read", "frontend", "validation", "graph_build", "optimise", "write")
GROWTH_STAGES = ("frontend", "validation", "submaps", "loops", "optimise")
"""The stages the growth section splits the cost per scan into."""
# iSAM2 settings compared: label -> (relinearizeThreshold, relinearizeSkip, enablePartialRelinearizationCheck).
ISAM2_SETTINGS = {
    "GTSAM default (0.1, skip 10)": (0.1, 10, False),
    "partial check (0.1, skip 10)": (0.1, 10, True),
    "loose (0.5, skip 10)": (0.5, 10, False),
}
ISAM2_SIZES = (1_000, 10_000)


def _rows(header: list[str], rows: list[list[str]]) -> list[str]:
    """A Markdown table as lines (the report is a list of lines)."""
    return table(header, rows).rstrip("\n").split("\n")


@dataclass
class Report:
    """Rows of the CSV (section, item, metric, value, unit) and the Markdown."""

    rows: list[tuple[str, str, str, float, str]] = field(default_factory=list)
    markdown: list[str] = field(default_factory=list)

    def add(self, section: str, item: str, metric: str, value: float, unit: str) -> None:
        self.rows.append((section, item, metric, float(value), unit))

    def csv_text(self) -> str:
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(["section", "item", "metric", "value", "unit"])
        writer.writerows((s, i, m, f"{v:.6g}", u) for s, i, m, v, u in self.rows)
        return out.getvalue()


# --- ratio and real-time factor ------------------------------------------------


def kiss_icp_alone(scans, config) -> float:
    """Wall time (s) of KISS-ICP over every scan, points prepared as the
    pipeline prepares them."""
    from slam.frontend.kiss import ScanMatcher, ScanProjector

    start = time.perf_counter()
    matcher = ScanMatcher(config, scans.range_max)
    project = ScanProjector(scans.angles, config.min_range_m, matcher.max_range)
    for ranges in scans.ranges:
        matcher.register(project(ranges))
    return time.perf_counter() - start


RATIO_VARIANTS = {"gating on": ["validation.mode=on"], "gating on, no plots": ["validation.mode=on", "output.plots=false"]}


def bench_ratio(report: Report, cache: Path, out: Path, repeats: int) -> None:
    from slam.readers.read import read_recording
    from slam.pipeline.folder import run_map

    run = simulated(cache, "telemax_lab", SEED)
    configs = {name: load_config(CONFIG, sets) for name, sets in RATIO_VARIANTS.items()}
    frontend = configs["gating on"].frontend
    scans = read_recording(run, configs["gating on"].input).scans
    for cfg in configs.values():
        run_map(run, cfg, out / "map")  # warm-up: lazy imports, caches
    icp, duration = [], 0.0
    walls = {name: [] for name in configs}
    stages = {name: {s: [] for s in STAGES + ("other",)} for name in configs}
    for _ in range(repeats):  # taking turns, so load from elsewhere hits all alike
        icp.append(kiss_icp_alone(scans, frontend))
        for name, cfg in configs.items():
            t = time.perf_counter()
            result = run_map(run, cfg, out / "map")
            walls[name].append(time.perf_counter() - t)
            duration = result.metrics["duration_s"]
            timings = result.metrics["timings_s"]
            for s in STAGES:
                stages[name][s].append(timings[s])
            # Keyframes, measurements, evaluation: the rest of the wall time.
            stages[name]["other"].append(walls[name][-1] - sum(timings[s] for s in STAGES))
    alone = statistics.median(icp)
    report.add("ratio", "kiss_icp_alone", "wall", alone, "s")
    rows, split_rows = [], []
    for name in configs:
        wall = statistics.median(walls[name])
        ratio = statistics.median(w / a for w, a in zip(walls[name], icp))
        split = {s: statistics.median(v) for s, v in stages[name].items()}
        report.add("ratio", name, "pipeline_wall", wall, "s")
        report.add("ratio", name, "ratio", ratio, "x")
        report.add("ratio", name, "realtime_factor", duration / wall, "x")
        for s, v in split.items():
            report.add("ratio", name, f"stage_{s}", v, "s")
        rows.append([name, f"{wall:.2f}", f"{alone:.2f}", f"{ratio:.2f}×", f"{duration / wall:.0f}×"])
        split_rows.append([name] + [f"{split[s]:.3f}" for s in STAGES + ("other",)])
    report.markdown += [
        f"## Gated pipeline vs KISS-ICP alone (telemax_lab, {duration:.1f} s, {len(scans):,} scans)", "",
        f"Median of {repeats} runs each, taking turns in one process. The pipeline is `run_map` (the library form "
        "of `gslam map`) with `--gating on`: reading the bag, KISS-ICP, validation, graph, optimisation, "
        "evaluation and writing the result folder (`map.ply`, the validation log, and the plots unless stated). "
        "KISS-ICP alone is the same scan matcher over the same scans, already in memory.", "",
    ] + _rows(["variant", "pipeline [s]", "KISS-ICP alone [s]", "ratio (target ≤ 1.3)", "RTF (target ≥ 100×)"],
               rows) + ["", "Split of the pipeline's wall time [s]:", ""] + _rows(
        ["variant", "read", "front-end (KISS-ICP)", "validation", "graph build", "optimise", "write", "other"],
        split_rows,
    ) + [""]


def bench_cli(report: Report, cache: Path, out: Path, repeats: int) -> None:
    """``gslam map`` as a command in a fresh process: imports included, the
    bytecode cached (:data:`scripts.bench.perf.speed.BYTECODE_ENV`) by an
    untimed run first."""
    run = simulated(cache, "telemax_lab", SEED)
    walls = []
    for k in range(repeats + 1):
        cmd = [sys.executable, "-m", "slam.cli", "map", str(run), "--config", str(CONFIG),
               "--out", str(out / f"cli{k}"), "--gating", "on"]
        t = time.perf_counter()
        subprocess.run(cmd, check=True, cwd=ROOT, env=timed_env(), capture_output=True)
        if k:
            walls.append(time.perf_counter() - t)
    duration = json.loads((out / "cli1" / "metrics.json").read_text())["duration_s"]
    wall = statistics.median(walls)
    report.add("ratio", "telemax_lab", "cli_wall", wall, "s")
    report.add("ratio", "telemax_lab", "cli_realtime_factor", duration / wall, "x")
    report.markdown += [f"As a command (`gslam map --gating on`, fresh interpreter, imports included): "
                        f"{wall:.2f} s, {duration / wall:.0f}× real time (median of {repeats}).", ""]


# --- growth with run length -------------------------------------------------------


def _child_map(run: str, out: str) -> None:
    """In a fresh process: map one run and print its metrics as JSON."""
    from slam.pipeline.folder import run_map

    t = time.perf_counter()
    result = run_map(run, load_config(CONFIG, ["validation.mode=on"]), out)
    m = result.metrics
    print(json.dumps({"wall_s": time.perf_counter() - t, "duration_s": m["duration_s"], "n_poses": m["n_poses"],
                      "n_scans": len(result.recording.scans), "timings_s": m["timings_s"]}))


def map_in_child(run: Path, out: Path) -> dict:
    """Map ``run`` in a fresh interpreter; its metrics, command wall time and
    peak resident memory (MiB, that child's ``ru_maxrss``)."""
    cmd = [sys.executable, "-m", "scripts.bench", "perf", "--child-map", str(run), str(out)]
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, env=timed_env(), stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    stdout = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise RuntimeError(f"mapping {run} failed with exit code {proc.returncode}")
    m = json.loads(stdout.strip().splitlines()[-1])
    m["command_s"] = time.perf_counter() - t
    m["peak_mib"] = usage.ru_maxrss / 1024  # Linux: KiB
    return m


def linear_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """Least-squares slope, intercept and R² of y over x."""
    slope, intercept = np.polyfit(x, y, 1)
    resid = y - (slope * x + intercept)
    total = np.sum((y - y.mean()) ** 2)
    return float(slope), float(intercept), float(1.0 - np.sum(resid**2) / total) if total > 0 else 1.0


def bench_growth(report: Report, cache: Path, out: Path, laps: list[int], repeats: int) -> None:
    rows, xs, walls, cmds, mems, n_scans, per_scan = [], [], [], [], [], [], []
    for n in laps:
        run = simulated(cache, "telemax_loop", SEED, n)
        runs = [map_in_child(run, out / f"loop_{n}") for _ in range(repeats)]
        med = {k: statistics.median(r[k] for r in runs) for k in ("wall_s", "command_s", "peak_mib")}
        duration = runs[0]["duration_s"]
        scans = runs[0]["n_scans"]
        xs.append(duration), walls.append(med["wall_s"]), cmds.append(med["command_s"])
        mems.append(med["peak_mib"]), n_scans.append(scans)
        for k, unit in (("wall_s", "s"), ("command_s", "s"), ("peak_mib", "MiB")):
            report.add("growth", f"laps_{n}", k, med[k], unit)
        report.add("growth", f"laps_{n}", "duration_s", duration, "s")
        report.add("growth", f"laps_{n}", "keyframes", runs[0]["n_poses"], "")
        stage = {k: statistics.median(r["timings_s"].get(k, 0.0) for r in runs) for k in GROWTH_STAGES}
        for k, v in stage.items():
            report.add("growth", f"laps_{n}", f"stage_{k}", v, "s")
        per_scan.append(med["wall_s"] / scans)
        rows.append([str(n), f"{duration / 60:.1f}", f"{scans:,}", f"{runs[0]['n_poses']:,}", f"{med['wall_s']:.1f}",
                     f"{med['command_s']:.1f}", f"{duration / med['command_s']:.0f}×", f"{med['peak_mib']:.0f}",
                     f"{1e3 * med['wall_s'] / scans:.3f}", f"{per_scan[-1] / per_scan[0]:.2f}",
                     *(f"{1e3 * stage[k] / scans:.3f}" for k in GROWTH_STAGES)])
    x = np.array(xs) / 3600.0
    w_slope, w_icpt, w_r2 = linear_fit(x, np.array(walls))
    m_slope, m_icpt, m_r2 = linear_fit(x, np.array(mems))
    for name, v, unit in (("wall_slope", w_slope, "s/h"), ("wall_intercept", w_icpt, "s"), ("wall_r2", w_r2, ""),
                          ("mem_slope", m_slope, "MiB/h"), ("mem_intercept", m_icpt, "MiB"), ("mem_r2", m_r2, "")):
        report.add("growth", "fit", name, v, unit)
    growth = per_scan[-1] / per_scan[0]
    report.add("growth", "fit", "per_scan_longest_over_shortest", growth, "x")
    report.markdown += [
        "## Growth with run length (telemax_loop, gating on)", "",
        f"Each run mapped in a fresh process, median of {repeats}; `run_map` is the pipeline in-process, "
        "`command` adds interpreter start and imports; peak memory is that process's maximum resident set; "
        "the cost per scan is `run_map`'s, and per stage that stage's seconds over the scans (the front-end "
        "runs in a second process).", "",
    ] + _rows(["laps", "data [min]", "scans", "keyframes", "run_map [s]", "command [s]", "RTF (command)",
                "peak memory [MiB]", "ms per scan", f"per scan / {laps[0]} lap(s) (target ≤ 1.1)",
                *(f"{k} ms per scan" for k in GROWTH_STAGES)], rows) + [
        "",
        f"Least-squares fit over data hours h: wall = {w_slope:.1f} s/h · h + {w_icpt:.1f} s (R² = {w_r2:.4f}); "
        f"peak memory = {m_slope:.0f} MiB/h · h + {m_icpt:.0f} MiB (R² = {m_r2:.4f}). "
        f"Time per scan, longest run over shortest: {growth:.2f} "
        f"({'within' if growth <= 1.1 else 'above'} the target 1.1).", "",
    ]


# --- iSAM2 latency ---------------------------------------------------------------


def bench_isam2(report: Report, cache: Path, out: Path, laps: int, repeats: int) -> None:
    import gtsam

    from slam.graph.backend import optimise
    from slam.outputs.evaluation import evaluate
    from slam.outputs.loops import loop_metrics
    from slam.pipeline.core import Mapping
    from slam.readers.read import read_recording

    run = simulated(cache, "telemax_loop", SEED, laps)
    cfg = load_config(CONFIG, ["validation.mode=on", "backend.optimizer=isam2", "keyframes.period_s=0.5",
                              "loops.enabled=true"])
    pipe = Mapping(read_recording(run, cfg.input), cfg, source=run)
    pipe.match_scans()
    pipe.build_measurements()
    pipe.validate()
    meas, n = pipe.measurements, len(pipe.measurements)
    pose0 = pipe.initial_pose()
    batch = optimise(meas, pose0, cfg.backend.model_copy(update={"optimizer": "batch"}), pipe.weights).trajectory
    gt, ev = pipe.recording.groundtruth, cfg.evaluation

    def ate(traj) -> float:
        return evaluate(traj, gt, ev.rpe_deltas_m, ev.max_time_offset_s)["ate_rmse_m"]

    report.add("isam2", "batch", "ate_rmse", ate(batch), "m")
    start = time.perf_counter()
    pipe.judge_loops(pipe.find_loops())
    loops_s = time.perf_counter() - start
    lm = loop_metrics(pipe.loop_search, pipe.loop_observation, pipe.keyframe_truth(), cfg.evaluation)
    batch_loops = optimise(meas, pose0, cfg.backend.model_copy(update={"optimizer": "batch"}), pipe.weights,
                           loops=pipe.loop_factors).trajectory
    rows = []
    settings = [(label, setting, None) for label, setting in ISAM2_SETTINGS.items()]
    settings += [(f"{label}, with loops", setting, pipe.loop_factors)
                 for label, setting in ISAM2_SETTINGS.items() if "loose" not in label]
    for label, (threshold, skip, partial), loops in settings:
        stats: dict[str, list[float]] = {}
        for _ in range(repeats):
            params = gtsam.ISAM2Params()
            params.setRelinearizeThreshold(threshold)
            params.relinearizeSkip = skip
            params.enablePartialRelinearizationCheck = partial
            result = optimise(meas, pose0, cfg.backend, pipe.weights, isam2_params=params, loops=loops)
            lat = result.update_latencies_s
            stats.setdefault("total", []).append(result.build_time_s + result.optimise_time_s)
            for size in ISAM2_SIZES:
                window = lat[max(size - 500, 0) : size + 500] if size < n else lat[-1000:]
                stats.setdefault(f"median_{size}", []).append(float(np.median(window)))
                stats.setdefault(f"p99_{size}", []).append(float(np.percentile(window, 99)))
            stats.setdefault("max", []).append(float(lat.max()))
        med = {k: statistics.median(v) for k, v in stats.items()}
        est = result.trajectory
        ref = batch if loops is None else batch_loops
        dev, err = float(np.max(np.hypot(est.x - ref.x, est.y - ref.y))), ate(est)
        for k, v in med.items():
            report.add("isam2", label, k, v * (1 if k == "total" else 1e3), "s" if k == "total" else "ms")
        report.add("isam2", label, "max_deviation_from_batch", dev, "m")
        report.add("isam2", label, "ate_rmse", err, "m")
        rows.append([label] + [f"{1e3 * med[f'{q}_{s}']:.2f}" for s in ISAM2_SIZES for q in ("median", "p99")]
                    + [f"{1e3 * med['max']:.1f}", f"{med['total']:.1f}", f"{err:.3f}", f"{dev:.2f}"])
    report.markdown += [
        f"## iSAM2 per-keyframe latency (telemax_loop, {laps} laps, {n:,} keyframes every 0.5 s)", "",
        "One keyframe's step as it runs online: build its factors, `ISAM2.update`, read back the pose for the "
        f"next prediction. Statistics over the 1,000 keyframes around each graph size, median of {repeats} runs.", "",
    ] + _rows(["relinearisation (threshold, skip)", "1k: median [ms]", "1k: p99 [ms]", "10k: median [ms]",
                "10k: p99 [ms] (target < 20)", "max [ms]", "whole run [s]", "ATE [m]", "max distance to batch [m]"],
               rows) + ["", f"Batch (Levenberg-Marquardt) over the same graph: ATE {ate(batch):.3f} m; with the loops "
                         f"{ate(batch_loops):.3f} m. Loop closing kept {lm['accepted']:,} of {lm['found']:,} loops "
                         f"({lm.get('wrong_accepted', 0)} of them wrong against ground truth) in {loops_s:.1f} s.", ""]


# --- diagnosis ------------------------------------------------------------------


def synthetic_model(n: int):
    """A model of ``n`` components C0..C{n-1}: relations between neighbours on
    a ring and two apart, each with failure masking (CORR)."""
    from validation.diagnosis.model import SystemModel

    comps = [f"C{i}" for i in range(n)]
    relations = {f"r{i}_{(i + d) % n}": (comps[i], comps[(i + d) % n]) for d in (1, 2) for i in range(n)
                 if n > 2 * d or d == 1}
    masking = [{"relation": r, "corr": True, "masking_prob": 0.05} for r in relations]
    return SystemModel.model_validate({"components": comps, "relations": relations, "failure_masking": masking})


def synthetic_patterns(model, count: int, seed: int = 0) -> list[dict]:
    """Distinct observation patterns: 0-2 faulty components; a relation
    touching one shows no_match with probability 0.8."""
    from validation.diagnosis.model import Observation

    rng = np.random.default_rng(seed)
    seen, out = set(), []
    for _ in range(count * 20):
        faulty = set(rng.choice(model.components, size=rng.integers(0, 3), replace=False))
        obs = {r: (Observation.NO_MATCH if (a in faulty or b in faulty) and rng.random() < 0.8 else Observation.MATCH)
               for r, (a, b) in model.relations.items()}
        key = frozenset(obs.items())
        if key not in seen:
            seen.add(key)
            out.append(obs)
        if len(out) == count:
            break
    return out


def time_diagnosis(model, patterns: list[dict], repeats: int) -> tuple[float, float]:
    """Median time per step (s): cold (a fresh diagnoser, every pattern new)
    and memoised (the same patterns again)."""
    from validation.diagnosis.reiter import Diagnoser

    cold, warm = [], []
    for _ in range(repeats):
        with Diagnoser(model) as d:
            t = time.perf_counter()
            for obs in patterns:
                d.diagnose(obs)
            cold.append((time.perf_counter() - t) / len(patterns))
            t = time.perf_counter()
            for obs in patterns:
                d.diagnose(obs)
            warm.append((time.perf_counter() - t) / len(patterns))
    return statistics.median(cold), statistics.median(warm)


def bench_diagnosis(report: Report, cache: Path, out: Path, repeats: int) -> None:
    from slam.config import validation_sections
    from slam.pipeline.folder import run_map

    rows = []
    cfg = load_config(CONFIG, ["validation.mode=on", "output.plots=false"])
    model = validation_sections(cfg)[0].model
    result = run_map(simulated(cache, "telemax_lab", SEED), cfg, out / "diag")
    olog = result.validation.observer_log
    steps = [olog.observations(k) for k in range(len(result.validation.step_t))]
    distinct = list({frozenset(o.items()): o for o in steps}.values())
    cold, _ = time_diagnosis(model, distinct, repeats)
    _, warm = time_diagnosis(model, steps, repeats)
    rows.append(["telemax (5 sensors), observations of telemax_lab", f"{len(distinct)} of {len(steps):,} steps",
                 f"{1e3 * cold:.3f}", f"{1e3 * warm:.4f}"])
    report.add("diagnosis", "telemax_5", "cold_per_step", 1e3 * cold, "ms")
    report.add("diagnosis", "telemax_5", "memoised_per_step", 1e3 * warm, "ms")
    for n in (4, 8, 16, 32):
        model = synthetic_model(n)
        patterns = synthetic_patterns(model, 200)
        cold, warm = time_diagnosis(model, patterns, repeats)
        report.add("diagnosis", f"synthetic_{n}", "cold_per_step", 1e3 * cold, "ms")
        report.add("diagnosis", f"synthetic_{n}", "memoised_per_step", 1e3 * warm, "ms")
        rows.append([f"synthetic, {n} components, {len(model.relations)} relations", f"{len(patterns)} patterns",
                     f"{1e3 * cold:.3f}", f"{1e3 * warm:.4f}"])
    report.markdown += [
        "## Diagnosis time per step", "",
        "Cold: a fresh diagnoser meets each pattern for the first time (SAT calls, hitting sets). Memoised: the "
        "pattern was seen before. Synthetic models: a ring of components with relations to the neighbours one "
        f"and two apart, each with failure masking; patterns with 0–2 faulty components. Median of {repeats}.", "",
    ] + _rows(["model", "patterns", "cold [ms] (target < 10 at 32)", "memoised [ms] (target < 0.1)"], rows) + [""]


# --- main -------------------------------------------------------------------------
