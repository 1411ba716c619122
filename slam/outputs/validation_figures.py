"""Figures of a validated run, after the paper's:

* :func:`plot_yaw_trends` (its Fig. 2): the yaw streams over time with the
  qualitative trend symbol of each under it.
* :func:`plot_observer_alarms` (its Fig. 3): every observer's no_match /
  implausible over time, the sensors the diagnosis blamed, and the true
  fault intervals: shaded grey across the figure, and a row per sensor in
  its colour (one legend entry each).
* :func:`plot_system_model` (its Section 4): the components and the
  relations between them, as a graph.

The true faults are the recording's truth (``Recording.fault_truth``: a
run folder's ``truth.json``, a BROAD trial's labels), as read; a recording
without truth has no bands and no "true ... fault" in any legend.

Shading is drawn under everything else, so lines and bars keep the colours
the titles name.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from slam.outputs.plots import fault_color, save_figure
from slam.recording import Recording
from slam.recording import union_intervals

# The fault colours (slam.outputs.plots) are pale and none of them blue or red.
_ALARM_COLOR, _BLAME_COLOR = "tab:blue", "tab:red"


def _shade_faults(ax, recording: Recording, components=None, label: bool = True) -> None:
    """Each component's true fault intervals as a full-height band in its
    colour, below every line and bar; one legend entry per component."""
    for comp, intervals in (recording.fault_truth or {}).items():
        if components is not None and comp not in components:
            continue
        for k, (a, b) in enumerate(intervals):
            ax.axvspan(a, b, color=fault_color(comp), alpha=0.45, lw=0, zorder=0,
                       label=f"true {comp} fault" if label and k == 0 else None)


def plot_yaw_trends(path: str | Path, recording: Recording, validation) -> None:
    """Yaw streams (deg, unwrapped, each from 0) and their trend symbols.

    The symbols are those the observers used (first relation that carries
    each stream), on the validation steps.
    """
    log = validation.observer_log
    symbols: dict[str, np.ndarray] = {}
    for trace in log.relations.values():
        for stream, sym in zip(trace.relation.streams, (trace.symbol_a, trace.symbol_b)):
            if stream.endswith("_yaw") and stream not in symbols:
                symbols[stream] = np.where(trace.valid, sym, np.nan)
    streams = _yaw_streams(recording, validation)
    names = [n for n in ("compass_yaw", "gyro_yaw", "sm_yaw", "odo_yaw") if n in symbols]
    fig = Figure(figsize=(10, 2.2 + 1.2 * len(names)))
    axes = fig.subplots(1 + len(names), 1, sharex=True, gridspec_kw={"height_ratios": [3] + [1] * len(names)})
    top = axes[0]
    sane = []  # the view follows compass and gyro: a failed scan matcher may spin off
    for name in names:
        if name in streams:
            t, yaw = streams[name]
            deg = np.degrees(yaw - yaw[0])
            top.plot(t, deg, label=name, linewidth=1.0)
            if name in ("compass_yaw", "gyro_yaw"):
                sane.append(deg)
    if sane:
        lo, hi = min(d.min() for d in sane), max(d.max() for d in sane)
        pad = 0.2 * (hi - lo) + 10.0
        top.set_ylim(lo - pad, hi + pad)
    _shade_faults(top, recording, {"IMU_YAW", "SM_YAW", "IMU_GYRO", "ODO_YAW"})
    top.set_axisbelow(True)
    top.set_ylabel("yaw change [deg]")
    top.set_title(f"{recording.name}: yaw streams and their qualitative trends")
    top.legend(loc="best", fontsize="small")
    top.grid(True, linewidth=0.5, alpha=0.5)
    for ax, name in zip(axes[1:], names):
        ax.step(log.t, symbols[name], where="post", linewidth=1.0)
        ax.set_yticks([-1, 0, 1], ["−", "0", "+"])
        ax.set_ylim(-1.4, 1.4)
        ax.set_ylabel(name, rotation=0, ha="right", fontsize="small")
        ax.grid(True, linewidth=0.5, alpha=0.5)
        _shade_faults(ax, recording, {"IMU_YAW", "SM_YAW", "IMU_GYRO", "ODO_YAW"}, label=False)
    axes[-1].set_xlabel("time [s]")
    save_figure(fig, path)


def _yaw_streams(recording: Recording, validation) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    from validation.streams import validation_streams

    out = {}
    sm = getattr(validation, "sm_poses", None)
    for name, s in validation_streams(recording, sm).items():
        if name.endswith("_yaw"):
            out[name] = (s.t, np.unwrap(s.values) if s.angular else s.values)
    return out


def plot_observer_alarms(path: str | Path, recording: Recording, validation) -> None:
    """One row per observer (no_match or implausible, blue bars), one row
    per component blamed by the most probable diagnosis (red bars), and one
    row per component with true faults (bars in its colour, which also
    shades those times across the figure)."""
    log = validation.observer_log
    rows: list[tuple[str, np.ndarray, str]] = []
    for name, trace in log.relations.items():
        rows.append((name, trace.no_match & trace.valid, _ALARM_COLOR))
    for name, trace in log.unary.items():
        rows.append((name, trace.implausible & trace.valid, _ALARM_COLOR))
    t = log.t
    if validation.results is not None:
        comps = sorted({c for r in validation.results if r.consistent for c in r.diagnoses[0]})
        for c in comps:
            blamed = np.array([r.consistent and c in r.diagnoses[0] for r in validation.results])
            rows.append((f"blamed: {c}", blamed, _BLAME_COLOR))
    truth = [(c, iv) for c, iv in (recording.fault_truth or {}).items() if iv]
    fig = Figure(figsize=(10, 1.2 + 0.45 * (len(rows) + len(truth))))
    ax = fig.add_subplot()
    dt = np.median(np.diff(t)) if len(t) > 1 else 0.1
    n_rows = len(rows) + len(truth)
    for i, (name, on, color) in enumerate(rows):
        y = n_rows - 1 - i
        starts = np.flatnonzero(on & ~np.r_[False, on[:-1]])
        ends = np.flatnonzero(on & ~np.r_[on[1:], False])
        ax.broken_barh([(t[a], t[b] - t[a] + dt) for a, b in zip(starts, ends)], (y - 0.35, 0.7),
                       color=color, zorder=3)
    for j, (comp, intervals) in enumerate(truth):
        y = n_rows - 1 - len(rows) - j
        ax.broken_barh([(a, b - a) for a, b in intervals], (y - 0.35, 0.7), color=fault_color(comp),
                       edgecolor="0.3", linewidth=0.5, zorder=3, label=f"true {comp} fault")
    names = [n for n, _, _ in rows] + [f"true fault: {c}" for c, _ in truth]
    ax.set_yticks(range(n_rows), list(reversed(names)), fontsize="small")
    # Any true fault, shaded once: overlapping colours would make a colour of their own.
    for k, (a, b) in enumerate(union_intervals(*(iv for _, iv in truth))):
        ax.axvspan(a, b, color="0.88", lw=0, zorder=0, label="any true fault" if k == 0 else None)
    ax.set_axisbelow(True)
    ax.set_xlabel("time [s]")
    ax.set_xlim(t[0], t[-1] + dt)
    ax.set_ylim(-0.7, n_rows - 0.3)
    faults = ", true faults (grey; a row per sensor)" if truth else ""
    ax.set_title(f"{recording.name}: observer alarms (blue), blamed sensors (red){faults}", fontsize="medium")
    ax.grid(True, axis="x", linewidth=0.5, alpha=0.5)
    if truth:
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    save_figure(fig, path)


def observer_alarms_note(fault_truth) -> str:
    """What a report says :func:`plot_observer_alarms` shows (of the gated
    variant); it names the true faults only where the figure draws some."""
    note = "The gated variant's observer alarms and blamed sensors"
    if fault_truth is None:
        return note + "; the recording has no fault truth to hold them against."
    if not any(fault_truth.values()):
        return note + "; the recording's fault truth has no fault."
    return note + " over the true faults."


_KIND_LETTER = {"trend": "T", "residual": "R", "cusum": "C", "offset": "O"}


def plot_system_model(path: str | Path, components, relations, checks=None, dropped=None, title: str = "") -> None:
    """The system model as a graph (the paper's Section 4 structure): one
    node per modality component (whole-sensor components and LOOP aside),
    grouped by sensor around a circle; one edge per related pair, labelled
    with its observers' kinds (T trend, R residual, C cusum, O offset), and
    the pairs ``dropped`` (name -> pair) by calibration dashed in grey.
    ``relations``: name -> (kind, pair); ``checks``: component -> names of
    its unary checks, written under it."""
    checks, dropped = checks or {}, dropped or {}
    sensors = {c for _, pair in relations.values() for c in pair} | {c for pair in dropped.values() for c in pair}
    nodes = [c for c in components if c in sensors or c in checks]
    angle = np.linspace(0.5 * np.pi, 2.5 * np.pi, len(nodes), endpoint=False)
    where = {c: (np.cos(a), np.sin(a)) for c, a in zip(nodes, angle)}
    fig = Figure(figsize=(7.5, 7.0))
    ax = fig.add_subplot()
    kinds: dict[frozenset, list[str]] = {}
    for kind, pair in relations.values():
        kinds.setdefault(frozenset(pair), []).append(_KIND_LETTER.get(kind, "?"))
    lost = {frozenset(pair) for pair in dropped.values()} - set(kinds)
    for pair in lost:
        (x0, y0), (x1, y1) = (where[c] for c in pair)
        ax.plot([x0, x1], [y0, y1], color="0.65", ls="--", lw=1.2, zorder=1)
    for pair, letters in kinds.items():
        (x0, y0), (x1, y1) = (where[c] for c in pair)
        ax.plot([x0, x1], [y0, y1], color="tab:blue", lw=1.0 + 0.6 * len(letters), alpha=0.8, zorder=2)
        ax.text(0.5 * (x0 + x1), 0.5 * (y0 + y1), "".join(sorted(letters, key="TRCO".index)), fontsize="small",
                ha="center",
                va="center", zorder=4, bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none"})
    for c, (x, y) in where.items():
        ax.scatter([x], [y], s=2200, color=fault_color(c), edgecolor="0.2", zorder=3)
        ax.text(x, y, c, ha="center", va="center", fontsize="x-small", zorder=5)
        if c in checks:
            ax.text(1.32 * x, 1.32 * y, "\n".join(checks[c]), ha="center", va="center", fontsize="x-small",
                    color="0.3")
    ax.plot([], [], color="tab:blue", label="related: T trend, R residual, C cusum, O offset")
    if lost:
        ax.plot([], [], color="0.65", ls="--", label="dropped by calibrate")
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, -0.08), fontsize="small", frameon=False)
    ax.set_xlim(-1.6, 1.6)
    ax.set_ylim(-1.6, 1.6)
    ax.set_aspect("equal")
    ax.axis("off")
    ax.set_title(title or "system model: components and the relations between them", fontsize="medium")
    save_figure(fig, path)
