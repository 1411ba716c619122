"""Tune the robust-kernel baselines on the scenarios' tuning seeds.

For each kernel (Huber, Cauchy, DCS) and parameter, and for GTSAM's GNC
(TLS, Geman-McClure) with and without an inlier-probability threshold, map
every scenario and fault-free twin on the tuning seeds (1-3, the seeds the
gating config was chosen on) ungated, and report the aligned ATE per
scenario (median over seeds) and the score: the geometric mean, over every
run, of the candidate's ATE over the best candidate's ATE on that run (1 is
best on every run; a scale-free score, so that no scenario's metres
outweigh another's). The best parameter per kernel goes into
configs/variants.yaml; the report seeds (11-20) are never used here.

    python -m scripts.bench tune_baselines [--out runs/tune_baselines] [--seeds 1-3] [--only NAME ...]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slam.config import load_config
from slam.errors import GslamError
from slam.results.atomic import write_text
from slam.pipeline.folder import MappingPipeline
from slam.resources import shipped_config
from slam.sim import simulate

SCENARIOS = (
    "telemax_lab", "telemax_compass", "corridor", "hall", "compass_steel",
    "telemax_lab_clean", "corridor_clean", "hall_clean", "compass_steel_clean",
)
CANDIDATES: tuple[tuple[str, list[str]], ...] = (
    *((f"huber c={c}", ["backend.robust_kernel=huber", f"backend.robust_param={c}"]) for c in (0.5, 1.0, 1.345, 2.0, 3.0)),
    *((f"cauchy c={c}", ["backend.robust_kernel=cauchy", f"backend.robust_param={c}"]) for c in (0.5, 1.0, 2.0, 3.0)),
    *((f"dcs phi={c}", ["backend.robust_kernel=dcs", f"backend.robust_param={c}"]) for c in (0.5, 1.0, 2.0, 5.0)),
    *((f"gnc_{loss} p={p}", [f"backend.optimizer=gnc_{loss}", f"backend.gnc_inlier_probability={p}"])
      for loss in ("tls", "gm") for p in ("null", 0.9, 0.99)),
)


@dataclass
class TuneResult:
    scenarios: list[str]
    ate: dict[str, dict[tuple[str, int], float]] = field(default_factory=dict)  # candidate -> (scenario, seed) -> ATE

    def score(self, name: str) -> float:
        runs = next(iter(self.ate.values())).keys()
        best = {r: min(per[r] for per in self.ate.values()) for r in runs}
        return float(np.exp(np.mean([np.log(self.ate[name][r] / best[r]) for r in runs])))

    def markdown(self) -> str:
        head = "| candidate | " + " | ".join(self.scenarios) + " | score |"
        lines = [head, "|" + "---|" * (len(self.scenarios) + 2)]
        for name, per in self.ate.items():
            meds = [np.median([v for (sc, _), v in per.items() if sc == s]) for s in self.scenarios]
            lines.append(f"| {name} | " + " | ".join(f"{v:.3f}" for v in meds) + f" | {self.score(name):.3f} |")
        return "\n".join(lines) + "\n"


def tune(config: Path, scenarios_dir: Path, out: Path, seeds: list[int], scenarios: list[str]) -> TuneResult:
    result = TuneResult(scenarios)
    for scenario in scenarios:
        for seed in seeds:
            run = out / "runs" / f"{scenario}_seed{seed}"
            if not (run / "truth.json").exists():
                simulate(scenarios_dir / f"{scenario}.yaml", run, seed=seed)
            recording = frontend = None
            for name, overrides in CANDIDATES:
                cfg = load_config(config, ["validation.mode=off", "output.plots=false", *overrides])
                pipe = MappingPipeline(run, cfg, out / "maps" / f"{scenario}_seed{seed}",
                                       recording=recording, frontend=frontend)
                metrics = pipe.run().metrics
                recording, frontend = pipe.recording, pipe.frontend
                result.ate.setdefault(name, {})[(scenario, seed)] = metrics["ate_rmse_m"]
                print(f"{scenario:20s} {seed:3d} {name:18s} ATE {metrics['ate_rmse_m']:.3f} m", file=sys.stderr)
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", type=Path, default=shipped_config("telemax.yaml"))
    p.add_argument("--scenarios", type=Path, default=shipped_config("scenarios"))
    p.add_argument("--out", type=Path, default=Path("runs/tune_baselines"))
    p.add_argument("--seeds", default="1-3", help="first-last (default 1-3)")
    p.add_argument("--only", nargs="+", default=list(SCENARIOS), metavar="NAME", help="scenarios (default: all)")
    args = p.parse_args(argv)
    a, _, b = args.seeds.partition("-")
    seeds = list(range(int(a), int(b or a) + 1))
    try:
        result = tune(args.config, args.scenarios, args.out, seeds, args.only)
    except GslamError as e:
        print(f"tune_baselines: error: {e}", file=sys.stderr)
        return 1
    table = result.markdown()
    write_text(args.out / "tune_baselines.md", table)
    print(table)
    return 0

