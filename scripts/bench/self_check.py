"""The map's self-check on the CARMEN logs, the Husky bag and the demo.

Each figure of ``slam/outputs/self_check.py`` with its samples, the verdict
and the check's seconds, beside the map's ATE.

    python -m scripts.bench self_check [--logs intel orebro husky demo ...] [--jobs N] [--out DIR]
                                       [--data DIR]

Each map is made as a user makes it, as a process (``python -m slam.cli``,
that is ``gslam``):

* a CARMEN log: ``gslam map DATA/carmen/LOG-corrected.log.gz --config
  configs/datasets/carmen.yaml``;
* the Husky bag: ``gslam map DATA/rosbag/test1_husky_2015.bag --config
  configs/datasets/husky.yaml``;
* the demo: ``gslam demo`` (telemax_lab, the scenario's seed), whose
  ungated, gated and oracle variants are three rows.

Every figure is read from the run's ``metrics.json``: ``self_check`` (each
figure's ``value`` and ``samples``, ``stamps_synthesised``, ``verdict``,
``blame_share``), ``timings_s.self_check`` and ``ate_rmse_m`` (against the
log's corrected poses or the simulator's truth; none for the bag). A row
whose data is absent is skipped, and the page says why. Writes
``docs/results/self_check.md``.
"""

from __future__ import annotations

import argparse
import json
import logging
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from scripts.bench.common import CONFIGS, HUSKY_BAG, REPO, carmen_log, publish, quiet_logging, table
from slam.readers.datasets import data_root

log = logging.getLogger(__name__)

CARMEN_LOGS = ("intel", "freiburg-079", "aces", "csail", "fhw", "freiburg-101", "seattle", "belgioioso",
               "infinite-corridor", "orebro")
HUSKY = "husky"
DEMO = "demo"
DEMO_VARIANTS = ("ungated", "gated", "oracle")
UNITS = (*CARMEN_LOGS, HUSKY, DEMO)
FIGURES = ("scan_agreement", "free_space_returns", "loop_residual_m", "odometry_disagreement")
GOOD_ATE_M = 0.2
"""A CARMEN log mapped within this ATE of its corrected reference counts as mapped well in the page's summary."""
HEADER = ["log", "ATE m", "scan_agreement", "free_space_returns", "loop_residual_m", "odometry_disagreement",
          "stamps synthesised", "verdict", "self-check s"]


@dataclass
class Unit:
    """One process to run: its name (a CARMEN log, ``husky`` or ``demo``),
    its input, its command's arguments after ``gslam -q`` and its folder."""

    name: str
    source: Path
    args: list[str]
    out: Path


@dataclass
class Row:
    """One row of the table: its label, its group (``carmen``, ``husky``,
    ``demo``) and its run's metrics.json."""

    label: str
    group: str
    metrics: dict = field(default_factory=dict)

    @property
    def check(self) -> dict | None:
        return self.metrics.get("self_check")

    @property
    def ate_m(self) -> float | None:
        return self.metrics.get("ate_rmse_m")

    def figure(self, name: str) -> dict | None:
        check = self.check
        return None if check is None else check["figures"].get(name)

    def value(self, name: str) -> float | None:
        f = self.figure(name)
        return None if f is None else f["value"]


def units_of(names: list[str], data: Path, work: Path) -> tuple[list[Unit], list[str]]:
    """The processes for ``names`` and, for each one whose input is absent,
    why it is skipped."""
    units, skipped = [], []
    for name in names:
        if name == DEMO:
            units.append(Unit(name, Path("telemax_lab"), ["demo", "--out", str(work / "demo")], work / "demo"))
            continue
        if name == HUSKY:
            source, config = data / HUSKY_BAG, CONFIGS / "datasets" / "husky.yaml"
        else:
            source, config = carmen_log(data, name), CONFIGS / "datasets" / "carmen.yaml"
        if not source.is_file():
            skipped.append(f"{name}: {source} not found (set GSLAM_DATA or --data to the data folder)")
            continue
        out = work / ("husky" if name == HUSKY else f"carmen/{name}")
        units.append(Unit(name, source, ["map", str(source), "--config", str(config), "--out", str(out)], out))
    return units, skipped


def run_unit(unit: Unit) -> str | None:
    """Run ``unit`` as gslam does (``python -m slam.cli -q ...``, from the
    repository root); None when it finished, else why not."""
    cmd = [sys.executable, "-m", "slam.cli", "-q", *unit.args]
    start = time.perf_counter()
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True)
    log.info("%s: exit %d in %.0f s", unit.name, done.returncode, time.perf_counter() - start)
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["(no message)"])[-1]
        return f"{unit.name}: gslam exited {done.returncode}: {last}"
    return None


