"""The Husky bag with one injected fault of each kind the bag's sensors can
have (``gslam inject``): is each found, and blamed on the right sensor?

    python -m scripts.bench husky_faults [--data DIR] [--config configs/datasets/husky.yaml]
                                         [--out runs/bench_husky_faults] [--faults SPEC ...]

``scripts/bench/husky_dipole.py`` asks this of the compass alone. Here each
fault of ``FAULTS`` is injected on its own into a copy of the bag, after
the first 180 s the shipped config learnt its observers from and after the
AHRS heading's own drift (195-215 s):

* a gyro bias step of 2 and of 1 deg/s;
* wheel slip: the odometry's distance 1.5 x and 0.7 x the true one;
* the odometry's turn 1.5 x the true one (skid steering on another ground);
* GPS multipath: the fixes 8 m off;
* a magnetic dipole beside the path, seen by the IMU's heading.

Each injected bag is mapped with gating on, pass and observers as the
config says. Reported per fault: the labelled component, per-step recall
and precision of the diagnosis (``metrics.json``), the labelled intervals
detected and the delay, and the share of the *judged* steps with a false
alarm: after ``JUDGED_FROM_S``, outside the real drift and outside each
label and the ``AFTER_LABEL_S`` after it, a step that blames a sensor, or
has no diagnosis, except the compass from 195 s on, where the AHRS heading
stays off to the end of the bag (``judges.REAL_FAULT_FROM_S``),
and the GPS where the recorded fixes wander off on their own
(``judges.gps_wanders``). The first row maps the bag
without a fault: its judged alarms are the validator's own false alarms
(and the bag's real events: wheel slips at 317 and 350 s). Then the map:
ATE against the bag's own GPS fixes (``scripts/bench/husky.py``; the
injected fixes are not the reference) gated, ungated and with the best of
the robust kernels of ``configs/variants.yaml`` on that bag.

``--faults`` injects others (``gslam inject`` syntax), to choose a config
on faults other than the reported ones. Writes ``husky_faults.md``.
"""

from __future__ import annotations

import argparse
import io
import logging
import tempfile
import time
from pathlib import Path


from scripts.bench.common import HUSKY_BAG, KERNELS, publish, quiet_logging
from scripts.bench.judges import AFTER_LABEL_S, REAL_DRIFT, ate_vs_gps, false_alarms, gps_wanders
from slam.commands.compare import load_variants
from slam.config import load_config
from slam.commands.inject import inject
from slam.commands.inject.spec import parse_fault
from slam.results.atomic import write_text
from slam.readers.datasets import data_root
from slam.readers.read import read_recording
from slam.pipeline.folder import run_map

log = logging.getLogger(__name__)
ROOT = Path(__file__).resolve().parents[2]
JUDGED_FROM_S = 180.0  # the shipped config learnt from the first 180 s
FAULTS = (
    "gyro_bias@250:280,bias_deg_s=2",
    "gyro_bias@330:360,bias_deg_s=1",
    "slip@240:270,scale=1.5",
    "slip@330:360,scale=0.7",
    "slip@260:290,scale=1,yaw_scale=1.5",
    "multipath@300:330,bias_m=8",
    "dipole@340:370,target=heading",
)


def judged_alarms(validation, labels: list[tuple[float, float]], wanders=()) -> tuple[float, int]:
    """``(share, steps)``: of the judged steps (module docstring), the share
    whose most probable diagnosis blames a sensor other than the compass in
    its own fault and the GPS in its own ``wanders``, or that have none
    (``judges.false_alarms``)."""
    t = validation.step_t
    keep = t > JUDGED_FROM_S
    for a, b in [*labels, REAL_DRIFT]:
        keep &= ~((t >= a) & (t <= b + AFTER_LABEL_S))
    alarm = false_alarms(validation, wanders)[1]
    return (float(alarm[keep].mean()) if keep.any() else float("nan")), int(keep.sum())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=None)
    ap.add_argument("--config", type=Path, default=ROOT / "configs/datasets/husky.yaml")
    ap.add_argument("--out", type=Path, default=ROOT / "runs/bench_husky_faults")
    ap.add_argument("--faults", nargs="+", default=list(FAULTS))
    args = ap.parse_args(argv)
    quiet_logging()
    for fault in args.faults:  # every spec checked before any work
        parse_fault(fault)
    bag = (args.data or data_root()) / HUSKY_BAG
    config = load_config(args.config, ["validation.mode=on", "output.plots=false"])
    kernels = load_variants(ROOT / "configs/variants.yaml", list(KERNELS))
    ungated = ["validation.mode=off", "output.plots=false"]
    others = {"ungated": load_config(args.config, ungated),
              **{name: load_config(args.config, [*ungated, *over]) for name, over in kernels.items()}}
    recorded = read_recording(bag, config.input)
    gps = recorded.gps  # the reference, as recorded
    wanders = gps_wanders(recorded)
    rows = []
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for i, fault in enumerate([None, *args.faults]):
            if fault is None:
                run, labels = bag, {}
            else:
                injected = inject(bag, [fault], tmp / f"run_{i}", config=config.input)
                run, labels = injected.run_dir, injected.faults
            res = run_map(run, config, tmp / f"map_{i}")
            m, v = res.metrics, res.validation
            ate = {name: ate_vs_gps(run_map(run, c, tmp / f"map_{i}_{name}").trajectory, gps)[0]
                   for name, c in others.items()}
            best = min(kernels, key=ate.get)
            intervals = [iv for ivs in labels.values() for iv in ivs]
            share, steps = judged_alarms(v, intervals, wanders)
            delays = m.get("detection_delay_s") or {}
            rows.append({
                "fault": fault or "none (the bag as recorded)",
                "label": ", ".join(labels) or "–",
                "recall": m.get("isolation_recall"), "precision": m.get("isolation_precision"),
                "detected": f"{m.get('faults_detected') or 0}/{(m.get('faults_detected') or 0) + (m.get('faults_missed') or 0)}",
                "delay_s": min((d for d in delays.values() if d is not None), default=None),
                "judged_alarms": share, "judged_steps": steps,
                "ate_gated_m": ate_vs_gps(res.trajectory, gps)[0], "ate_ungated_m": ate["ungated"],
                "best_kernel": best, "ate_kernel_m": ate[best],
            })
            log.info("%s", rows[-1])
    f = lambda x: "–" if x is None else f"{x:.3f}"  # noqa: E731
    out = io.StringIO()
    config = args.config.resolve()
    shown = config.relative_to(ROOT) if config.is_relative_to(ROOT) else config  # where the repository is, is no figure
    out.write(f"Config: {shown}\n\n| fault | labelled | recall | precision | intervals detected | delay s | "
              "judged steps blaming a sensor | judged steps | ATE vs GPS gated m | ungated m | best kernel m |\n"
              "|---|---|---|---|---|---|---|---|---|---|---|\n")
    for r in rows:
        out.write(f"| {r['fault']} | {r['label']} | {f(r['recall'])} | {f(r['precision'])} | {r['detected']} | "
                  f"{f(r['delay_s'])} | {f(r['judged_alarms'])} | {r['judged_steps']} | {r['ate_gated_m']:.2f} | "
                  f"{r['ate_ungated_m']:.2f} | {r['ate_kernel_m']:.2f} ({r['best_kernel']}) |\n")
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "husky_faults.md", out.getvalue())
    publish("husky_faults", "The Husky bag with one injected fault of each kind", out.getvalue(), argv)
    print(out.getvalue())
    print(f"{time.perf_counter() - start:.0f} s")
    return 0

