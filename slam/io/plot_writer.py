"""The figures of a map result, drawn in a second process.

matplotlib takes a third of a second to import and as long again to draw
the two figures of ``gslam map``. :class:`PlotWriter` starts a child
process (:mod:`slam.background`) when the run starts; the child imports
matplotlib while the parent reads and matches scans, then waits for the
estimate. :meth:`PlotWriter.submit` hands it over as soon as the numbers
are final, the parent writes the numeric results meanwhile, and
:meth:`PlotWriter.wait` returns once both PNGs are in the result folder
(before the folder is renamed into place). The figures are the same bytes
as drawn in the parent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slam.background import Inbox, start
from slam.recording import Interval, Trajectory


@dataclass
class MapFigures:
    """What the figures of one map result show."""

    folder: Path
    name: str
    estimate: Trajectory
    reference: Trajectory | None
    faults: dict[str, list[Interval]] = field(default_factory=dict)
    points: np.ndarray | None = None


def draw(figures: MapFigures) -> None:
    """``trajectory.png`` (estimate over the reference, true faults shaded)
    and, with points, ``map.png`` in ``figures.folder``."""
    from slam.plots import fault_shading, plot_map, plot_trajectories

    f = figures
    shaded = fault_shading(f.faults)
    plot_trajectories(f.folder / "trajectory.png", {"estimate": f.estimate}, f.reference, title=f.name, shaded=shaded)
    if f.points is not None:
        plot_map(f.folder / "map.png", f.points, f.estimate, title=f"{f.name}: laser map")


def _draw_when_given(inbox: Inbox) -> None:
    import slam.plots  # noqa: F401 - while the parent works

    figures = inbox()
    if figures is not None:
        draw(figures)


class PlotWriter:
    """Draws one result's figures in a second process when ``concurrent``
    (else in this one, at :meth:`wait`)."""

    def __init__(self, concurrent: bool = True):
        self.worker = start("plots", _draw_when_given, concurrent=concurrent)
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
