"""When the gate acted, against the true faults: the timeline of
``report.html``.

For each variant validated with a diagnosis (``validation.mode: on``):

* the gated spans: for each factor type and degree of freedom, the runs of
  validation steps it was excluded or inflated (the ``gate.<factor>.<dof>``
  columns of ``validation.csv``), from a step's time to the next step's;
* the true fault intervals, each detected (with its delay, from onset to
  the first step within it whose diagnoses name the component) or missed,
  by :func:`validation.metrics.validation_metrics`' own rule applied to that
  interval alone;
* the false alarms: runs of steps whose most probable diagnosis blames a
  component (or that have no diagnosis) while no component is inside a true
  fault.

The truth is the recording's as read (``Recording.fault_truth``); a
recording without it has no fault rows, no missed faults and no false
alarms, and no "true ... fault" anywhere in the timeline.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from validation.metrics import validation_metrics

Interval = tuple[float, float]

_ACTION_COLORS = {"exclude": "tab:red", "inflate": "tab:orange"}
_FALSE_ALARM_COLOR = "tab:purple"


@dataclass(frozen=True)
class GatedSpan:
    """One factor type's degree of freedom excluded or inflated from
    ``start_s`` to ``end_s`` (recording time, s)."""

    factor: str
    dof: str
    action: str
    start_s: float
    end_s: float


@dataclass(frozen=True)
class FaultOutcome:
    """One true fault interval of a component and whether validation named
    it within its span; ``delay_s``: onset to the first naming step."""

    component: str
    start_s: float
    end_s: float
    detected: bool
    delay_s: float | None


@dataclass
class GatingTimeline:
    """One validated variant's timeline; ``faults`` and ``false_alarms``
    are None without truth."""

    variant: str
    step_t: np.ndarray
    spans: list[GatedSpan]
    faults: list[FaultOutcome] | None
    false_alarms: list[Interval] | None


def _runs(on: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True."""
    starts = np.flatnonzero(on & ~np.r_[False, on[:-1]])
    ends = np.flatnonzero(on & ~np.r_[on[1:], False])
    return list(zip(starts.tolist(), ends.tolist()))


def _step_end(step_t: np.ndarray, k: int) -> float:
    """Where step ``k``'s decision ends: at the next step, or one step on."""
    if k + 1 < len(step_t):
        return float(step_t[k + 1])
    dt = float(np.median(np.diff(step_t))) if len(step_t) > 1 else 0.0
    return float(step_t[k]) + dt


def gated_spans(validation) -> list[GatedSpan]:
    """Every factor type's excluded and inflated runs, per degree of
    freedom, in ``validation.csv``'s column order."""
    t = validation.step_t
    spans = []
    for factor in sorted(validation.step_scales):
        scales = validation.step_scales[factor]
        for i, dof in enumerate(validation.factor_dofs[factor]):
            excluded = ~np.isfinite(scales[:, i])
            inflated = np.isfinite(scales[:, i]) & (scales[:, i] > 1.0)
            for action, on in (("exclude", excluded), ("inflate", inflated)):
                spans += [GatedSpan(factor, dof, action, float(t[a]), _step_end(t, b)) for a, b in _runs(on)]
    return sorted(spans, key=lambda s: (s.factor, s.dof, s.start_s))


def fault_outcomes(validation, truth: Mapping[str, Sequence[Interval]]) -> list[FaultOutcome]:
    """Each true fault interval, detected or missed, with its delay."""
    out = []
    for comp, intervals in truth.items():
        for a, b in intervals:
            one = validation_metrics(validation.step_t, validation.results, validation.actions,
                                     {comp: [(a, b)]}, validation.sensors)
            if one["faults_missed"] == 0 and one["faults_detected"] == 0:
                continue  # no validation step inside it: neither
            out.append(FaultOutcome(comp, float(a), float(b), one["faults_detected"] == 1,
                                    one["detection_delay_s"][comp]))
    return sorted(out, key=lambda f: (f.start_s, f.component))


def false_alarms(validation, truth: Mapping[str, Sequence[Interval]]) -> list[Interval]:
    """Runs of alarm steps while no component is inside a true fault."""
    t = validation.step_t
    alarm = np.array([not r.consistent or bool(r.diagnoses[0]) for r in validation.results], dtype=bool)
    faulty = np.zeros(len(t), dtype=bool)
    for intervals in truth.values():
        for a, b in intervals:
            faulty |= (t >= a) & (t <= b)
    return [(float(t[a]), _step_end(t, b)) for a, b in _runs(alarm & ~faulty)]


def gating_timeline(variant: str, validation, truth: Mapping[str, Sequence[Interval]] | None) -> GatingTimeline:
    """The timeline of one variant's validation; ``truth``: the recording's
    ``fault_truth`` (None or empty: no truth)."""
    known = bool(truth) and validation.results is not None
    return GatingTimeline(variant, validation.step_t, gated_spans(validation),
                          fault_outcomes(validation, truth) if known else None,
                          false_alarms(validation, truth) if known else None)


def has_timeline(validation) -> bool:
    """Whether a variant's validation has a diagnosis to draw: validated, not an oracle."""
    return validation is not None and getattr(validation, "results", None) is not None