def rows_of(unit: Unit) -> list[Row]:
    """The rows of a finished unit, from its metrics.json (the demo's: one per variant)."""
    if unit.name == DEMO:
        return [Row(f"demo, {v}", "demo", read_metrics(unit.out / "compare" / v / "metrics.json"))
                for v in DEMO_VARIANTS]
    if unit.name == HUSKY:
        return [Row("Husky bag (husky.yaml)", "husky", read_metrics(unit.out / "metrics.json"))]
    return [Row(unit.name, "carmen", read_metrics(unit.out / "metrics.json"))]


def read_metrics(path: Path) -> dict:
    return json.loads(path.read_text())


# -- the page -----------------------------------------------------------------


def _g(value: float | None) -> str | None:
    return None if value is None else f"{value:g}"


def figure_cell(figure: dict | None) -> str | None:
    """A figure as ``value (samples)``; – where it does not apply."""
    if figure is None or figure["value"] is None:
        return None
    return f"{figure['value']:g} ({figure['samples']})"


def cells(row: Row) -> list[object]:
    """The table's cells of ``row`` (None: –)."""
    check = row.check
    ate = None if row.ate_m is None else f"{row.ate_m:.3f}"
    if check is None:
        return [row.label, ate, *(None for _ in FIGURES), None, "no self-check", None]
    seconds = row.metrics.get("timings_s", {}).get("self_check")
    return [row.label, ate, *(figure_cell(row.figure(n)) for n in FIGURES),
            "no" if check.get("stamps_synthesised") is None else "yes", check["verdict"],
            None if seconds is None else f"{seconds:.2f}"]


def _unit(name: str) -> str:
    return " m" if name.endswith("_m") else ""


def _bound(figure: dict) -> str:
    return f"{'≥' if figure['side'] == 'at_least' else '≤'} {figure['bound']:g}"


def _figures_text(row: Row) -> str:
    return ", ".join(f"{n} {row.value(n):g}{_unit(n)}" if row.value(n) is not None else f"{n} –" for n in FIGURES)


def _verb(row: Row) -> str:
    return "passes" if row.check["verdict"] == "pass" else "fails"


def _range(rows: list[Row], name: str) -> str | None:
    have = [r for r in rows if r.value(name) is not None]
    if not have:
        return None
    lo = min(have, key=lambda r: r.value(name))
    hi = max(have, key=lambda r: r.value(name))
    u = _unit(name)
    if lo.value(name) == hi.value(name):
        return f"{name} {lo.value(name):g}{u} on every one"
    return f"{name} {lo.value(name):g}{u} ({lo.label}) to {hi.value(name):g}{u} ({hi.label})"


def findings(rows: list[Row]) -> list[str]:
    """Sentences drawn from the rows alone."""
    out = []
    checked = [r for r in rows if r.check is not None]
    carmen = [r for r in checked if r.group == "carmen" and r.ate_m is not None]
    if carmen:
        good = [r for r in carmen if r.ate_m <= GOOD_ATE_M]
        bad_good = [r.label for r in good if r.check["verdict"] != "pass"]
        text = (f"Of the {len(carmen)} CARMEN logs mapped, {len(good)} map within {GOOD_ATE_M:g} m ATE of their "
                "corrected reference; " + ("all of them pass" if not bad_good else
                                           f"of them, {', '.join(bad_good)} fail{'s' if len(bad_good) == 1 else ''}"))
        beyond = [r for r in carmen if r.ate_m > GOOD_ATE_M]
        if beyond:
            text += f". Beyond {GOOD_ATE_M:g} m: " + "; ".join(f"{r.label} ({r.ate_m:.3f} m) {_verb(r)}"
                                                for r in beyond)
        out.append(text + ".")
    for r in checked:
        if r.check["verdict"] == "fail":
            failed = [f"{n} {r.value(n):g}{_unit(n)} (bound {_bound(r.figure(n))})" for n in r.check["failed"]]
            absent = [n for n in FIGURES if r.value(n) is None]
            out.append(f"{r.label} fails on {', '.join(failed)}"
                       + (f"; {' and '.join(absent)} do{'es' if len(absent) == 1 else ''} not apply" if absent else "")
                       + ".")
    passing = [r for r in carmen if r.check["verdict"] == "pass"]
    ranges = [t for t in (_range(passing, n) for n in FIGURES) if t]
    if ranges:
        out.append("Over the CARMEN logs that pass: " + "; ".join(ranges) + ".")
    far = [r for r in carmen if r.check["verdict"] == "pass" and r.ate_m > GOOD_ATE_M]
    for r in far:
        out.append(f"{r.label} passes at {r.ate_m:.3f} m ATE: {_figures_text(r)}.")
    by_label = {r.label: r for r in checked}
    ungated, gated = by_label.get("demo, ungated"), by_label.get("demo, gated")
    if ungated is not None and gated is not None:
        pairs = ", ".join(f"{n} {_g(ungated.value(n)) or '–'} against {_g(gated.value(n)) or '–'}{_unit(n)}"
                          for n in FIGURES)
        text = f"The demo ungated against gated ({ungated.ate_m:.3f} m against {gated.ate_m:.3f} m ATE): {pairs}"
        scan = ungated.figure("scan_agreement")
        n_poses = ungated.metrics.get("n_poses")
        if scan is not None and scan["value"] is not None and n_poses:
            text += (f"; its scan_agreement rests on the {scan['samples']} of its {n_poses} keyframes whose scans "
                     f"hold points ({n_poses - scan['samples']} see nothing within the beam limits)")
        out.append(text + ".")
    blamed = [r for r in checked if r.check.get("blame_share") is not None]
    if blamed:
        out.append("blame_share (reported, not judged: the validator's alarm_fraction): "
                   + "; ".join(f"{r.label} {r.check['blame_share']:g}" for r in blamed) + ".")
    timed = [r for r in checked if r.metrics.get("timings_s", {}).get("self_check") is not None]
    if timed:
        def s(r: Row) -> float:
            return r.metrics["timings_s"]["self_check"]
        lo, hi = min(timed, key=s), max(timed, key=s)
        text = f"The check took {s(lo):.2f} s ({lo.label}) to {s(hi):.2f} s ({hi.label}"
        scan = hi.figure("scan_agreement")
        if hi.metrics.get("n_poses") and scan is not None:
            text += f": {hi.metrics['n_poses']} keyframes, {scan['samples']} of them checked for scan_agreement"
        out.append(text + ").")
    return out


