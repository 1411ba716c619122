"""Summaries of a sweep: ``summary.csv`` (one row per job), ``summary.md``
(mean ± std over seeds per input, variant and sweep point) and figures of
the headline metrics against each swept parameter.

The CSV is built only from the job folders' ``metrics.json`` (nested
mappings flattened with dots, e.g. ``timings_s.optimise``,
``detection_delay_s.IMU_YAW``), written with Python's round-trip float
text, so its numbers equal the files. One derived column is added:
``detection_delay_mean_s``, the mean of the per-component delays.
"""

from __future__ import annotations

import csv
import difflib
import io
import json
import logging
import math
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from slam.errors import GslamError
from validation.base.yamlio import unique_keys
from slam.outputs import report
from slam.commands.ablate.jobs import Job
from slam.commands.ablate.spec import AblationSpec
from slam.results.atomic import write_text
from slam.outputs.plots import save_figure
from slam.outputs.report import Figure as ReportFigure
from slam.outputs.report import Section, Table

log = logging.getLogger(__name__)

JOB_COLUMNS = ("job_id", "status", "error", "input", "seed", "variant")
# (column, label) of the headline metrics in summary.md and the figures.
HEADLINE: tuple[tuple[str, str], ...] = (
    ("ate_rmse_m", "ATE RMSE [m]"),
    ("detection_delay_mean_s", "detection delay [s]"),
    ("alarm_fraction", "alarm fraction"),
    ("isolation_precision", "isolation precision"),
    ("isolation_recall", "isolation recall"),
    ("faults_missed", "faults missed"),
    ("runtime_s", "runtime [s]"),
)
FIGURE_METRICS = ("ate_rmse_m", "detection_delay_mean_s", "alarm_fraction", "isolation_precision")
TIMING_COLUMNS = ("runtime_s", "realtime_factor", "validation_time_s")


@dataclass
class Summary:
    """The rows of ``summary.csv``, the files written, and the seconds
    ``report.html`` took (0 without one)."""

    rows: list[dict[str, Any]]
    columns: list[str]
    csv_path: Path
    md_path: Path
    figures: list[Path]
    report_s: float = 0.0


def flatten(metrics: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{'a': {'b': 1}}`` -> ``{'a.b': 1}``; lists are kept as JSON text."""
    flat: dict[str, Any] = {}
    for k, v in metrics.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            flat.update(flatten(v, key + "."))
        elif isinstance(v, list):
            flat[key] = json.dumps(v)
        else:
            flat[key] = v
    return flat


def job_row(out_dir: Path, job: Job) -> dict[str, Any]:
    """One job's row: what the job was, and its metrics if it finished."""
    row: dict[str, Any] = {"job_id": job.id, "input": job.input_label, "seed": job.seed, "variant": job.variant}
    row.update(job.params)
    metrics_path = out_dir / "jobs" / job.id / "metrics.json"
    failed_path = out_dir / "failed" / f"{job.id}.json"
    if metrics_path.exists():
        metrics = flatten(_job_json(metrics_path, out_dir / "jobs" / job.id))
        metrics["input_path"] = metrics.pop("input", None)
        delays = [v for k, v in metrics.items() if k.startswith("detection_delay_s.") and v is not None]
        metrics["detection_delay_mean_s"] = float(np.mean(delays)) if delays else None
        row.update(status="ok", error=None, **metrics)
    elif failed_path.exists():
        row.update(status="failed", error=_job_json(failed_path, failed_path).get("error"))
    else:
        row.update(status="missing", error=None)
    return row


def _job_json(path: Path, remove: Path) -> dict[str, Any]:
    """A job's JSON file of an earlier run into the sweep's folder (its
    metrics, its failure), read back as input: a one-line
    :class:`GslamError` naming it if it is not the JSON object gslam
    writes (edited, or not gslam's), and what to remove to run the job
    again."""
    try:
        data = json.loads(path.read_text(), object_pairs_hook=unique_keys)
        why = None if isinstance(data, dict) else f"a JSON {type(data).__name__}"
    except ValueError as e:  # not UTF-8, not JSON
        why = f"invalid JSON ({str(e).splitlines()[0]})"
    except RecursionError:
        why = "JSON nested too deeply"
    if why is not None:
        raise GslamError(f"{path}: expected the JSON object gslam writes, found {why}; remove {remove} to run the "
                         "job again")
    return data


def write_summary(out_dir: Path, jobs: list[Job], spec: AblationSpec, report_html: bool = True) -> Summary:
    """Write ``summary.csv``, ``summary.md``, ``plots/*.png`` and, with
    ``report_html``, ``report.html`` into ``out_dir``."""
    rows = [job_row(out_dir, job) for job in jobs]
    sweep_keys = spec.sweep_keys()
    columns = list(JOB_COLUMNS) + sweep_keys
    for row in rows:
        columns += [k for k in row if k not in columns]
    _check_metrics_named(spec, rows, columns)
    csv_path, md_path = out_dir / "summary.csv", out_dir / "summary.md"
    write_text(csv_path, _csv(rows, columns))
    write_text(md_path, _markdown(rows, spec, sweep_keys))
    figures = _figures(out_dir / "plots", rows, spec, sweep_keys)
    summary = Summary(rows, columns, csv_path, md_path, figures)
    if report_html:
        t = time.perf_counter()
        write_report(out_dir, rows, spec, figures)
        summary.report_s = time.perf_counter() - t
    return summary


def _check_metrics_named(spec: AblationSpec, rows: list[dict[str, Any]], columns: list[str]) -> None:
    """One warning line for each metric of the spec's ``metrics`` that no
    finished job wrote (a typo): its column of summary.md would be '–', as
    for a metric of no value. Said once the jobs ran: which metrics a job
    writes depends on its input and config."""
    if not spec.metrics or not any(r["status"] == "ok" for r in rows):
        return
    written = [c for c in columns if c not in JOB_COLUMNS and c not in spec.sweep_keys() and c != "input_path"]
    for metric in spec.metrics:
        if metric not in written:
            near = difflib.get_close_matches(metric, written, n=1)
            hint = f"did you mean '{near[0]}'? " if near else ""
            log.warning("metrics: no finished job wrote '%s', so its column of summary.md is empty; %sthe metrics "
                        "are the columns of summary.csv (%d), e.g. %s", metric, hint, len(written),
                        ", ".join(m for m, _ in HEADLINE))


def _csv(rows: list[dict[str, Any]], columns: list[str]) -> str:
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: _cell(row.get(k)) for k in columns})
    return out.getvalue()


