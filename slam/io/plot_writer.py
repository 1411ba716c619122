"""The figures of a map result, drawn in a second process.

matplotlib takes a third of a second to import and as long again to draw
the two figures of ``gslam map``. :class:`PlotWriter` starts a child
process (:mod:`slam.background`) when the run starts; the child imports
matplotlib while the parent reads and matches scans, at a lower priority
(``IMPORT_NICENESS``) so that it only takes CPU time the reading and scan
matching leave, and then waits for the estimate. :meth:`PlotWriter.submit`
hands it over as soon as the numbers are final; the child forks once more
so the two figures are drawn at the same time, one per core, while the
parent writes the numeric results. :meth:`PlotWriter.wait` returns once
both PNGs are in the result folder (before the folder is renamed into
place). The figures are the same bytes as drawn in the parent.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
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


def draw(figures: MapFigures, concurrent: bool = False) -> None:
    """``trajectory.png`` and, with points, ``map.png`` in ``figures.folder``;
    with ``concurrent``, the map in a forked child meanwhile."""
    if concurrent and figures.points is not None and hasattr(os, "fork"):
        worker = Subforked("map figure", draw_map, figures)
        draw_trajectory(figures)
        worker.result()
    else:
        draw_trajectory(figures)
        draw_map(figures)


def _draw_when_given(inbox: Inbox, concurrent: bool) -> None:
    niceness = os.nice(0)
    if concurrent:
        os.nice(IMPORT_NICENESS)
    import slam.plots  # noqa: F401 - while the parent works

    figures = inbox()
    if figures is None:
        return
    if concurrent:
        _renice(niceness)
    draw(figures, concurrent)


def _renice(niceness: int) -> None:
    """Back to ``niceness`` if this process may (raising priority needs a
    privilege on most systems: otherwise the figures are drawn at the lower one)."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, niceness)
    except OSError:
        pass


class PlotWriter:
    """Draws one result's figures in a second process when ``concurrent``
    (else in this one, at :meth:`wait`)."""

    def __init__(self, concurrent: bool = True):
        self.worker = start("plots", _draw_when_given, concurrent, concurrent=concurrent)
        self.submitted = False

    def submit(self, figures: MapFigures | None) -> None:
        """What to draw (None: nothing); once."""
        if not self.submitted:
            self.worker.send(figures)
            self.submitted = True

    def wait(self) -> None:
        """Return when the figures are written; raise what drawing raised."""
        self.submit(None)
        self.worker.result()

    def close(self) -> None:
        self.worker.close()
