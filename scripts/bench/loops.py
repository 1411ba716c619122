"""Loop closing benchmark: a Markdown report.

    python -m scripts.bench loops [--out loops.md] [--cache DIR] [--seeds 1 2 ... 10]
                                  [--sections telemax false_loops corridor runtime]
                                  [--repeats N] [--root DATA]

Sections:

* ``telemax``: ``telemax_lab`` for each seed, mapped with ``configs/telemax.yaml``
  by every variant of ``configs/variants.yaml`` (ungated, gated, oracle,
  robust kernels), each without and with loop closing (``loops.enabled``).
  The run is read and scan-matched once per seed. Aligned ATE mean +- std,
  and on how many seeds loops made the variant better. The loop parameters
  were chosen on seeds 11-13 (``configs/telemax.yaml``); report on others.
* ``false_loops``: wrong loops (slam.loops.inject: shifted copies of genuine
  loops and pairs far apart, 1-3 m and 3-15 deg off, each claiming a genuine
  loop's information) added to the loops found, ``--false-fraction`` of
  them (0.25: one wrong loop for three genuine), before the loop observer;
  how many survive and how much the ATE moves, on ``telemax_lab`` (gated)
  and the CARMEN logs (``configs/datasets/carmen.yaml``). Where the config
  takes its loops from the submaps (``loops.source: submaps``, both shipped
  ones), the wrong loops join the submap graph's loop constraints before
  graduated non-convexity judges them, as a wrong match would.
* ``corridor``: libRSF Corridor (``configs/datasets/librsf_corridor.yaml``),
  ATE without loops, with the file's loops through the loop observer, with
  each check alone, with none, and with the loops that agree with ground
  truth (oracle).
* ``runtime``: what loop closing adds to a whole ``gslam map`` run (the
  shipped config, plots and writing included): runs with and without loops
  taking turns, ``--repeats`` each, medians; the loop stage's own time
  (detection, verification, the observer) over the run without loops.

Times are wall-clock seconds on a machine shared with other work: compare
within one run.
"""

from __future__ import annotations

import argparse
import logging
import math
import statistics
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from scripts.bench.common import carmen_log, publish, quiet_logging
from slam.commands.compare import load_variants
from slam.config import load_config
from slam.results.atomic import write_text
from slam.readers.datasets import data_root
from slam.pipeline.config_fit import check_fit
from slam.pipeline.core import Mapping
from slam.pipeline.folder import MappingPipeline
from slam.readers.read import read_recording

log = logging.getLogger(__name__)

ROOT = Path(__file__).resolve().parents[2]
TELEMAX = ROOT / "configs" / "telemax.yaml"
CARMEN = ROOT / "configs" / "datasets" / "carmen.yaml"
CORRIDOR = ROOT / "configs" / "datasets" / "librsf_corridor.yaml"
VARIANTS = ROOT / "configs" / "variants.yaml"
LAB = ROOT / "configs" / "scenarios" / "telemax_lab.yaml"
CARMEN_LOGS = ("intel", "freiburg-079", "aces")


@dataclass
class Report:
    lines: list[str] = field(default_factory=list)

    def table(self, header: list[str], rows: list[list[str]]) -> None:
        self.lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        self.lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
        self.lines.append("")


def simulated(cache: Path, seed: int) -> Path:
    """``telemax_lab`` with ``seed``, simulated into ``cache`` once."""
    from slam.sim import load_scenario, simulate_scenario

    out = cache / f"telemax_lab_s{seed}"
    if not (out / "truth.json").exists():
        scenario = load_scenario(LAB)
        simulate_scenario(scenario.model_copy(update={"seed": seed}), out)
    return out


