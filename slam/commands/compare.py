"""Several variants of the pipeline on the same run: ungated, gated, oracle
and robust-kernel baselines (``gslam compare``).

The run is read and scan-matched once; each variant is a normal result
folder ``OUT/<variant>/`` as ``gslam map`` writes it. ``OUT`` follows the
rule of :mod:`slam.results.outdir` and is built whole beside its place. Beside
the variants:
``comparison.csv`` and ``comparison.md`` (one row per variant, the columns
defined under the table, :data:`DEFINITIONS`; every figure is one of the
variant's ``metrics.json``),
the figures a reader of the paper expects (trajectories over ground truth,
compass-yaw trends, observer alarms over the true fault intervals), and
``report.html``, all of it and each variant's map on one page, under its
provenance (``output.report``; :mod:`slam.outputs.report`,
:mod:`slam.outputs.provenance`).
"""

from __future__ import annotations

import csv
import io
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from slam.config import PipelineConfig, check_given_once, config_files, dump_config, load_config
from validation.base.yamlio import load_yaml, yaml_kind
from slam.errors import GslamError
from validation.base.errors import InputError
from slam.results.outdir import result_folder
from slam.results.records import PLAIN_NAME, PLAIN_NAME_RULE
from slam.pipeline.folder import RESULT_FILES, MapResult, MappingPipeline
from slam.outputs.provenance import collect
from slam.outputs.report import Figure, Section, Table, write_report
from slam.resources import shipped_config

log = logging.getLogger(__name__)

COMPARE_FILES = ("comparison.csv", "comparison.md", "report.html", "trajectories.png", "trajectories_full.png",
                 "compass_trends.png", "observer_alarms.png", "gating_timeline.png")
"""The files of a comparison beside its variants' folders."""

COLUMNS: tuple[tuple[str, str, str], ...] = (
    # (metrics.json key, column header, format)
    ("ate_rmse_m", "ATE RMSE [m]", "{:.3f}"),
    ("ate_rmse_unaligned_m", "ATE unaligned [m]", "{:.3f}"),
    ("rpe_trans_pct", "RPE trans [%]", "{:.2f}"),
    ("rpe_rot_deg_per_m", "RPE rot [deg/m]", "{:.4f}"),
    ("final_error_m", "final error [m]", "{:.3f}"),
    ("yaw_rmse_deg", "yaw RMSE [deg]", "{:.2f}"),
    ("runtime_with_shared_s", "runtime [s]", "{:.2f}"),
    ("alarm_fraction", "alarm fraction", "{:.3f}"),
    ("isolation_precision", "isolation precision", "{:.3f}"),
    ("isolation_recall", "isolation recall", "{:.3f}"),
    ("faults_missed", "faults missed", "{:d}"),
    ("false_alarm_fraction", "false alarm fraction", "{:.3f}"),
)

DEFINITIONS: dict[str, str] = {
    "runtime [s]": "runtime_with_shared_s, the seconds from reading the input to writing metrics.json "
                   "(runtime_s; process start and imports not counted), plus, for a variant that reused an earlier "
                   "variant's reading and scan matching, the seconds those took there (its timings_s read and "
                   "frontend): what the variant costs on its own",
    "alarm fraction": "share of validation steps with an alarm (the oracle: where it gated a factor)",
    "isolation precision, recall": "over the steps, the blamed components that were truly faulty, over those blamed "
                                   "and over those truly faulty",
    "faults missed": "true fault intervals no diagnosis named within their span, of all true fault intervals "
                     "(faults_missed of faults_missed + faults_detected)",
    "false alarm fraction": "share of validation steps with an alarm while no component was inside a true fault",
}
"""What each column but the errors means, printed under the table; the
metrics are those of each variant's ``metrics.json`` (definitions in
:mod:`validation.metrics`), "–" where the variant has none (no validation,
no truth)."""

_MISSED_OF = ("faults_missed", "faults_detected")