def plot_gating_timeline(path: str | Path, name: str, timelines: Sequence[GatingTimeline]) -> None:
    """One panel per variant: a row per gated factor type and degree of
    freedom (red excluded, orange inflated), a row of false alarms, and a
    row per component with true faults (detected in its colour, missed
    hatched and marked "missed", the delay written at the onset)."""
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    from slam.outputs.plots import fault_color, save_figure

    panels = []
    for tl in timelines:
        rows = sorted({(s.factor, s.dof) for s in tl.spans})
        comps = sorted({f.component for f in tl.faults or ()})
        panels.append((tl, rows, comps))
    heights = [max(1, len(rows) + len(comps) + (tl.false_alarms is not None)) for tl, rows, comps in panels]
    fig = Figure(figsize=(10, 1.4 + 0.38 * sum(heights) + 0.5 * len(panels)))
    axes = fig.subplots(len(panels), 1, squeeze=False, sharex=True,
                        gridspec_kw={"height_ratios": heights})[:, 0]
    for ax, (tl, rows, comps), n in zip(axes, panels, heights):
        labels = [f"{factor}.{dof}" for factor, dof in rows]
        y_of = {row: n - 1 - i for i, row in enumerate(rows)}
        for s in tl.spans:
            y = y_of[(s.factor, s.dof)]
            ax.broken_barh([(s.start_s, s.end_s - s.start_s)], (y - 0.35, 0.7), color=_ACTION_COLORS[s.action],
                           zorder=3)
        if tl.false_alarms is not None:
            y = n - 1 - len(rows)
            labels.append("false alarm")
            ax.broken_barh([(a, b - a) for a, b in tl.false_alarms], (y - 0.35, 0.7), color=_FALSE_ALARM_COLOR,
                           zorder=3)
        for j, comp in enumerate(comps):
            y = n - 1 - len(rows) - 1 - j
            labels.append(f"true fault: {comp}")
            for f in (f for f in tl.faults if f.component == comp):
                ax.broken_barh([(f.start_s, f.end_s - f.start_s)], (y - 0.35, 0.7), facecolor=fault_color(comp),
                               edgecolor="0.3", linewidth=0.5, hatch=None if f.detected else "///", zorder=3)
                text = f"+{f.delay_s:.1f} s" if f.detected and f.delay_s is not None else "missed"
                ax.text(f.start_s, y, f" {text}", va="center", ha="left", fontsize="x-small", zorder=4)
        ax.set_yticks(range(n - 1, n - 1 - len(labels), -1), labels, fontsize="small")
        ax.set_ylim(-0.7, n - 0.3)
        ax.set_title(f"{tl.variant}" + ("" if rows else ": nothing gated"), fontsize="small", loc="left")
        ax.grid(True, axis="x", linewidth=0.5, alpha=0.5)
        ax.set_axisbelow(True)
        if len(tl.step_t):
            ax.set_xlim(tl.step_t[0], _step_end(tl.step_t, len(tl.step_t) - 1))
    handles = [Patch(color=c, label=f"{a}d") for a, c in _ACTION_COLORS.items()]
    if any(tl.faults is not None for tl in timelines):
        handles += [Patch(color=_FALSE_ALARM_COLOR, label="false alarm"),
                    Patch(facecolor="white", edgecolor="0.3", hatch="///", label="true fault, missed")]
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"{name}: factors gated over time", fontsize="medium")
    # Below the time axis, where no bar or title can be under it (the PNG is cut to what is drawn).
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=len(handles),
               fontsize="small", frameon=False)
    save_figure(fig, path)


def timeline_note(timelines: Sequence[GatingTimeline]) -> str:
    """What the report's section shows; it names the true faults only where there are some."""
    note = ("When the gate acted in each variant validated with a diagnosis: per factor type and degree of "
            "freedom, the spans it was excluded (red) or inflated (orange), from validation.csv.")
    if any(tl.faults is not None for tl in timelines):
        note += (" Under them the false alarms (alarm steps while no component was inside a true fault) and each "
                 "true fault interval of the recording's truth, detected (with its delay from onset to the first "
                 "step naming it) or missed (hatched). metrics.json scores validation against those and also "
                 "against the times the scan matcher was wrong by ground truth, so its figures may differ.")
    return note


def timeline_tables(timelines: Sequence[GatingTimeline], metrics: Mapping[str, Mapping]) -> list:
    """The report's tables: each variant's figures from ``metrics.json``
    (faults missed and detected, false alarm fraction, detection delay per
    component), the true faults detected or missed, the false alarms, and
    the gated spans."""
    from slam.outputs.report import Table

    def num(value, fmt: str = "{:.1f}") -> str:
        return "–" if value is None else fmt.format(value)

    summary = []
    for tl in (tl for tl in timelines if tl.faults is not None):
        m = metrics.get(tl.variant, {})
        delays = m.get("detection_delay_s") or {}
        summary.append([tl.variant, num(m.get("faults_missed"), "{:d}"), num(m.get("faults_detected"), "{:d}"),
                        num(m.get("false_alarm_fraction"), "{:.3f}"),
                        ", ".join(f"{c} {num(d)}" for c, d in delays.items()) or "–"])
    tables = [Table(["variant", "faults missed", "faults detected", "false alarm fraction", "detection delay [s]"],
                    summary, "metrics.json")] if summary else []
    faults = [[tl.variant, f.component, f"{f.start_s:.1f}", f"{f.end_s:.1f}", "detected" if f.detected else "missed",
               num(f.delay_s)] for tl in timelines for f in tl.faults or ()]
    if faults:
        tables.append(Table(["variant", "true fault", "from [s]", "to [s]", "outcome", "delay [s]"], faults,
                            "true fault intervals (the recording's truth)"))
    alarms = [[tl.variant, f"{a:.1f}", f"{b:.1f}"] for tl in timelines for a, b in tl.false_alarms or ()]
    if alarms:
        tables.append(Table(["variant", "false alarm from [s]", "to [s]"], alarms, "false alarms"))
    spans = [[tl.variant, s.factor, s.dof, s.action, f"{s.start_s:.1f}", f"{s.end_s:.1f}"]
             for tl in timelines for s in tl.spans]
    tables.append(Table(["variant", "factor", "dof", "action", "from [s]", "to [s]"], spans,
                        "gated spans (validation.csv's gate columns)"))
    return tables