def mapped(path: Path, config_path: Path, overrides: list[str], shared: dict, wrong_fraction: float = 0.0,
           seed: int = 0) -> Mapping:
    """One variant mapped in memory (no result folder), reusing the
    recording and front-end in ``shared``; ``wrong_fraction``: wrong loops
    added before they are judged, as a fraction of the loops found: to the
    submap graph's before its GNC where submaps close the loops, else to
    what the loop search found."""
    cfg = load_config(config_path, ["output.plots=false", "output.progress=false", *overrides])
    if "rec" not in shared:
        shared["rec"] = read_recording(path, cfg.input)
    check_fit(shared["rec"], cfg, path)
    core = Mapping(shared["rec"], cfg, shared.get("fe"), path)
    core.match_scans()
    shared["fe"] = core.frontend
    core.build_measurements()
    core.validate()
    core.learn_odometry_scale()
    core.recheck()

    def add_wrong(constraints: list) -> list:
        genuine = [c for c in constraints if c.kind == "loop"]
        count = math.ceil(wrong_fraction * len(genuine) / (1.0 - wrong_fraction)) if genuine else 0
        return wrong_submap_loops(genuine, count, seed)

    core.build_submaps(add_wrong if wrong_fraction > 0 else None)
    search = core.find_loops()
    if wrong_fraction > 0 and search is not None and search.loops and not cfg.submaps.enabled:
        from slam.loops.inject import wrong_loops

        count = math.ceil(wrong_fraction * len(search.loops) / (1.0 - wrong_fraction))
        search.loops = search.loops + wrong_loops(search.chain, search.loops, count, seed)
    core.judge_loops(search)
    core.optimise()
    core.evaluate()
    return core


def wrong_submap_loops(genuine: list, count: int, seed: int) -> list:
    """``count`` copies of genuine submap loop constraints, shifted as
    :func:`slam.loops.inject.wrong_loops` shifts its copies
    (:func:`~slam.loops.inject.wrong_shift`), with the genuine one's
    information; score -1 marks them."""
    from dataclasses import replace

    from validation.base.geometry import compose
    from slam.loops.inject import wrong_shift

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        model = genuine[int(rng.integers(len(genuine)))]
        out.append(replace(model, delta=compose(np.asarray(model.delta, float), wrong_shift(rng)), score=-1.0))
    return out


def stats(values: list[float]) -> str:
    return f"{np.mean(values):.3f} ± {np.std(values):.3f}"


# --- telemax ---------------------------------------------------------------------


def bench_telemax(report: Report, cache: Path, seeds: list[int]) -> None:
    variants = load_variants(VARIANTS)
    ate: dict[tuple[str, bool], list[float]] = {}
    loops: dict[str, list[dict]] = {}
    for seed in seeds:
        run, shared = simulated(cache, seed), {}
        for name, overrides in variants.items():
            for with_loops in (False, True):
                pipe = mapped(run, TELEMAX, [*overrides, f"loops.enabled={str(with_loops).lower()}"], shared)
                ate.setdefault((name, with_loops), []).append(pipe.metrics["ate_rmse_m"])
                if with_loops:
                    loops.setdefault(name, []).append(pipe.metrics["loops"])
        log.info("telemax seed %d done", seed)
    rows = []
    for name in variants:
        off, on = ate[(name, False)], ate[(name, True)]
        better = sum(b < a for a, b in zip(off, on))
        ls = loops[name]
        rows.append([
            name, stats(off), stats(on), f"{statistics.median(b / a for a, b in zip(off, on)):.3f}",
            f"{better}/{len(off)}", f"{np.mean([m['found'] for m in ls]):.1f}", f"{np.mean([m['accepted'] for m in ls]):.1f}",
            str(sum(m.get("wrong_accepted", 0) for m in ls)), str(sum(m.get("true_rejected", 0) for m in ls)),
        ])
    report.lines += [f"### telemax_lab, seeds {seeds[0]}-{seeds[-1]}: every variant without and with loop closing", ""]
    report.table(["variant", "ATE without loops [m]", "ATE with loops [m]", "with / without (median)",
                  "seeds better with loops", "loops found (mean)", "kept (mean)", "wrong kept (total)",
                  "right rejected (total)"], rows)
    off, on = ate[("gated", False)], ate[("gated", True)]
    report.lines += ["Per seed, gated: " + ", ".join(f"{s}: {a:.3f} → {b:.3f}" for s, a, b in zip(seeds, off, on)), ""]


