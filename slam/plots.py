"""Result figures as PNG: trajectories over a reference, and point maps.

Built with matplotlib's object-oriented API (``Figure`` without pyplot), so
no GUI backend and no global figure state are involved; every figure is
written atomically by :func:`save_figure`.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from slam.io.atomic import atomic_path
from slam.recording import Interval, Trajectory

logger = logging.getLogger(__name__)

DPI = 120
# Pale colours, apart from the default line cycle, so bands never look like a path.
_SHADE_COLORS = ("gold", "violet", "lightgreen", "lightskyblue", "wheat")


def save_figure(fig: Figure, path: str | Path) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) atomically."""
    with atomic_path(path) as tmp:
        # zlib level 1: the same pixels, written in a fraction of the time.
        fig.savefig(tmp, dpi=DPI, bbox_inches="tight", pil_kwargs={"compress_level": 1})
    logger.debug("wrote figure %s", path)


def _new_axes(title: str) -> tuple[Figure, Axes]:
    fig = Figure(figsize=(8, 7))
    ax = fig.add_subplot()
    ax.set_title(title)
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, linewidth=0.5, alpha=0.5)
    return fig, ax


def _interval_mask(t: np.ndarray, intervals: Sequence[Interval]) -> np.ndarray:
    """True where ``t`` (s) lies in any closed interval."""
    mask = np.zeros(len(t), dtype=bool)
    for start, end in intervals:
        mask |= (t >= start) & (t <= end)
    return mask


def _draw_shaded(
    ax: Axes, base: Trajectory, shaded: Sequence[tuple[str, Sequence[Interval]]]
) -> None:
    """Overlay the parts of ``base`` inside each labelled set of intervals
    as a broad translucent band, broken where the mask is False."""
    for n, (label, intervals) in enumerate(shaded):
        mask = _interval_mask(base.t, intervals)
        ax.plot(
            np.where(mask, base.x, np.nan),
            np.where(mask, base.y, np.nan),
            color=_SHADE_COLORS[n % len(_SHADE_COLORS)],
            linewidth=9,
            alpha=0.45,
            solid_capstyle="round",
            label=label,
            zorder=1,
        )


def plot_trajectories(
    path: str | Path,
    trajectories: Mapping[str, Trajectory],
    reference: Trajectory | None = None,
    title: str = "",
    shaded: Sequence[tuple[str, Sequence[Interval]]] = (),
    zoom_margin: float | None = None,
) -> None:
    """Top-down plot of labelled trajectories (m, world frame) over an
    optional reference, written as a PNG to ``path``.

    ``zoom_margin``: limit the view to the reference's extent plus this
    fraction of it, so one estimate that flew off does not hide the rest.

    ``shaded`` highlights time segments, e.g. the outdoor part or a fault:
    each ``(label, intervals)`` marks the poses of the reference (else of
    the first trajectory) whose time (s, recording time) lies in one of the
    intervals. Start (circle) and end (cross) of every path are marked.
    """
    fig, ax = _new_axes(title)
    base = reference if reference is not None else next(iter(trajectories.values()), None)
    if base is not None and shaded:
        _draw_shaded(ax, base, shaded)
    curves: list[tuple[str, Trajectory, dict]] = []
    if reference is not None:
        curves.append(("reference", reference, {"color": "black", "linestyle": "--", "linewidth": 1.2}))
    curves += [(label, traj, {"linewidth": 1.2}) for label, traj in trajectories.items()]
    for label, traj, style in curves:
        if len(traj) == 0:
            continue
        (line,) = ax.plot(traj.x, traj.y, label=label, zorder=2, **style)
        color = line.get_color()
        ax.plot(traj.x[0], traj.y[0], "o", color=color, markersize=6, zorder=3)
        ax.plot(traj.x[-1], traj.y[-1], "x", color=color, markersize=8, mew=2, zorder=3)
    if zoom_margin is not None and reference is not None and len(reference):
        lo, hi = reference.xy().min(axis=0), reference.xy().max(axis=0)
        pad = zoom_margin * max(hi - lo) + 1.0
        ax.set_aspect("equal", adjustable="box")  # fixed limits: let the box adapt
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.legend(loc="best", fontsize="small")
    save_figure(fig, path)


def plot_map(
    path: str | Path,
    points_xy: np.ndarray,
    trajectory: Trajectory | None = None,
    title: str = "",
) -> None:
    """Top-down point map: ``points_xy`` (n, 2) world points in m as small
    dots, with an optional trajectory on top, written as a PNG to ``path``."""
    fig, ax = _new_axes(title)
    pts = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    ax.scatter(
        pts[:, 0], pts[:, 1], s=2.0, c="0.3", marker=".", linewidths=0, label=f"map ({len(pts)} points)"
    )
    if trajectory is not None and len(trajectory):
        ax.plot(trajectory.x, trajectory.y, color="tab:blue", linewidth=1.2, label="trajectory")
        ax.plot(trajectory.x[0], trajectory.y[0], "o", color="tab:blue", markersize=6)
        ax.plot(trajectory.x[-1], trajectory.y[-1], "x", color="tab:blue", markersize=8, mew=2)
    ax.legend(loc="best", fontsize="small", markerscale=10)
    save_figure(fig, path)
