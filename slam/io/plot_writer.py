"""The figures of a map result, drawn in processes of their own.

matplotlib takes a third of a second to import and as long again to draw
the two figures of ``gslam map``. :class:`PlotWriter` starts one child
process per figure (:mod:`slam.background`) when the run starts; each
imports matplotlib while the parent reads and matches scans, at a lower
priority (``IMPORT_NICENESS``) so that it only takes CPU time the reading
and scan matching leave, and then waits for the estimate.
:meth:`PlotWriter.submit` hands it over as soon as the numbers are final;
the two figures are drawn at the same time while the parent writes the
numeric results. (Forking the second drawer only then would cost more than
it saves: parent and child both fault on every page they then touch.)
:meth:`PlotWriter.wait` returns once both PNGs are in the result folder
(before the folder is renamed into place). The figures are the same bytes
as drawn in the parent."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slam.background import Inbox, start
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


def draw(figures: MapFigures) -> None:
    """``trajectory.png`` and, with points, ``map.png`` in ``figures.folder``."""
    draw_trajectory(figures)
    draw_map(figures)


FIGURES = {"trajectory figure": draw_trajectory, "map figure": draw_map}


def _draw_when_given(inbox: Inbox, which: str, concurrent: bool) -> None:
    niceness = os.nice(0)
    if concurrent:
        os.nice(IMPORT_NICENESS)
    import slam.plots  # while the parent works

    slam.plots.warm_up()
    figures = inbox()
    if figures is None:
        return
    if concurrent:
        _renice(niceness)
    FIGURES[which](figures)


def _renice(niceness: int) -> None:
    """Back to ``niceness`` if this process may (raising priority needs a
    privilege on most systems: otherwise the figures are drawn at the lower one)."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, niceness)
    except OSError:
        pass


class PlotWriter:
    """Draws one result's figures, each in a process of its own when
    ``concurrent`` (else in this one, at :meth:`wait`)."""

    def __init__(self, concurrent: bool = True):
        self.workers = [start(which, _draw_when_given, which, concurrent, concurrent=concurrent) for which in FIGURES]
        self.submitted = False

    def submit(self, figures: MapFigures | None) -> None:
        """What to draw (None: nothing); once."""
        if not self.submitted:
            for worker in self.workers:
                worker.send(figures)
            self.submitted = True

    def wait(self) -> None:
        """Return when the figures are written; raise what drawing raised."""
        self.submit(None)
        for worker in self.workers:
            worker.result()

    def close(self) -> None:
        for worker in self.workers:
            worker.close()
