"""Result figures as PNG: trajectories over a reference, occupancy grids
and point maps.

Built with matplotlib's object-oriented API (``Figure`` without pyplot), so
no GUI backend and no global figure state are involved; every figure is
written atomically by :func:`save_figure`.
"""

from __future__ import annotations

import itertools
import logging
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from slam.results.atomic import atomic_path
from slam.outputs.occupancy import GridMap
from slam.recording import SENSOR_MODALITIES, Interval, Trajectory

logger = logging.getLogger(__name__)

DPI = 120
# Pale colours, apart from the default line cycle, so bands never look like a
# path; one per component of the fault truth (slam.recording.COMPONENTS), the
# same in every figure, a sensor's modalities in neighbouring hues.
FAULT_COLORS = {"ODO_DIST": "wheat", "ODO_YAW": "burlywood", "IMU_GYRO": "lightskyblue", "IMU_YAW": "lightgreen",
                "SM_DIST": "gold", "SM_LAT": "khaki", "SM_YAW": "darkkhaki", "GPS": "violet"}
_SHADE_COLORS = tuple(FAULT_COLORS.values())
# Drawn on top of the other variants, in colours the default cycle then skips.
HIGHLIGHT_STYLES = (
    {"color": "tab:green", "linewidth": 4.0, "alpha": 0.55},  # under the next one: a band around it
    {"color": "tab:red", "linewidth": 1.8},
)

Shade = tuple[str, Sequence[Interval]] | tuple[str, Sequence[Interval], str]


def fault_color(component: str) -> str:
    """The pale colour of a component's true faults; a whole sensor's
    (``SM``, ``ODO``) is its first modality's, any other (``LOOP``) grey."""
    first = SENSOR_MODALITIES.get(component, (component,))[0]
    return FAULT_COLORS.get(first, "lightgrey")


def fault_shading(faults: Mapping[str, Sequence[Interval]]) -> list[Shade]:
    """``(label, intervals, colour)`` of each component with true faults."""
    return [(f"true {c} fault", iv, fault_color(c)) for c, iv in faults.items() if iv]


def save_figure(fig: Figure, path: str | Path) -> None:
    """Write ``fig`` to ``path`` as a PNG, atomically; the figure's label
    (``fig.set_label``), where it has one, is the PNG's Description text:
    what the figure draws, for a reader of the file (:func:`png_description`)."""
    with atomic_path(path) as tmp:
        _render_png(fig, tmp, fig.get_label() or None)
    logger.debug("wrote figure %s", path)


def png_description(path: str | Path) -> str | None:
    """The Description text :func:`save_figure` wrote into a PNG, if any."""
    from PIL import Image

    with Image.open(path) as image:
        return image.text.get("Description")


TRAJECTORIES_DESCRIPTION = "trajectories: "
"""How :func:`plot_trajectories`' Description starts; the labels drawn follow, comma-separated."""


def _render_png(fig: Figure, target, description: str | None = None) -> None:
    # zlib level 1: the same pixels, written in a fraction of the time.
    metadata = {"Description": description} if description else None
    fig.savefig(target, format="png", dpi=DPI, bbox_inches="tight", metadata=metadata,
                pil_kwargs={"compress_level": 1})


def warm_up() -> None:
    """Draw a small figure with the elements of the real ones into memory:
    the first figure a process draws also loads the font and fills
    matplotlib's text caches (some 40 ms), which a process waiting for its
    data can do beforehand."""
    import io

    fig, ax = _new_axes("warm-up")
    ax.plot([0.0, 1.0], [0.0, 1.0], label="a")
    ax.legend(loc="best", fontsize="small")
    _render_png(fig, io.BytesIO())


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


