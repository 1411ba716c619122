"""Tune the robust-kernel baselines once on the shared scenarios.

For each kernel (Huber, Cauchy, DCS) and parameter, and for GTSAM's GNC
(TLS, Geman-McClure) with and without an inlier-probability threshold, map
telemax_lab, telemax_lab_clean and telemax_compass (seed 1) ungated and
report the aligned ATE per scenario and its mean. The best parameter per
kernel goes into configs/variants.yaml.

    python scripts/tune_baselines.py [--out runs/tune_baselines] [--seed 1]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slam.config import load_config
from slam.errors import GslamError
from slam.io.atomic import write_text
from slam.pipeline import MappingPipeline
from slam.resources import shipped_config
from slam.sim import simulate

SCENARIOS = ("telemax_lab", "telemax_lab_clean", "telemax_compass")
CANDIDATES: tuple[tuple[str, list[str]], ...] = (
    *((f"huber c={c}", ["backend.robust_kernel=huber", f"backend.robust_param={c}"]) for c in (0.5, 1.0, 1.345, 2.0, 3.0)),
    *((f"cauchy c={c}", ["backend.robust_kernel=cauchy", f"backend.robust_param={c}"]) for c in (0.5, 1.0, 2.0, 3.0)),
    *((f"dcs phi={c}", ["backend.robust_kernel=dcs", f"backend.robust_param={c}"]) for c in (0.5, 1.0, 2.0, 5.0)),
    *((f"gnc_{loss} p={p}", [f"backend.optimizer=gnc_{loss}", f"backend.gnc_inlier_probability={p}"])
      for loss in ("tls", "gm") for p in ("null", 0.9, 0.99)),
)


@dataclass
class TuneResult:
    ate: dict[str, dict[str, float]] = field(default_factory=dict)  # candidate -> scenario -> ATE

    def markdown(self) -> str:
        head = "| candidate | " + " | ".join(SCENARIOS) + " | mean |"
        lines = [head, "|" + "---|" * (len(SCENARIOS) + 2)]
        for name, per in self.ate.items():
            vals = [per[s] for s in SCENARIOS]
            lines.append(f"| {name} | " + " | ".join(f"{v:.3f}" for v in vals) + f" | {np.mean(vals):.3f} |")
        return "\n".join(lines) + "\n"


def tune(config: Path, scenarios_dir: Path, out: Path, seed: int) -> TuneResult:
    result = TuneResult()
    for scenario in SCENARIOS:
        run = out / "runs" / f"{scenario}_seed{seed}"
        if not (run / "truth.json").exists():
            simulate(scenarios_dir / f"{scenario}.yaml", run, seed=seed)
        recording = frontend = None
        for name, overrides in CANDIDATES:
            cfg = load_config(config, ["validation.mode=off", "output.plots=false", *overrides])
            pipe = MappingPipeline(run, cfg, out / "maps" / scenario, recording=recording, frontend=frontend)
            metrics = pipe.run().metrics
            recording, frontend = pipe.recording, pipe.frontend
            result.ate.setdefault(name, {})[scenario] = metrics["ate_rmse_m"]
            print(f"{scenario:18s} {name:18s} ATE {metrics['ate_rmse_m']:.3f} m", file=sys.stderr)
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", type=Path, default=shipped_config("telemax.yaml"))
    p.add_argument("--scenarios", type=Path, default=shipped_config("scenarios"))
    p.add_argument("--out", type=Path, default=Path("runs/tune_baselines"))
    p.add_argument("--seed", type=int, default=1)
    args = p.parse_args(argv)
    try:
        result = tune(args.config, args.scenarios, args.out, args.seed)
    except GslamError as e:
        print(f"tune_baselines: error: {e}", file=sys.stderr)
        return 1
    table = result.markdown()
    write_text(args.out / "tune_baselines.md", table)
    print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
