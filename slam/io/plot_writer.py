"""The figures of a map result, drawn in processes of their own.

matplotlib takes a third of a second to import and a tenth of a second to
draw each of the two figures of ``gslam map``. :class:`PlotWriter` starts
a child process (:mod:`slam.background`) when the run starts; it imports
matplotlib while the parent reads and matches scans, at a lower priority
(``IMPORT_NICENESS``) so that it takes only CPU time the reading and scan
matching leave, draws a small figure to load fonts and caches, and forks
the trajectory's drawer, which warms up the same way; then both wait.
:meth:`PlotWriter.submit` hands over the estimate as soon as it is final,
and the trajectory is drawn while the parent makes the map's points;
:meth:`PlotWriter.submit_points` hands those over, and the map is drawn
while the parent evaluates and writes the numbers. :meth:`PlotWriter.wait`
returns once both PNGs are in the result folder (before the folder is
renamed into place). The figures are the same bytes as drawn in the
parent."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any
from pathlib import Path

import numpy as np

from slam.background import Inbox, Subforked, start
from slam.recording import Interval, Trajectory

IMPORT_NICENESS = 10  # the child's priority while it imports and waits; back to the parent's to draw


@dataclass
class MapFigures:
    """What the figures of one map result show."""

    folder: Path
    name: str
    estimate: Trajectory
    reference: Trajectory | None
    faults: dict[str, list[Interval]] = field(default_factory=dict)
    points: np.ndarray | None = None


def draw_trajectory(figures: MapFigures) -> None:
    """``trajectory.png``: the estimate over the reference, true faults shaded."""
    from slam.plots import fault_shading, plot_trajectories

    f = figures
    plot_trajectories(f.folder / "trajectory.png", {"estimate": f.estimate}, f.reference, title=f.name,
                      shaded=fault_shading(f.faults))


def draw_map(figures: MapFigures) -> None:
    """``map.png``: the laser points and the estimate (nothing without points)."""
    from slam.plots import plot_map

    f = figures
    if f.points is not None:
        plot_map(f.folder / "map.png", f.points, f.estimate, title=f"{f.name}: laser map")


def _draw_when_given(inbox: Inbox, concurrent: bool) -> None:
    """The plot process: import and warm up, fork the trajectory's drawer
    (both then warm up their own copy of matplotlib's state, so neither
    faults on shared pages while drawing), pass it the figures as soon as
    they come, and draw the map once its points follow."""
    niceness = os.nice(0)
    if concurrent:
        os.nice(IMPORT_NICENESS)
    import slam.plots  # while the parent works

    slam.plots.warm_up()
    drawer = start_subforked("trajectory figure", _draw_trajectory_when_given, niceness) if concurrent else None
    slam.plots.warm_up()
    figures = inbox()
    try:
        if drawer is not None:
            drawer.send(figures)
        elif figures is not None:
            draw_trajectory(figures)
        points = inbox()
        if figures is not None and points is not None:
            if concurrent:
                _renice(niceness)
            figures.points = points
            draw_map(figures)
        if drawer is not None:
            drawer.result()
    finally:
        if drawer is not None:
            drawer.close()


def _draw_trajectory_when_given(inbox: Inbox, niceness: int) -> None:
    import slam.plots

    slam.plots.warm_up()
    figures = inbox()
    if figures is not None:
        _renice(niceness)
        draw_trajectory(figures)


def start_subforked(what: str, fn: Callable[..., None], *args: Any) -> Subforked | None:
    """A :class:`~slam.background.Subforked` child where ``os.fork`` exists, else None."""
    return Subforked(what, fn, *args) if hasattr(os, "fork") else None


def _renice(niceness: int) -> None:
    """Back to ``niceness`` if this process may (raising priority needs a
    privilege on most systems: otherwise the figures are drawn at the lower one)."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, niceness)
    except OSError:
        pass


class PlotWriter:
    """Draws one result's figures in a second process (and its child) when
    ``concurrent``, else in this one, at :meth:`wait`. :meth:`submit` the
    figures, then :meth:`submit_points` the map's points: the trajectory is
    drawn while the points are made."""

    def __init__(self, concurrent: bool = True):
        self.worker = start("plots", _draw_when_given, concurrent, concurrent=concurrent)
        self.sent = 0  # messages sent: the figures, then the points

    def submit(self, figures: MapFigures | None) -> None:
        """What to draw (None: nothing); once."""
        if self.sent == 0:
            self.worker.send(figures)
            self.sent = 1

    def submit_points(self, points: np.ndarray | None) -> None:
        """The map's points (None: no map figure); once, after :meth:`submit`."""
        self.submit(None)
        if self.sent == 1:
            self.worker.send(points)
            self.sent = 2

    def wait(self) -> None:
        """Return when the figures are written; raise what drawing raised."""
        self.submit_points(None)
        self.worker.result()

    def close(self) -> None:
        self.worker.close()
