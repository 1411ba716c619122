"""``python -m scripts.bench NAME [ARGS ...]``: run one benchmark."""

from __future__ import annotations

import argparse
import importlib
import sys

from slam.errors import run_script

BENCHES = {
    "gating": "gating against the robust kernels and the oracles over many seeds of every scenario",
    "perf": "performance of the gated pipeline: stage split, growth with run length, iSAM2, diagnosis",
    "speed": "gslam map as a process against KISS-ICP alone",
    "throughput": "gslam map against real time on the simulated mission",
    "loops": "loop closing on telemax_lab, false loops, the libRSF corridor, runtime",
    "carmen": "relative errors on the CARMEN logs against their corrected reference",
    "carmen_cuts": "CARMEN with the laser cut over stretches: gated against ungated and the kernels",
    "broad": "BROAD: the compass observers, thresholds chosen leave-one-trial-out",
    "broad_loto": "BROAD: every trial mapped with observers calibrated on the other twelve",
    "husky": "the Husky bag ungated and gated, against GPS",
    "husky_dipole": "the Husky bag with injected compass dipoles: found, and quiet elsewhere?",
    "husky_faults": "the Husky bag with one injected fault of each kind: found and blamed right?",
    "tune_baselines": "tune the robust-kernel baselines on the scenarios' tuning seeds",
    "tune_loops": "loop closing on the CARMEN logs kept for tuning",
}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(
        prog="python -m scripts.bench", description="Run one benchmark of gated-slam (from the repository root).",
        epilog="benchmarks:\n" + "\n".join(f"  {name:<15} {what}" for name, what in BENCHES.items())
        + "\n\npython -m scripts.bench NAME --help shows a benchmark's options.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("name", choices=list(BENCHES), metavar="NAME", help="the benchmark to run")
    args, rest = parser.parse_known_args(argv[:1])
    module = importlib.import_module(f"scripts.bench.{args.name}")
    run_script(f"bench {args.name}", lambda: module.main(argv[1:]))
    return 0


if __name__ == "__main__":
    main()