def _cell(value: Any) -> Any:
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return value


def _numbers(rows: list[dict[str, Any]], key: str) -> list[float]:
    vals = [r.get(key) for r in rows if r["status"] == "ok"]
    return [float(v) for v in vals if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)]


def _mean_std(vals: list[float], digits: int = 3) -> str:
    if not vals:
        return "–"
    if len(vals) == 1:
        return f"{vals[0]:.{digits}f}"
    return f"{np.mean(vals):.{digits}f} ± {np.std(vals, ddof=1):.{digits}f}"


def short_names(keys: list[str]) -> dict[str, str]:
    """Each swept key by its last segment, or in full where two would clash."""
    last = [k.split(".")[-1] for k in keys]
    return {k: (s if last.count(s) == 1 else k) for k, s in zip(keys, last)}


def _fmt(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _groups(rows: list[dict[str, Any]], keys: list[str]) -> dict[tuple, list[dict[str, Any]]]:
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        groups[(r["input"], r["variant"], *(json.dumps(r.get(k)) for k in keys))].append(r)
    return groups


def summary_tables(rows: list[dict[str, Any]], spec: AblationSpec, keys: list[str]) -> dict[str, Table]:
    """Per input, the table of ``summary.md``: a row per variant and sweep
    point, mean ± std over seeds of each headline metric."""
    metrics = [(m, dict(HEADLINE).get(m, m)) for m in spec.metrics] if spec.metrics else list(HEADLINE)
    short = short_names(keys)
    by_input: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in rows:
        by_input[r["input"]].append(r)
    tables = {}
    for name, group in by_input.items():
        headers = ["variant"] + [short[k] for k in keys] + ["n"] + [label for _, label in metrics]
        cells = []
        for (_, variant, *_), members in _groups(group, keys).items():
            ok = sum(r["status"] == "ok" for r in members)
            point = [_fmt(members[0].get(k)) if members[0].get(k) is not None else "–" for k in keys]
            cells.append([variant] + point + [f"{ok}/{len(members)}"] + [_mean_std(_numbers(members, m)) for m, _ in metrics])
        tables[name] = Table(headers, cells)
    return tables


def _intro(rows: list[dict[str, Any]], keys: list[str]) -> list[str]:
    """The lines under the title: the count of jobs, the swept keys' full names."""
    n_ok = sum(r["status"] == "ok" for r in rows)
    short = short_names(keys)
    lines = [f"{len(rows)} jobs, {n_ok} finished, {len(rows) - n_ok} failed or missing. "
             "Mean ± std (sample) over seeds; n = finished / jobs."]
    lines += [f"`{s}`: `{k}`" + ("  " if i < len(keys) - 1 else "") for i, (k, s) in enumerate(short.items()) if s != k]
    return lines


def _markdown(rows: list[dict[str, Any]], spec: AblationSpec, keys: list[str]) -> str:
    lines = [f"# {spec.name}", ""]
    if spec.description:
        lines += [spec.description.strip(), ""]
    lines += _intro(rows, keys)
    lines.append("")
    for name, table in summary_tables(rows, spec, keys).items():
        lines += [f"## {name}", "", "| " + " | ".join(table.headers) + " |", "|" + "---|" * len(table.headers)]
        lines += ["| " + " | ".join(cells) + " |" for cells in table.rows]
        lines.append("")
    failed = [r for r in rows if r["status"] == "failed"]
    if failed:
        lines += ["## Failed jobs", ""] + [f"- `{r['job_id']}`: {r['error']}" for r in failed] + [""]
    return "\n".join(lines)


def write_report(out_dir: Path, rows: list[dict[str, Any]], spec: AblationSpec, figures: list[Path]) -> None:
    """``report.html``: the description, each input's table, the failed
    jobs and the plots, on one page (:mod:`slam.outputs.report`)."""
    keys = spec.sweep_keys()
    sections = [Section(name, tables=[table]) for name, table in summary_tables(rows, spec, keys).items()]
    failed = [r for r in rows if r["status"] == "failed"]
    if failed:
        sections.append(Section("Failed jobs", tables=[Table(["job", "error"], [[r["job_id"], str(r["error"])] for r in failed])]))
    sections.append(Section("Plots", "Each headline metric against each swept value: mean ± std over seeds and "
                            "the other swept values.", figures=[ReportFigure(p, f"against {p.stem}") for p in figures]))
    intro = " ".join([spec.description.strip()] if spec.description else []) + " " + " ".join(
        line.replace("`", "") for line in _intro(rows, keys))
    report.write_report(out_dir / "report.html", spec.name, sections, intro.strip())


def _figures(plot_dir: Path, rows: list[dict[str, Any]], spec: AblationSpec, keys: list[str]) -> list[Path]:
    """One figure per swept key (and one over variants when there are
    several): each headline metric against the value, one line per input
    and variant, mean ± std over seeds and the other swept values."""
    axes_keys = [k for k in keys if len({json.dumps(r.get(k)) for r in rows if r.get(k) is not None}) > 1]
    if len(spec.variants) > 1:
        axes_keys.append("variant")
    paths = []
    for key in axes_keys:
        path = plot_dir / f"{_file_name(key)}.png"
        _plot_against(path, rows, key)
        paths.append(path)
    return paths


def _file_name(key: str) -> str:
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in key)


