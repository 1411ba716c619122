"""Gating against the robust kernels and the oracles, over many seeds of every
scenario and its fault-free twin.

    python -m scripts.bench gating [--scenarios NAME ...] [--seeds 1-10]
                                   [--variants NAME ...] [--config configs/telemax.yaml]
                                   [--workers 2] [--out runs/bench_gating] [--set KEY=VALUE ...]

Each (scenario, seed) is simulated once into ``OUT/inputs/`` and mapped with
every variant of ``configs/variants.yaml`` (the recording read and
scan-matched once, as ``gslam compare`` does). One row per run and variant
goes to ``OUT/results.csv``; finished (scenario, seed) pairs are skipped when
the command runs again with the same config, variants, overrides and code.
Each variant's result folder is ``OUT/maps-KEY/<scenario>-seed<N>/<variant>/``,
KEY naming the config, variants and overrides. ``OUT/summary.md`` has, per faulty scenario, the median and worst ATE of
each variant, the ratio of gated to the best robust kernel (the kernel with
the lowest median ATE on that scenario; per seed against that kernel's run
on the same seed) and to the tight oracle; per twin, gated against ungated
and the alarm fraction; and the detection delay and blame-end lag.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import logging
import math
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

from scripts.bench.common import KERNELS
from slam.compare import load_variants
from slam.config import load_config
from slam.io.atomic import write_text
from slam.pipeline import MappingPipeline

REPO = Path(__file__).resolve().parents[2]
SCENARIOS = REPO / "configs" / "scenarios"

# Each faulty scenario and its fault-free twin (same world and path, without
# the causes of the faults).
TWINS = {
    "telemax_lab": "telemax_lab_clean",
    "telemax_compass": "telemax_lab_clean",
    "corridor": "corridor_clean",
    "hall": "hall_clean",
    "compass_steel": "compass_steel_clean",
}
METRICS = (
    "ate_rmse_m", "yaw_rmse_deg", "alarm_fraction", "false_alarm_fraction", "isolation_precision",
    "isolation_recall", "detection_delay_median_s", "blame_end_lag_median_s", "faults_missed", "runtime_s",
)

log = logging.getLogger(__name__)


def parse_seeds(text: str) -> list[int]:
    """``"1-10"`` or ``"1,3,5"`` or ``"11-20,25"``."""
    seeds: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            seeds += list(range(int(a), int(b) + 1))
        else:
            seeds.append(int(part))
    return seeds


def _flat(metrics: dict) -> dict:
    """The figures of one run: delays are summarised over components."""
    row = {k: metrics.get(k) for k in METRICS if not k.endswith("_median_s")}
    for key in ("detection_delay", "blame_end_lag"):
        values = metrics.get(f"{key}_s")
        vals = [v for v in values.values() if v is not None] if isinstance(values, dict) else []
        row[f"{key}_median_s"] = float(np.median(vals)) if vals else None
    return row


def run_one(
    scenario: str, seed: int, config: str, variants: dict[str, list[str]], overrides: list[str], out: str, key: str
) -> list[dict]:
    """Simulate (if needed) and map one seed of one scenario with every variant."""
    from slam.sim import simulate

    out_dir = Path(out)
    run_dir = out_dir / "inputs" / f"{scenario}-seed{seed}"
    if not (run_dir / "truth.json").exists():
        simulate(SCENARIOS / f"{scenario}.yaml", run_dir, seed=seed)
    rows = []
    recording = frontend = frontend_cfg = None
    for name, ov in variants.items():
        cfg = load_config(config, [*overrides, *ov, "output.plots=false"])
        if frontend_cfg is not None and cfg.frontend != frontend_cfg:
            frontend = None
        pipe = MappingPipeline(run_dir, cfg, out_dir / f"maps-{key}" / f"{scenario}-seed{seed}" / name,
                               recording=recording, frontend=frontend)
        res = pipe.run()
        recording, frontend, frontend_cfg = pipe.recording, pipe.frontend, cfg.frontend
        rows.append({"scenario": scenario, "seed": seed, "variant": name, **_flat(res.metrics)})
    return rows


def _key(config: str, variants: dict, overrides: list[str]) -> str:
    """Names the results: the config, the variants, the overrides and the
    code (every module and config of the package), so a change of any
    gives new runs."""
    text = Path(config).read_text() + json.dumps(variants, sort_keys=True) + json.dumps(overrides)
    for path in sorted([*REPO.glob("slam/**/*.py"), *REPO.glob("validation/*.py"), *REPO.glob("configs/**/*.yaml")]):
        text += path.read_text()
    return hashlib.sha1(text.encode()).hexdigest()[:10]


def _read_rows(path: Path) -> list[dict]:
    if not path.exists():
        return []
    with path.open() as f:
        return list(csv.DictReader(f))


def _num(v) -> float:
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def summarise(rows: list[dict], variants: list[str]) -> str:
    """The markdown summary described in the module docstring."""
    ate: dict[tuple[str, str], dict[int, float]] = {}
    other: dict[tuple[str, str], dict[int, dict]] = {}
    for r in rows:
        key = (r["scenario"], r["variant"])
        ate.setdefault(key, {})[int(r["seed"])] = _num(r["ate_rmse_m"])
        other.setdefault(key, {})[int(r["seed"])] = r
    scenarios = sorted({r["scenario"] for r in rows}, key=lambda s: (s not in TWINS, s))
    lines = ["# Gating against robust kernels and oracles", ""]

    def med(values) -> float:
        v = [x for x in values if np.isfinite(x)]
        return float(np.median(v)) if v else math.nan

    # 1. ATE per variant: median [worst] over seeds.
    shown = [v for v in variants if any((s, v) in ate for s in scenarios)]
    lines += ["## ATE RMSE [m]: median over seeds [worst seed]", ""]
    lines += ["| scenario | seeds | " + " | ".join(shown) + " |", "|---|---|" + "---|" * len(shown)]
    for s in scenarios:
        n = len(ate.get((s, shown[0]), {}))
        cells = []
        for v in shown:
            vals = list(ate.get((s, v), {}).values())
            cells.append(f"{med(vals):.3f} [{max(vals):.3f}]" if vals else "–")
        lines.append(f"| {s} | {n} | " + " | ".join(cells) + " |")

    # 2. Faulty scenarios: gated against the best robust kernel and the tight oracle.
    faulty = [s for s in scenarios if s in TWINS]
    ratios = []
    if faulty and any((s, "gated") in ate for s in faulty):
        lines += ["", "## Faulty scenarios: gated against the best robust kernel and the tight oracle", ""]
        lines += [
            "| scenario | best kernel | gated / best kernel: median, worst | gated / oracle: median, worst | "
            "alarm fraction | false alarms | detection delay [s] | blame-end lag [s] |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for s in faulty:
            g = ate.get((s, "gated"), {})
            kernels = {k: med(ate[(s, k)].values()) for k in KERNELS if (s, k) in ate}
            if not g or not kernels:
                continue
            best = min(kernels, key=kernels.get)
            r_k = [g[i] / ate[(s, best)][i] for i in g if i in ate[(s, best)]]
            o = ate.get((s, "oracle"), {})
            r_o = [g[i] / o[i] for i in g if i in o]
            ratios.append(med(r_k))
            extra = other[(s, "gated")].values()
            cells = [
                f"{best} ({kernels[best]:.3f})",
                f"{med(r_k):.2f}, {max(r_k):.2f}",
                f"{med(r_o):.2f}, {max(r_o):.2f}" if r_o else "–",
            ]
            for col in ("alarm_fraction", "false_alarm_fraction", "detection_delay_median_s", "blame_end_lag_median_s"):
                vals = [_num(e.get(col)) for e in extra]
                cells.append(f"{med(vals):.3f}" if np.any(np.isfinite(vals)) else "–")
            lines.append(f"| {s} | " + " | ".join(cells) + " |")
        if ratios:
            gm = float(np.exp(np.mean(np.log(ratios))))
            lines += ["", f"Geometric mean over the faulty scenarios of the median gated / best-kernel ratio: **{gm:.2f}**."]

    # 3. Twins: gated against ungated, and alarms.
    twins = [s for s in scenarios if s not in TWINS]
    if twins and any((s, "gated") in ate for s in twins):
        lines += ["", "## Fault-free twins: gated against ungated", ""]
        lines += ["| twin | gated / ungated: median, worst | alarm fraction: median, worst |", "|---|---|---|"]
        for s in twins:
            g, u = ate.get((s, "gated"), {}), ate.get((s, "ungated"), {})
            r = [g[i] / u[i] for i in g if i in u]
            alarms = [_num(e.get("alarm_fraction")) for e in other.get((s, "gated"), {}).values()]
            cell_r = f"{med(r):.3f}, {max(r):.3f}" if r else "–"
            lines.append(f"| {s} | {cell_r} | {med(alarms):.4f}, {np.nanmax(alarms):.4f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenarios", nargs="+", default=sorted(set(TWINS) | set(TWINS.values())))
    p.add_argument("--seeds", default="1-10")
    p.add_argument("--variants", nargs="+", default=None, help="default: every variant of configs/variants.yaml")
    p.add_argument("--variants-file", default=str(REPO / "configs" / "variants.yaml"))
    p.add_argument("--config", default=str(REPO / "configs" / "telemax.yaml"))
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", default="runs/bench_gating")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override for every variant")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")

    variants = load_variants(args.variants_file, args.variants)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    key = _key(args.config, variants, args.set)
    results = out / f"results-{key}.csv"
    rows = _read_rows(results)
    done = {(r["scenario"], int(r["seed"])) for r in rows}
    todo = [(s, i) for s in args.scenarios for i in parse_seeds(args.seeds) if (s, i) not in done]
    print(f"{len(todo)} runs to do, {len(done)} done ({results})", flush=True)
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        futures = {pool.submit(run_one, s, i, args.config, variants, args.set, str(out), key): (s, i) for s, i in todo}
        for fut in as_completed(futures):
            s, i = futures[fut]
            try:
                new = fut.result()
            except Exception as e:  # a failed run is reported, the others go on
                print(f"  {s} seed {i}: failed: {e}", flush=True)
                continue
            rows += new
            fieldnames = ["scenario", "seed", "variant", *METRICS]
            text = ",".join(fieldnames) + "\n" + "".join(
                ",".join("" if r.get(k) is None else str(r.get(k)) for k in fieldnames) + "\n" for r in rows
            )
            write_text(results, text)
            gated = next((r for r in new if r["variant"] == "gated"), None)
            note = f"gated {gated['ate_rmse_m']:.3f} m" if gated else ""
            print(f"  {s} seed {i} done ({time.perf_counter() - start:.0f} s) {note}", flush=True)
    chosen = [r for r in rows if r["scenario"] in args.scenarios and int(r["seed"]) in parse_seeds(args.seeds)]
    summary = summarise(chosen, list(variants))
    write_text(out / f"summary-{key}.md", summary)
    print(summary)
    return 0