# --- false loops ---------------------------------------------------------------------


def bench_false_loops(report: Report, cache: Path, seeds: list[int], root: Path, fraction: float) -> None:
    rows = []
    cases = [(f"telemax_lab s{s}", simulated(cache, s), TELEMAX, ["validation.mode=on", "loops.enabled=true"]) for s in seeds]
    for name in CARMEN_LOGS:
        path = carmen_log(root, name)
        if path.is_file():
            cases.append((name, path, CARMEN, ["loops.enabled=true"]))
    for k, (label, path, config, overrides) in enumerate(cases):
        shared = {}
        clean = mapped(path, config, overrides, shared)
        dirty = mapped(path, config, overrides, shared, wrong_fraction=fraction, seed=1000 + k)
        if dirty.submaps is not None:  # the wrong loops went to the submap graph's GNC
            injected = [c for c in [*dirty.submaps.of_kind("loop"), *dirty.submaps.dropped_of_kind("loop")]
                        if c.score == -1.0]
            kept = sum(c.score == -1.0 for c in dirty.submaps.of_kind("loop"))
            reasons = {"gnc": len(injected) - kept} if len(injected) > kept else {}
        else:
            injected = [v for v in dirty.loop_observation.verdicts if v.loop.source == "injected"]
            kept = sum(v.accepted for v in injected)
            reasons = {}
            for v in injected:
                if not v.accepted:
                    reasons[v.reason] = reasons.get(v.reason, 0) + 1
        a, b = clean.metrics["ate_rmse_m"], dirty.metrics["ate_rmse_m"]
        found = clean.metrics["loops"]["found"]
        share = f"{len(injected) / (found + len(injected)):.0%}" if found + len(injected) else "–"
        rows.append([label, str(found), f"{len(injected)} ({share})", str(kept),
                     " ".join(f"{r} {n}" for r, n in sorted(reasons.items())), f"{a:.3f}", f"{b:.3f}",
                     f"{100.0 * (b - a) / a:+.1f} %"])
        log.info("false loops %s done", label)
    report.lines += [f"### Injected wrong loops ({fraction:.0%} of all loops)", ""]
    report.table(["run", "loops found", "wrong loops added", "wrong kept", "rejected by", "ATE [m]",
                  "ATE with wrong loops [m]", "change"], rows)


# --- libRSF Corridor ---------------------------------------------------------------


def bench_corridor(report: Report, root: Path) -> None:
    path = root / "librsf" / "Corridor_Input.txt"
    if not path.is_file():
        report.lines += [f"libRSF Corridor not found at {path}; skipped.", ""]
        return
    cases = {
        "no loops": ["loops.enabled=false"],
        "loops, observer (chain check, PCM, support)": [],
        "loops, chain check only": ["loops.observer.pcm=false", "loops.observer.min_support=0"],
        "loops, PCM only": ["loops.observer.chain_check=false"],
        "loops, no check": ["loops.observer.chain_check=false", "loops.observer.pcm=false", "loops.observer.min_support=0"],
        "loops, observer, unscaled chain": ["loops.observer.chain_scale_from_loops=false"],
        "loops, observer + GNC": ["loops.gnc=true"],
        "loops, oracle (agree with ground truth)": ["validation.mode=oracle"],
    }
    rows, shared = [], {}
    for label, overrides in cases.items():
        if "oracle" in label:
            overrides = overrides + ["validation.model={components: [ODO_DIST, ODO_YAW, ODO, IMU_GYRO, IMU_YAW, SM_DIST, SM_LAT, SM_YAW, SM, "
                                     "GPS, LOOP]}",
                                     "validation.observers.relations=[]", "validation.observers.magnetometer.enabled=false",
                                     "validation.observers.gps.enabled=false"]
        start = time.perf_counter()
        pipe = mapped(path, CORRIDOR, overrides, shared)
        elapsed = time.perf_counter() - start
        m = pipe.metrics
        lm = m.get("loops", {})
        rows.append([label, f"{m['ate_rmse_m']:.2f}", f"{m.get('rpe_trans_pct_10m', float('nan')):.2f}",
                     str(lm.get("found", "–")), str(lm.get("accepted", "–")), str(lm.get("wrong_accepted", "–")),
                     f"{pipe.timings.loops_s:.2f}", f"{elapsed:.1f}"])
    report.lines += ["### libRSF Corridor (loops from the file, weight ≥ 0.43)", ""]
    report.table(["loops", "ATE [m]", "RPE 10 m [%]", "loops", "kept", "wrong kept", "loop stage [s]", "run [s]"], rows)


