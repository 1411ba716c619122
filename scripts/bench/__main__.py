"""``python -m scripts.bench NAME [ARGS ...]``: run one benchmark;
``python -m scripts.bench all [--quick]``: run every one that writes a
results page, each in its own process, and regenerate ``docs/results/``."""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import time

from scripts.bench.common import REPO, table
from slam.errors import run_script

RESULTS = {  # name: what it measures (each writes docs/results/NAME.md)
    "gating": "gating against the robust kernels and the oracles over many seeds of every scenario",
    "perf": "gslam map as a process against KISS-ICP alone; stages, growth, iSAM2, diagnosis",
    "loops": "loop closing on telemax_lab, false loops, the libRSF corridor, runtime",
    "carmen": "relative errors on the CARMEN logs against their corrected reference",
    "carmen_cuts": "CARMEN with the laser cut over stretches: gated against ungated and the kernels",
    "real_faults": "the CARMEN report logs, the Husky bag and BROAD trials with injected faults: gated against every kernel and oracle",
    "broad": "BROAD: the compass observers, thresholds chosen leave-one-trial-out",
    "broad_loto": "BROAD: every trial mapped with observers calibrated on the other twelve",
    "husky": "the Husky bag ungated and gated, against GPS",
    "husky_dipole": "the Husky bag with injected compass dipoles: found, and quiet elsewhere?",
    "husky_faults": "the Husky bag with one injected fault of each kind: found and blamed right?",
    "proposal": "the system model gslam inspect proposes, calibrated, against the shipped ones, held out",
    "self_check": "the map's self-check on the CARMEN logs, the Husky bag and the demo, beside each map's ATE",
    "walkthrough": "inspect, calibrate and map --gating on the Husky bag: docs/three_commands.md (not a results page)",
}
TUNING = {
    "tune_baselines": "tune the robust-kernel baselines on the scenarios' tuning seeds",
    "tune_loops": "loop closing on the CARMEN logs kept for tuning",
}
QUICK = {  # the arguments of each bench under `all --quick`: every page in under 30 minutes on 2 cores
    "gating": ["--seeds", "11-12"],
    "perf": ["--quick"],
    "loops": ["--seeds", "1", "--repeats", "1", "--sections", "telemax", "false_loops", "corridor"],
    "carmen": ["--mission-seeds", "1"],
    "carmen_cuts": ["--logs", "aces"],
    "real_faults": ["--logs", "aces", "--faults", "cut3", "--jobs", "2"],
    "broad": [],
    "broad_loto": ["--only", "trend"],
    "husky": [],
    "husky_dipole": ["--sets", "trend", "shipped", "--passes", "offline", "--no-folds"],
    "husky_faults": [],
    "proposal": ["--seeds", "11-12", "--carmen-logs", "intel", "aces"],
    "self_check": ["--logs", "intel", "aces", "orebro", "husky", "demo"],
    "walkthrough": [],
}


def run_all(quick: bool, only: list[str]) -> int:
    """Every results bench in its own process, one after the other; a table
    of how long each took and whether it finished."""
    rows, failed = [], 0
    for name in only:
        cmd = [sys.executable, "-m", "scripts.bench", name, *(QUICK[name] if quick else [])]
        print(f"== {' '.join(cmd[1:])}", flush=True)
        start = time.perf_counter()
        code = subprocess.run(cmd, cwd=REPO).returncode
        seconds = time.perf_counter() - start
        failed += code != 0
        rows.append([name, "ok" if code == 0 else f"exit {code}", f"{seconds:.0f}"])
        print(f"== {name}: {rows[-1][1]} in {seconds:.0f} s", flush=True)
    print(table(["bench", "result", "wall [s]"], rows))
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    names = {**RESULTS, **TUNING}
    parser = argparse.ArgumentParser(
        prog="python -m scripts.bench", description="Run a benchmark of gated-slam (from the repository root).",
        epilog="benchmarks (each writes docs/results/NAME.md):\n"
        + "\n".join(f"  {name:<15} {what}" for name, what in RESULTS.items())
        + "\n\ntuning runs (parameters chosen on tuning data, printed):\n"
        + "\n".join(f"  {name:<15} {what}" for name, what in TUNING.items())
        + "\n\n  all [--quick] [--only NAME ...]  every benchmark above, each in its own process"
        + "\n\npython -m scripts.bench NAME --help shows a benchmark's options.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("name", choices=[*names, "all"], metavar="NAME", help="the benchmark to run, or all")
    args, _ = parser.parse_known_args(argv[:1])
    if args.name == "all":
        sub = argparse.ArgumentParser(prog="python -m scripts.bench all")
        sub.add_argument("--quick", action="store_true", help="the short settings of each bench (QUICK)")
        sub.add_argument("--only", nargs="+", choices=list(RESULTS), default=list(RESULTS))
        opts = sub.parse_args(argv[1:])
        return run_all(opts.quick, opts.only)
    module = importlib.import_module(f"scripts.bench.{args.name}")
    sys.argv[0] = f"python -m scripts.bench {args.name}"  # the bench's usage line, as its docs write the command
    run_script(f"bench {args.name}", lambda: module.main(argv[1:]))
    return 0


if __name__ == "__main__":
    run_script("bench", main)
