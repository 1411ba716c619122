"""``gslam``: the command line. It only parses arguments and calls the
library; every command is a library function returning a result object."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from slam.errors import GslamError
from validation.errors import ValidationError

log = logging.getLogger("gslam")

EXAMPLES = """\
examples:
  gslam simulate configs/scenarios/telemax_lab.yaml --out runs/lab --seed 1
  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_map
  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_gated --gating on
  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_isam2 --set backend.optimizer=isam2
  gslam map recording.bag --config my_robot.yaml --out runs/real --set input.topics.scan=/base_scan
  gslam compare runs/lab --config configs/telemax.yaml --out runs/lab_compare
  gslam demo --out runs/demo
  gslam ablate configs/ablations/gating_policy.yaml --out runs/ablate_gating --workers 2
"""


def _cmd_simulate(args: argparse.Namespace) -> int:
    from slam.sim import simulate

    res = simulate(args.scenario, args.out, seed=args.seed, progress=not args.quiet)
    print(f"wrote {res.run_dir} ({res.duration_s:.1f} s simulated)")
    for comp, intervals in res.faults.items():
        if intervals:
            spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in intervals)
            print(f"  true faults {comp}: {spans}")
    return 0


def _cmd_map(args: argparse.Namespace) -> int:
    from slam.config import load_config
    from slam.pipeline import run_map

    overrides = list(args.set or [])
    if args.gating is not None:
        overrides.append(f"validation.mode={args.gating}")
    config = load_config(args.config, overrides)
    res = run_map(args.input, config, args.out, progress=not args.quiet)
    _print_metrics(res.out_dir, res.metrics)
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from slam.compare import run_compare

    only = args.only.split(",") if args.only else None
    res = run_compare(args.input, args.config, args.out, args.variants, only, args.set or [], progress=not args.quiet)
    print((Path(args.out) / "comparison.md").read_text())
    print(f"wrote {res.out_dir}")
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from slam.compare import run_compare
    from slam.sim import simulate

    paths = (Path(args.scenario), Path(args.config), Path(args.variants))
    for p in paths:
        if not p.exists():
            raise GslamError(f"{p}: not found; run the demo from the repository root or pass --scenario/--config/--variants")
    out = Path(args.out)
    run_dir = out / Path(args.scenario).stem
    if not (run_dir / "truth.json").exists():
        sim = simulate(args.scenario, run_dir, seed=args.seed, progress=not args.quiet)
        print(f"simulated {sim.run_dir} ({sim.duration_s:.1f} s of the Telemax lab mission)")
    only = args.only.split(",") if args.only else None
    res = run_compare(run_dir, args.config, out / "compare", args.variants, only, progress=not args.quiet)
    print((res.out_dir / "comparison.md").read_text())
    print(f"result folders, tables and figures in {res.out_dir}")
    return 0


def _cmd_ablate(args: argparse.Namespace) -> int:
    from slam.ablate import load_spec, run_ablation

    spec = load_spec(args.spec, max_seeds=args.seeds)
    res = run_ablation(spec, args.out, workers=args.workers, backend=args.backend, address=args.address,
                       progress=not args.quiet, source=args.spec)
    print(res.summary.md_path.read_text())
    print(f"{len(res.jobs)} jobs: {len(res.ran)} ran, {len(res.skipped)} already finished, "
          f"{len(res.failed)} failed ({res.wall_s:.1f} s); wrote {res.out_dir}")
    for job_id, error in res.failed.items():
        print(f"  failed {job_id}: {error}")
    return 1 if res.failed else 0


def _print_metrics(out_dir: Path, metrics: dict) -> None:
    keys = (
        "ate_rmse_m", "ate_rmse_unaligned_m", "rpe_trans_pct", "rpe_rot_deg_per_m", "final_error_m",
        "n_poses", "runtime_s", "realtime_factor", "alarm_fraction", "detection_delay_s",
        "isolation_precision", "isolation_recall", "validation_time_s",
    )
    shown = {k: metrics[k] for k in keys if k in metrics}
    print(f"wrote {out_dir}")
    print(json.dumps(shown, indent=2))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="gslam",
        description="Offline SLAM (GTSAM) with sensor validation that gates each factor per time step.",
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("simulate", help="simulate a scenario into a ROS 2 bag plus true fault intervals",
                       epilog="example:\n  gslam simulate configs/scenarios/telemax_lab.yaml --out runs/lab --seed 1",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("scenario", help="scenario YAML (configs/scenarios/*.yaml)")
    s.add_argument("--out", required=True, help="run folder to create (bag/ and truth.json)")
    s.add_argument("--seed", type=int, default=None, help="random seed (default: the scenario's)")
    s.set_defaults(func=_cmd_simulate)

    m = sub.add_parser("map", help="map a recorded or simulated run and evaluate it",
                       epilog="examples:\n  gslam map runs/lab --config configs/telemax.yaml --out runs/lab_map\n"
                              "  gslam map runs/lab --config configs/telemax.yaml --out runs/x --set backend.factors.gps.enabled=false",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    m.add_argument("input", help="run folder, ROS 2 bag folder or ROS 1 .bag file")
    m.add_argument("--config", required=True, help="pipeline config YAML (e.g. configs/telemax.yaml)")
    m.add_argument("--out", required=True, help="result folder (replaced atomically)")
    m.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key (repeatable)")
    m.add_argument("--gating", choices=["off", "on", "oracle", "interval_oracle"], default=None,
                   help="off: every factor in; on: causal sensor validation gates factors; "
                        "oracle: gate with the true fault intervals (default: the config's validation.mode)")
    m.set_defaults(func=_cmd_map)

    c = sub.add_parser("compare", help="run ungated, gated, oracle and robust-kernel variants on the same run",
                       epilog="examples:\n  gslam compare runs/lab --config configs/telemax.yaml --out runs/lab_compare\n"
                              "  gslam compare runs/lab --config configs/telemax.yaml --out runs/x --only ungated,gated",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    c.add_argument("input", help="run folder, ROS 2 bag folder or ROS 1 .bag file")
    c.add_argument("--config", required=True, help="pipeline config YAML")
    c.add_argument("--out", required=True, help="comparison folder: one result folder per variant, tables, figures")
    c.add_argument("--variants", default="configs/variants.yaml", help="variants YAML (default configs/variants.yaml)")
    c.add_argument("--only", default=None, help="comma-separated subset of the variants")
    c.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key for every variant")
    c.set_defaults(func=_cmd_compare)

    d = sub.add_parser("demo", help="simulate the Telemax lab mission, map it ungated, gated and with the oracle",
                       epilog="examples:\n  gslam demo\n  gslam demo --out runs/demo_all --only "
                              "ungated,gated,oracle,huber,cauchy,dcs,gnc_tls,gnc_gm --seed 2",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    d.add_argument("--out", default="runs/demo", help="demo folder (default runs/demo)")
    d.add_argument("--scenario", default="configs/scenarios/telemax_lab.yaml")
    d.add_argument("--config", default="configs/telemax.yaml")
    d.add_argument("--variants", default="configs/variants.yaml")
    d.add_argument("--only", default="ungated,gated,oracle", help="variants to run (default ungated,gated,oracle)")
    d.add_argument("--seed", type=int, default=None)
    d.set_defaults(func=_cmd_demo)

    a = sub.add_parser("ablate", help="run a sweep of configs, scenarios and seeds (resumable; local or Ray)",
                       epilog="examples:\n  gslam ablate configs/ablations/gating_policy.yaml --out runs/ablate_gating\n"
                              "  gslam ablate configs/ablations/paper_parameters.yaml --out runs/pp --workers 2 --seeds 3\n"
                              "  gslam ablate SPEC.yaml --out /shared/runs/x --backend ray --address auto",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    a.add_argument("spec", help="ablation spec YAML (configs/ablations/*.yaml)")
    a.add_argument("--out", required=True, help="sweep folder; running again skips finished jobs")
    a.add_argument("--workers", type=int, default=None, help="parallel jobs (default: CPU count)")
    a.add_argument("--backend", choices=["local", "ray"], default="local",
                   help="local: process pool; ray: one Ray task per job (pip install \".[ray]\")")
    a.add_argument("--address", default=None, help="Ray cluster address (e.g. auto); default: a local Ray instance")
    a.add_argument("--seeds", type=int, default=None, help="only the first N seeds of each scenario (a quick look)")
    a.set_defaults(func=_cmd_ablate)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
    )
    try:
        return args.func(args)
    except (GslamError, ValidationError) as e:
        print(f"gslam: error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("gslam: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