# --- runtime ---------------------------------------------------------------------------


def bench_runtime(report: Report, cache: Path, root: Path, repeats: int) -> None:
    cases = [("telemax_lab s1 (gated)", simulated(cache, 1), TELEMAX, ["validation.mode=on"])]
    for name in CARMEN_LOGS:
        cases.append((name, carmen_log(root, name), CARMEN, []))
    cases.append(("libRSF Corridor", root / "librsf" / "Corridor_Input.txt", CORRIDOR, []))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, path, config, overrides in cases:
            if not path.exists():
                continue
            runs: dict[bool, list[float]] = {False: [], True: []}
            stage: list[float] = []
            for r in range(repeats):
                for with_loops in (False, True):
                    cfg = load_config(config, [*overrides, "output.progress=false", f"loops.enabled={str(with_loops).lower()}"])
                    pipe = MappingPipeline(path, cfg, Path(tmp) / f"{label}-{r}-{with_loops}".replace(" ", "_"))
                    result = pipe.run()
                    runs[with_loops].append(result.metrics["runtime_s"])
                    if with_loops:
                        stage.append(pipe.core.timings.loops_s)
            off, on, st = statistics.median(runs[False]), statistics.median(runs[True]), statistics.median(stage)
            rows.append([label, f"{off:.2f}", f"{on:.2f}", f"{100 * (on - off) / off:+.0f} %", f"{st:.2f}",
                         f"{100 * st / off:.0f} %"])
            log.info("runtime %s done", label)
    report.lines += [f"### Run time with and without loop closing (whole `gslam map` run in-process, plots and writing "
                     f"included; median of {repeats}, taking turns)", ""]
    report.table(["run", "without loops [s]", "with loops [s]", "added", "loop stage [s]",
                  "loop stage / run without (target < 30 %)"], rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--cache", type=Path, default=Path("runs/bench_loops_cache"))
    ap.add_argument("--seeds", type=int, nargs="+", default=list(range(1, 11)))
    ap.add_argument("--sections", nargs="+", default=["telemax", "false_loops", "corridor", "runtime"],
                    choices=["telemax", "false_loops", "corridor", "runtime"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--false-fraction", type=float, default=0.25)
    ap.add_argument("--root", type=Path, default=None, help="data root (default: $GSLAM_DATA or ../shared/data)")
    args = ap.parse_args(argv)
    quiet_logging("%(name)s: %(message)s")
    root = data_root() if args.root is None else args.root
    args.cache.mkdir(parents=True, exist_ok=True)
    report = Report(["## Loop closing benchmark", ""])
    if "telemax" in args.sections:
        bench_telemax(report, args.cache, args.seeds)
    if "false_loops" in args.sections:
        bench_false_loops(report, args.cache, args.seeds, root, args.false_fraction)
    if "corridor" in args.sections:
        bench_corridor(report, root)
    if "runtime" in args.sections:
        bench_runtime(report, args.cache, root, args.repeats)
    text = "\n".join(report.lines) + "\n"
    if args.out is not None:
        write_text(args.out, text)
    publish("loops", "Loop closing", text, argv)
    print(text)
    return 0