@dataclass
class CompareResult:
    """The comparison folder, each variant's result, and the seconds
    ``report.html`` took (0 without one)."""

    out_dir: Path
    results: dict[str, MapResult]
    report_s: float = 0.0

    def table(self) -> list[dict[str, Any]]:
        rows = []
        for name, res in self.results.items():
            row = {"variant": name}
            row.update({key: res.metrics.get(key) for key in _csv_keys()})
            rows.append(row)
        return rows


def _csv_keys() -> list[str]:
    """The metrics of a row: the columns', and the detected faults beside the missed."""
    keys = [key for key, _, _ in COLUMNS]
    return keys + [k for k in _MISSED_OF if k not in keys]


def load_variants(path: str | Path, only: list[str] | None = None) -> dict[str, list[str]]:
    """Variants from YAML: name -> mapping of dotted overrides."""
    data = load_yaml(path, "variants file")
    variants: dict[str, list[str]] = {}
    folded: dict[str, str] = {}
    reserved = {f.casefold() for f in COMPARE_FILES}
    for key, overrides in data.items():
        if not isinstance(key, str):
            raise GslamError(f"{path}: variant name {_yaml_scalar(key)}: YAML reads it as {yaml_kind(key)}, not as a "
                             "name; quote it (a variant's name names its result folder)")
        name = key
        if not PLAIN_NAME.fullmatch(name) or name.casefold() in reserved:
            raise GslamError(f"{path}: variant {name!r}: a variant's name names its result folder: {PLAIN_NAME_RULE}, "
                             f"other than {', '.join(COMPARE_FILES)} in any case")
        other = folded.setdefault(name.casefold(), name)
        if other != name:
            raise GslamError(f"{path}: variants {other!r} and {name!r} differ only in case: on a file system that "
                             "ignores case (macOS, Windows) their result folders would be one; rename one")
        if not isinstance(overrides, dict):
            raise GslamError(f"{path}: variant '{name}': expected a mapping of dotted.key: value")
        variants[name] = [f"{k}={_yaml_scalar(v)}" for k, v in overrides.items()]
    if only:
        unknown = [n for n in only if n not in variants]
        if unknown:
            raise GslamError(f"{path}: unknown variant '{unknown[0]}' (known: {', '.join(variants)})")
        variants = {n: variants[n] for n in only}
    if not variants:
        raise GslamError(f"{path}: no variants")
    return variants


def _yaml_scalar(value: Any) -> str:
    """``value`` as YAML text that parses back to it (for a ``--set``)."""
    if isinstance(value, str):
        return value
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()


def _table(rows: list[dict[str, Any]]) -> Table:
    """The comparison table's headers and formatted cells."""
    headers = ["variant"] + [h for _, h, _ in COLUMNS]
    cells = [[row["variant"]] + [_cell(row, k, fmt) for k, _, fmt in COLUMNS] for row in rows]
    return Table(headers, cells)


def _cell(row: dict[str, Any], key: str, fmt: str) -> str:
    value = row.get(key)
    if value is None:
        return "–"
    if key == _MISSED_OF[0] and row.get(_MISSED_OF[1]) is not None:
        return f"{value} of {value + row[_MISSED_OF[1]]}"
    return fmt.format(value)


def definitions_text() -> list[str]:
    """One line per defined column, as printed under the table."""
    return [f"{name}: {text}." for name, text in DEFINITIONS.items()]


def _markdown(rows: list[dict[str, Any]], title: str) -> str:
    table = _table(rows)
    lines = [f"# {title}", "", "| " + " | ".join(table.headers) + " |", "|" + "---|" * len(table.headers)]
    lines += ["| " + " | ".join(cells) + " |" for cells in table.rows]
    lines += ["", *(f"- {line}" for line in definitions_text())]
    return "\n".join(lines) + "\n"