def _draw_shaded(ax: Axes, base: Trajectory, shaded: Sequence[Shade]) -> None:
    """Overlay the parts of ``base`` inside each labelled set of intervals
    as a broad translucent band, broken where the mask is False (from the
    first pose inside to the last: matplotlib walks a line's leading NaNs
    one by one in Python)."""
    for n, (label, intervals, *color) in enumerate(shaded):
        mask = _interval_mask(base.t, intervals)
        inside = np.flatnonzero(mask)
        span = slice(inside[0], inside[-1] + 1) if len(inside) else slice(0, 0)
        ax.plot(
            np.where(mask, base.x, np.nan)[span],
            np.where(mask, base.y, np.nan)[span],
            color=color[0] if color else _SHADE_COLORS[n % len(_SHADE_COLORS)],
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
    shaded: Sequence[Shade] = (),
    zoom_margin: float | None = None,
    highlight: Sequence[str] = (),
) -> None:
    """Top-down plot of labelled trajectories (m, world frame) over an
    optional reference, written as a PNG to ``path``.

    ``zoom_margin``: limit the view to the reference's extent plus this
    fraction of it, so one estimate that flew off does not hide the rest.

    ``shaded`` highlights time segments, e.g. the outdoor part or a fault:
    each ``(label, intervals)`` marks the poses of the reference (else of
    the first trajectory) whose time (s, recording time) lies in one of the
    intervals. Start (circle) and end (cross) of every path are marked.

    ``highlight``: up to two labels drawn last, on top of everything, in
    :data:`HIGHLIGHT_STYLES` (a broad green band, then a red line), the
    others thinner in the default colours.
    """
    fig, ax = _new_axes(title)
    reference, trajectories, origin = relative_to_reference(reference, trajectories)
    if origin is not None:
        ax.set_xlabel(f"x east [m] from the reference's start ({origin[0]:.1f})")
        ax.set_ylabel(f"y north [m] from the reference's start ({origin[1]:.1f})")
    base = reference if reference is not None else next(iter(trajectories.values()), None)
    if base is not None and shaded:
        _draw_shaded(ax, base, shaded)
    on_top = [h for h in highlight if h in trajectories][: len(HIGHLIGHT_STYLES)]
    taken = {style["color"] for style in HIGHLIGHT_STYLES[: len(on_top)]}
    cycle = itertools.cycle([c for c in (f"C{i}" for i in range(10)) if _named(c) not in taken])
    curves: list[tuple[str, Trajectory, dict]] = []
    if reference is not None:
        # Thin and dashed, so it can lie on top of everything.
        curves.append(("reference", reference, {"color": "black", "linestyle": "--", "linewidth": 1.0, "zorder": 7}))
    thin = 1.0 if on_top else 1.2
    curves += [(label, traj, {"linewidth": thin, "color": next(cycle), "zorder": 2})
               for label, traj in trajectories.items() if label not in on_top]
    curves += [(label, trajectories[label], {**style, "zorder": 4 + k})
               for k, (label, style) in enumerate(zip(on_top, HIGHLIGHT_STYLES))]
    for label, traj, style in curves:
        if len(traj) == 0:
            continue
        (line,) = ax.plot(traj.x, traj.y, label=label, **style)
        color, z = line.get_color(), style["zorder"] + 0.5
        ax.plot(traj.x[0], traj.y[0], "o", color=color, markersize=6, zorder=z)
        ax.plot(traj.x[-1], traj.y[-1], "x", color=color, markersize=8, mew=2, zorder=z)
    if zoom_margin is not None and reference is not None and len(reference):
        lo, hi = reference.xy().min(axis=0), reference.xy().max(axis=0)
        pad = zoom_margin * max(hi - lo) + 1.0
        ax.set_aspect("equal", adjustable="box")  # fixed limits: let the box adapt
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.legend(loc="best", fontsize="small")
    fig.set_label(TRAJECTORIES_DESCRIPTION + ", ".join(trajectories))
    save_figure(fig, path)


LARGE_COORDINATE_M = 1e4
"""Beyond this a reference is in a global frame (UTM, a national grid)."""


def relative_to_reference(
    reference: Trajectory | None, trajectories: Mapping[str, Trajectory]
) -> tuple[Trajectory | None, dict[str, Trajectory], np.ndarray | None]:
    """A reference with large (UTM) coordinates, and every trajectory as far
    out as it, moved to start at the origin; a trajectory near the origin
    already (an estimate started there) stays. Returns the moved ones and
    the offset taken off (None if nothing moved)."""
    out = dict(trajectories)
    if reference is None or not len(reference) or np.max(np.abs(reference.xy())) < LARGE_COORDINATE_M:
        return reference, out, None
    origin = reference.xy()[0].copy()

    def moved(traj: Trajectory) -> Trajectory:
        if not len(traj) or np.max(np.abs(traj.xy())) < LARGE_COORDINATE_M:
            return traj
        return Trajectory(traj.t, traj.x - origin[0], traj.y - origin[1], traj.yaw)

    return moved(reference), {k: moved(v) for k, v in out.items()}, origin


def _named(color: str) -> str:
    """``C3`` -> ``tab:red``: the default cycle's colour by its tableau name."""
    from matplotlib.colors import TABLEAU_COLORS, to_hex

    hex_color = to_hex(color)
    return next((name for name, value in TABLEAU_COLORS.items() if value == hex_color), hex_color)


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
    _draw_path(ax, trajectory)
    ax.legend(loc="best", fontsize="small", markerscale=10)
    save_figure(fig, path)


def plot_grid_map(path: str | Path, grid: GridMap, trajectory: Trajectory | None = None, title: str = "") -> None:
    """Top-down occupancy grid as ``map.pgm`` shows it (black occupied,
    white free, grey unknown) in world metres, with an optional trajectory
    on top, written as a PNG to ``path``."""
    from slam.outputs.map_server import PIXELS, map_image
    from slam.outputs.occupancy import UNKNOWN

    fig, ax = _new_axes(title)
    ax.grid(False)
    ax.set_facecolor(str(PIXELS[UNKNOWN] / 255))  # around the grid, where the axes reach past it: unknown too
    ax.imshow(map_image(grid.cells), cmap="gray", vmin=0, vmax=255, extent=grid.extent(), origin="upper",
              interpolation="antialiased", zorder=0)
    _draw_path(ax, trajectory)
    if trajectory is not None and len(trajectory):
        ax.legend(loc="best", fontsize="small")
    save_figure(fig, path)


def _draw_path(ax: Axes, trajectory: Trajectory | None) -> None:
    """The trajectory, its start (circle) and end (cross)."""
    if trajectory is None or not len(trajectory):
        return
    ax.plot(trajectory.x, trajectory.y, color="tab:blue", linewidth=1.2, label="trajectory")
    ax.plot(trajectory.x[0], trajectory.y[0], "o", color="tab:blue", markersize=6)
    ax.plot(trajectory.x[-1], trajectory.y[-1], "x", color="tab:blue", markersize=8, mew=2)