def _plot_against(path: Path, rows: list[dict[str, Any]], key: str) -> None:
    ok = [r for r in rows if r["status"] == "ok" and r.get(key) is not None]
    values = []
    for r in ok:
        if r[key] not in values:
            values.append(r[key])
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    if numeric:
        values = sorted(values)
    xpos = {json.dumps(v): (float(v) if numeric else i) for i, v in enumerate(values)}
    lines: dict[tuple[str, str], list[dict[str, Any]]] = defaultdict(list)
    for r in ok:
        lines[(r["input"], "all" if key == "variant" else r["variant"])].append(r)
    fig = Figure(figsize=(11, 8))
    for i, metric in enumerate(FIGURE_METRICS):
        ax = fig.add_subplot(2, 2, i + 1)
        for n, ((inp, variant), members) in enumerate(lines.items()):
            xs, ms, ss = [], [], []
            for v in values:
                vals = _numbers([r for r in members if r[key] == v], metric)
                if vals:
                    xs.append(xpos[json.dumps(v)])
                    ms.append(np.mean(vals))
                    ss.append(np.std(vals))
            if xs:
                label = inp if key == "variant" else f"{inp} / {variant}"
                # a fixed colour per line: a metric missing for one line must not shift the others
                ax.errorbar(xs, ms, yerr=ss, marker="o", capsize=3, label=label, color=f"C{n % 10}")
        ax.set_ylabel(dict(HEADLINE)[metric])
        ax.set_xlabel(key)
        if not numeric:
            ax.set_xticks(range(len(values)), [str(v) for v in values], rotation=30, ha="right")
        ax.grid(alpha=0.3)
    legend = {}
    for ax in fig.axes:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            legend.setdefault(lab, h)
    handles, labels = list(legend.values()), list(legend)
    if handles:
        fig.legend(handles, labels, loc="lower center", ncol=min(4, len(labels)), fontsize="small")
    fig.suptitle(f"against {key}: mean ± std over seeds and other swept values")
    fig.tight_layout(rect=(0, 0.08, 1, 0.96))
    save_figure(fig, path)
