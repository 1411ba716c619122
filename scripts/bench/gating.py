"""Gating against the robust kernels and the oracles, over many seeds of every
scenario and its fault-free twin.

    python -m scripts.bench gating [--scenarios NAME ...] [--seeds 1-10]
                                   [--variants NAME ...] [--variants-file configs/variants.yaml]
                                   [--config configs/telemax.yaml] [--workers 2] [--out DIR] [--set KEY=VALUE ...]

The sweep runs through ``gslam ablate``'s library (:mod:`slam.commands.ablate`):
each (scenario, seed) is simulated once and mapped with every variant of
``--variants-file``, the jobs of one input sharing its reading and scan
matching; ``--out`` keeps the sweep folder (a later run into it skips the
finished jobs), by default it is temporary. The page has, per faulty
scenario, the median and worst ATE of each variant, the ratio of gated to
the best robust kernel (the kernel with the lowest median ATE on that
scenario; per seed against that kernel's run on the same seed) and to the
tight oracle; per twin, gated against ungated and the alarm fraction; and
the detection delay and blame-end lag. With a variant ``gated_no_loops``
(``configs/bench_variants.yaml``: the same without submaps and loops), a
section on what loop closing does: per scenario, gated with loops against
gated without (median ratio, and on how many seeds it is worse), and the
loops kept with how many are wrong (the simulator knows the true poses).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import tempfile
from pathlib import Path

import numpy as np
import yaml

from scripts.bench.common import KERNELS, include_in_readme, publish
from slam.commands.ablate import AblationSpec, run_ablation
from slam.commands.compare import load_variants
from slam.errors import GslamError
from validation.base.yamlio import load_yaml

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
    loops = metrics.get("loops") if isinstance(metrics.get("loops"), dict) else {}
    row["loops_kept"], row["loops_wrong"] = loops.get("accepted"), loops.get("wrong_accepted")
    return row


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
    lines: list[str] = []

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

    # 4. Loop closing: gated with loops against gated without, and the loops' precision.
    if any((s, "gated_no_loops") in ate for s in scenarios):
        lines += ["", "## Loop closing: gated with loops against gated without", "",
                  "A kept loop is wrong when it is more than 0.15 m or 3 deg off the truth.", ""]
        lines += ["| scenario | gated [m] | gated without loops [m] | with / without: median, worst | "
                  "seeds worse (> 1 %) | loops kept | wrong | precision |", "|---|---|---|---|---|---|---|---|"]
        for s in scenarios:
            g, n = ate.get((s, "gated"), {}), ate.get((s, "gated_no_loops"), {})
            if not g or not n:
                continue
            r = [g[i] / n[i] for i in g if i in n]
            worse = sum(x > 1.01 for x in r)
            kept = sum(int(_num(e.get("loops_kept")) or 0) for e in other[(s, "gated")].values()
                       if np.isfinite(_num(e.get("loops_kept"))))
            wrong = sum(int(_num(e.get("loops_wrong"))) for e in other[(s, "gated")].values()
                        if np.isfinite(_num(e.get("loops_wrong"))))
            precision = f"{100 * (1 - wrong / kept):.1f} %" if kept else "–"
            lines.append(f"| {s} | {med(g.values()):.3f} | {med(n.values()):.3f} | {med(r):.2f}, {max(r):.2f} | "
                         f"{worse} of {len(r)} | {kept} | {wrong} | {precision} |")
    return "\n".join(lines) + "\n"


def sweep_spec(scenarios: list[str], seeds: list[int], variants_file: str, only: list[str] | None, config: str,
               overrides: list[str]) -> AblationSpec:
    """The bench as an ablation: every scenario and seed, every variant."""
    load_variants(variants_file, only)  # unknown names: one line naming the file
    variants = load_yaml(variants_file, "config")
    fixed = {}
    for item in overrides:
        key, sep, value = item.partition("=")
        if not sep:
            raise GslamError(f"--set {item}: expected KEY=VALUE")
        fixed[key] = yaml.safe_load(value)
    return AblationSpec.model_validate({
        "name": "bench_gating",
        "config": str(Path(config).resolve()),
        "inputs": {"scenarios": [{"path": str(SCENARIOS / f"{s}.yaml"), "seeds": seeds} for s in scenarios]},
        "variants": {name: variants[name] for name in (only or variants)},
        "set": fixed,
    })


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenarios", nargs="+", default=sorted(set(TWINS) | set(TWINS.values())))
    p.add_argument("--seeds", default="1-10")
    p.add_argument("--variants", nargs="+", default=None, help="default: every variant of --variants-file")
    p.add_argument("--variants-file", default=str(REPO / "configs" / "variants.yaml"))
    p.add_argument("--config", default=str(REPO / "configs" / "telemax.yaml"))
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=None, help="sweep folder to keep (default: a temporary one)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override for every variant")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    spec = sweep_spec(args.scenarios, parse_seeds(args.seeds), args.variants_file, args.variants, args.config, args.set)
    with tempfile.TemporaryDirectory(prefix="bench_gating_") as tmp:
        out = args.out or Path(tmp) / "sweep"
        result = run_ablation(spec, out, workers=args.workers, progress=False, source="bench gating")
        if result.failed:
            for job_id, error in result.failed.items():
                print(f"  failed {job_id}: {error}", flush=True)
        rows = []
        for job in result.jobs:
            metrics = out / "jobs" / job.id / "metrics.json"
            if metrics.exists():
                rows.append({"scenario": job.input_label, "seed": job.seed, "variant": job.variant,
                             **_flat(json.loads(metrics.read_text()))})
    summary = summarise(rows, list(spec.variants))
    publish("gating", "Gating against the robust kernels and the oracles, every scenario", summary, argv)
    include_in_readme("gating")
    print(summary)
    return 1 if result.failed else 0