def _csv(rows: list[dict[str, Any]]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=["variant", *_csv_keys()], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return out.getvalue()


def run_compare(
    input_path: str | Path,
    config_path: str | Path,
    out_dir: str | Path,
    variants_path: str | Path | None = None,
    only: list[str] | None = None,
    overrides: list[str] | None = None,
    progress: bool = False,
    force: bool = False,
    command: str | None = None,
) -> CompareResult:
    """Run every variant on ``input_path``; see the module docstring.
    ``variants_path``: default the shipped ``configs/variants.yaml``;
    ``force``: see :mod:`slam.results.outdir`; ``command``: the command
    line ``report.html`` names (default: this process's)."""
    out_dir = Path(out_dir)
    variants_path = Path(variants_path) if variants_path is not None else shipped_config("variants.yaml")
    variants = load_variants(variants_path, only)
    check_given_once(overrides or [])
    base = load_config(config_path, overrides or [])  # errors of the config and --set first
    configs = {name: _variant_config(config_path, overrides or [], variants_path, name, ov) for name, ov in variants.items()}
    names = [*COMPARE_FILES, *(f"{v}/{f}" for v in variants for f in RESULT_FILES)]
    inputs = [input_path, *config_files(config_path), variants_path]
    with result_folder(out_dir, "compare", inputs, force, names) as tmp:
        results, recording = _run_variants(input_path, configs, tmp, progress)
        result = CompareResult(tmp, results)
        rows = result.table()
        (tmp / "comparison.csv").write_text(_csv(rows))
        (tmp / "comparison.md").write_text(_markdown(rows, f"{recording.name}: variants compared"))
        timelines = _timelines(results, recording)
        _figures(tmp, results, recording, timelines)
        if base.output.report:
            made = collect(input_path, config_path, dump_config(base), command)
            report_s = _report(tmp, rows, recording, made.rows(), results, timelines)
        else:
            report_s = 0.0
    for name, res in results.items():
        res.out_dir = out_dir / name
    return CompareResult(out_dir, results, report_s)


def _variant_config(config_path, overrides: list[str], variants_path: Path, name: str, ov: list[str]) -> PipelineConfig:
    try:
        # A key of the variant's that --set also gives: the variant's would win, --set's "for every variant" not.
        check_given_once([*overrides, *ov], [*(f"--set {text}" for text in overrides), *ov])
        return load_config(config_path, [*overrides, *ov])
    except InputError as e:
        message = str(e)
        for text in ov:  # the variant's own keys: blame the variants file
            message = message.replace(f"--set {text}: ", f"{text}: ")
        raise GslamError(f"{variants_path}: variant '{name}': {message}") from None


def _run_variants(
    input_path: str | Path, configs: dict[str, PipelineConfig], folder: Path, progress: bool
) -> tuple[dict[str, MapResult], object]:
    """Each variant into ``folder/<name>``, sharing reading and scan matching.

    matplotlib is imported here once: the comparison's figures need it, and
    each variant's figures are drawn by a process forked from this one
    (slam.outputs.result_writer), which then starts with it loaded."""
    import slam.outputs.plots  # noqa: F401
    from tqdm import tqdm

    recording, frontend, frontend_cfg = None, None, None
    read_s = frontend_s = 0.0  # what the reading and the last scan matching took, for those who reuse them
    results: dict[str, MapResult] = {}
    # disable=None: a bar only on a terminal, never into a piped log.
    with tqdm(total=len(configs), desc="compare", unit="variant", leave=False, disable=None if progress else True) as bar:
        for name, cfg in configs.items():
            bar.set_postfix_str(name)
            if frontend_cfg is not None and cfg.frontend != frontend_cfg:
                frontend = None  # this variant changes the front-end: match again
            reused_s = (read_s if recording is not None else 0.0) + (frontend_s if frontend is not None else 0.0)
            pipe = MappingPipeline(input_path, cfg, folder / name, progress=progress, recording=recording,
                                   frontend=frontend, shared_s=reused_s)
            results[name] = res = pipe.run()
            timings = res.metrics.get("timings_s", {})
            if recording is None:
                read_s = timings.get("read", 0.0)
            if frontend is None:
                frontend_s = timings.get("frontend", 0.0)
            recording, frontend, frontend_cfg = pipe.recording, pipe.frontend, cfg.frontend
            log.info("%s: ATE %s m", name, res.metrics.get("ate_rmse_m"))
            bar.update(1)
    return results, recording


def _timelines(results: dict[str, MapResult], recording) -> list:
    """The gating timeline of each variant validated with a diagnosis."""
    from slam.outputs.gating_timeline import gating_timeline, has_timeline

    return [gating_timeline(name, r.validation, recording.fault_truth)
            for name, r in results.items() if has_timeline(r.validation)]


def _report(folder: Path, rows: list[dict[str, Any]], recording, provenance: list[tuple[str, str]],
            results: dict[str, MapResult], timelines: list) -> float:
    """``report.html``: its provenance, the table, each variant's self-check,
    the comparison's figures, the gating timeline and each variant's map;
    the seconds it took."""
    from slam.outputs.gating_timeline import timeline_note, timeline_tables
    from slam.outputs.self_check import SELF_CHECK_NOTE, self_check_table
    from slam.outputs.validation_figures import observer_alarms_note

    t = time.perf_counter()
    variants = [row["variant"] for row in rows]
    sections = [
        Section("Variants compared", " ".join(definitions_text()) + " Each variant's result folder holds its files "
                "(trajectory.tum, metrics.json, map.pgm, run.mcap).", tables=[_table(rows)]),
        Section("Self-check", SELF_CHECK_NOTE,
                tables=[self_check_table({v: r.metrics.get("self_check") for v, r in results.items()})]),
        Section("Trajectories", figures=[
            Figure(folder / "trajectories.png", "every variant over the reference, around it"),
            Figure(folder / "trajectories_full.png", "every variant over the reference, whole"),
        ]),
        Section("Yaw trends (the paper's Fig. 2)", "The gated variant's yaw streams and their trend symbols.",
                figures=[Figure(folder / "compass_trends.png", "yaw streams and trends")]),
        Section("Observer timelines (the paper's Fig. 3)", observer_alarms_note(recording.fault_truth),
                figures=[Figure(folder / "observer_alarms.png", "observers")]),
    ]
    if timelines:
        metrics = {tl.variant: results[tl.variant].metrics for tl in timelines}
        sections.append(Section("Gating timeline", timeline_note(timelines), tables=timeline_tables(timelines, metrics),
                                figures=[Figure(folder / "gating_timeline.png", "gating timeline")]))
    sections += [
        Section("Maps", "Each variant's occupancy grid and trajectory (map.png).", small=True,
                figures=[Figure(folder / v / "map.png", v) for v in variants]),
    ]
    write_report(folder / "report.html", f"{recording.name}: variants compared", sections, provenance=provenance)
    elapsed = time.perf_counter() - t
    log.info("report.html in %.2f s", elapsed)
    return elapsed


def _figures(out: Path, results: dict[str, MapResult], recording, timelines: list) -> None:
    from slam.outputs.gating_timeline import plot_gating_timeline
    from slam.outputs.plots import fault_shading, plot_trajectories
    from slam.outputs.validation_figures import plot_observer_alarms, plot_yaw_trends

    shaded = fault_shading(recording.fault_truth or {})
    trajectories = {name: r.trajectory for name, r in results.items()}
    title = f"{recording.name}: variants over the reference"
    on_top = [name for name in ("oracle", "gated") if name in trajectories]
    plot_trajectories(out / "trajectories.png", trajectories, recording.groundtruth, title, shaded,
                      zoom_margin=0.25, highlight=on_top)
    plot_trajectories(out / "trajectories_full.png", trajectories, recording.groundtruth, title, shaded,
                      highlight=on_top)
    gated = results.get("gated")
    validation = gated.validation if gated is not None else None
    if validation is not None and validation.observer_log is not None:
        plot_yaw_trends(out / "compass_trends.png", recording, validation)
        plot_observer_alarms(out / "observer_alarms.png", recording, validation)
    if timelines:
        plot_gating_timeline(out / "gating_timeline.png", recording.name, timelines)