def page(rows: list[Row], skipped: list[str], jobs: int, seed: int | None) -> str:
    """The page's body: the commands, the table, what is skipped, the findings."""
    demo = f"`gslam demo` (telemax_lab, seed {seed})" if seed is not None else "`gslam demo`"
    text = ("Each row is one map, made as a process: a CARMEN log by `gslam map LOG --config "
            "configs/datasets/carmen.yaml`, the Husky bag by `gslam map BAG --config configs/datasets/husky.yaml`, "
            f"the demo's variants by one {demo}. Each figure is `metrics.json`'s `self_check` value with its "
            "samples in parentheses (– where it does not apply); ATE is `ate_rmse_m` of the same file (against "
            "the log's corrected poses or the simulator's truth; the bag has none); stamps synthesised: whether "
            "the reader made the times (`stamps_synthesised`); self-check s: `timings_s.self_check`, with "
            f"{jobs} map{'s' if jobs != 1 else ''} at a time. The bounds are in "
            "[docs/cli.md](../cli.md#the-self-check).\n\n")
    text += table(HEADER, [cells(r) for r in rows])
    if skipped:
        text += "\nNot measured:\n\n" + "".join(f"- {s}\n" for s in skipped)
    notes = findings(rows)
    if notes:
        text += "\n" + "\n\n".join(notes) + "\n"
    reasons = {r.label: r.check["stamps_synthesised"] for r in rows
               if r.check is not None and r.check.get("stamps_synthesised") is not None}
    if reasons:
        text += "\nWhy the stamps were synthesised:\n\n" + "".join(f"- {k}: {v}\n" for k, v in reasons.items())
    return text


def demo_seed(work: Path) -> int | None:
    try:
        return int(yaml.safe_load((work / "demo" / "telemax_lab" / "scenario.yaml").read_text())["seed"])
    except (OSError, KeyError, TypeError, ValueError):
        return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=list(UNITS), choices=UNITS, metavar="NAME",
                        help="the rows to measure: CARMEN logs, husky, demo (default: all)")
    parser.add_argument("--jobs", type=int, default=1, help="maps run at once (default 1)")
    parser.add_argument("--out", type=Path, default=None, help="keep the result folders here (default: temporary)")
    parser.add_argument("--data", type=Path, default=None, help="the data folder (default: GSLAM_DATA or ../shared/data)")
    args = parser.parse_args(argv)
    quiet_logging("%(asctime)s %(message)s")
    log.setLevel(logging.INFO)
    data = args.data or data_root()
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_self_check_") as tmp:
        work = args.out if args.out is not None else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        units, skipped = units_of([u for u in UNITS if u in args.logs], data, work)
        for s in skipped:
            print(s, file=sys.stderr)
        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            errors = list(pool.map(run_unit, units))
        rows = []
        for unit, error in zip(units, errors):
            if error is None:
                rows.extend(rows_of(unit))
            else:
                skipped.append(error)
        if not rows:
            print("bench self_check: no row measured; the page is left as it was", file=sys.stderr)
            return 1
        body = page(rows, skipped, max(1, args.jobs), demo_seed(work) if DEMO in args.logs else None)
    publish("self_check", "The map's self-check on the CARMEN logs, the Husky bag and the demo", body, argv)
    print(body)
    print(f"{time.perf_counter() - start:.0f} s")
    return 1 if any(e is not None for e in errors) else 0
