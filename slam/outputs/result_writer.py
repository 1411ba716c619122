"""The files of a map result that are made from the final estimate (the
figures, the occupancy grid, ``run.mcap``), made in processes of their own.

matplotlib takes a third of a second to import and a tenth of a second to
draw each of the two figures of ``gslam map``; rosbags' type store another
third of a second to load. :class:`ResultWriter` starts a child process
(:mod:`slam.processes.background`) when the run starts; it imports matplotlib and
rosbags while the parent reads and matches scans, at a lower priority
(``IMPORT_NICENESS``) so that it takes only CPU time the reading and scan
matching leave, draws a small figure and a message of each type to load
fonts, caches and serialisers, and forks the trajectory figure's drawer,
which warms up the same way; then both wait. :meth:`ResultWriter.submit`
hands over the estimate as soon as it is final, and the trajectory is drawn
while the parent makes the map's points; :meth:`ResultWriter.submit_map`
hands over the keyframes' scans (and those points), and the child builds
the occupancy grid (:mod:`slam.outputs.occupancy`), writes ``map.pgm`` and
``map.yaml``, draws ``map.png`` and writes ``run.mcap``
(:mod:`slam.outputs.run_mcap`), all while the parent evaluates and writes the
numbers. :meth:`ResultWriter.wait` returns once every file is in the
result folder (before the folder is renamed into place). The files are the
same bytes as made in the parent (``concurrent=False``).

:class:`SelfChecker` makes the map's self-check (:mod:`slam.outputs.self_check`)
in a child of its own the same way: open3d, whose nearest neighbours it
uses, takes half a second to import, which the child spends while the
parent reads and maps; the figures are the same as made in the parent."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from slam.processes.background import Inbox, Subforked, start
from slam.outputs.run_mcap import RunContent
from slam.outputs.occupancy import GridMap, GridModel
from slam.recording import Interval, Trajectory

IMPORT_NICENESS = 10  # the child's priority while it imports and waits; back to the parent's to work


@dataclass
class FinalEstimate:
    """The run's final estimate and what the files made from it show:
    ``faults``, the recording's true fault intervals (its ``fault_truth``;
    empty without truth: no band, no legend)."""

    folder: Path
    name: str
    estimate: Trajectory
    reference: Trajectory | None
    faults: dict[str, list[Interval]] = field(default_factory=dict)


@dataclass
class MapInputs:
    """What the map's files are made from: ``points``, the voxel-thinned
    map (``map.ply``; the map figure where there is no grid); ``ranges``
    (K, beams) each keyframe's scan with beam ``angles`` and the range
    limits of a return (``beam_limits``, m); ``grid``, the grid's model
    (None: no grid); ``mcap``, the bag's other content (None: no bag)."""

    points: np.ndarray | None = None
    ranges: np.ndarray | None = None
    angles: np.ndarray | None = None
    beam_limits: tuple[float, float] = (0.0, np.inf)
    grid: GridModel | None = None
    mcap: RunContent | None = None


@dataclass
class MapOutputs:
    """What was made: the grid's size and cell counts and the bag's messages
    per topic (for ``metrics.json``), and the seconds each took."""

    grid: dict | None = None
    mcap_messages: dict[str, int] | None = None
    grid_s: float = 0.0
    mcap_s: float = 0.0


def draw_trajectory(run: FinalEstimate) -> None:
    """``trajectory.png``: the estimate over the reference, the true faults shaded (none without truth)."""
    from slam.outputs.plots import fault_shading, plot_trajectories

    plot_trajectories(run.folder / "trajectory.png", {"estimate": run.estimate}, run.reference, title=run.name,
                      shaded=fault_shading(run.faults))


def draw_map(run: FinalEstimate, grid: GridMap | None, points: np.ndarray | None) -> None:
    """``map.png``: the occupancy grid and the estimate, else (without a
    grid) the laser points; nothing without either."""
    from slam.outputs.plots import plot_grid_map, plot_map

    if grid is not None:
        plot_grid_map(run.folder / "map.png", grid, run.estimate, title=f"{run.name}: occupancy grid")
    elif points is not None:
        plot_map(run.folder / "map.png", points, run.estimate, title=f"{run.name}: laser map")


def make_grid(run: FinalEstimate, inputs: MapInputs) -> tuple[GridMap | None, dict | None]:
    """The occupancy grid of the keyframes' scans at the estimate, written
    as ``map.pgm`` and ``map.yaml``; and its figures for the metrics."""
    from slam.outputs.map_server import write_map
    from slam.outputs.occupancy import FREE, OCCUPIED, build_grid

    if inputs.grid is None or inputs.ranges is None:
        return None, None
    grid = build_grid(inputs.ranges, inputs.angles, run.estimate, *inputs.beam_limits, inputs.grid)
    if grid is None:
        return None, None
    cells = grid.classify()
    write_map(run.folder, cells)
    counts = {"width": cells.cells.shape[1], "height": cells.cells.shape[0], "resolution_m": cells.resolution_m,
              "occupied_cells": int(np.sum(cells.cells == OCCUPIED)), "free_cells": int(np.sum(cells.cells == FREE))}
    return cells, counts


def write_mcap(run: FinalEstimate, inputs: MapInputs, grid: GridMap | None) -> tuple[dict, float]:
    """``run.mcap`` with the grid and the keyframes' scans in the world
    frame; the messages per topic and the seconds it took."""
    from slam.frontend.kiss import ScanProjector
    from slam.outputs.run_mcap import write_run_mcap

    t = time.perf_counter()
    content = inputs.mcap
    content.grid = grid
    if inputs.ranges is not None:
        xy, row = ScanProjector(inputs.angles, *inputs.beam_limits).world_points(inputs.ranges, run.estimate)
        content.scans = np.split(xy, np.searchsorted(row, np.arange(1, len(inputs.ranges))))
    counts = write_run_mcap(run.folder / "run.mcap", content)
    return counts, time.perf_counter() - t


def _make_when_given(inbox: Inbox, concurrent: bool, plots: bool, mcap: bool) -> MapOutputs:
    """The child: import and warm up, fork the trajectory's drawer (both
    then warm up their own copy of matplotlib's state, so neither faults on
    shared pages while drawing), pass it the estimate as soon as it comes,
    and make the map's files once their inputs follow."""
    niceness = os.nice(0)
    if concurrent:
        os.nice(IMPORT_NICENESS)
    if plots:
        import slam.outputs.plots  # while the parent works

        slam.outputs.plots.warm_up()
    if mcap:
        from slam.outputs.run_mcap import warm_up

        warm_up()
    drawer = start_subforked("trajectory figure", _draw_trajectory_when_given, niceness) if concurrent and plots else None
    if plots:
        slam.outputs.plots.warm_up()
    run = inbox()
    out = MapOutputs()
    try:
        if drawer is not None:
            drawer.send(run)
        elif run is not None and plots:
            draw_trajectory(run)
        inputs = inbox()
        if run is not None and inputs is not None:
            if concurrent:
                _renice(niceness)
            _make_map(run, inputs, out, plots)
        if drawer is not None:
            drawer.result()
    finally:
        if drawer is not None:
            drawer.close()
    return out


def _make_map(run: FinalEstimate, inputs: MapInputs, out: MapOutputs, plots: bool) -> None:
    """The grid first (the figure and the bag show it), then the map
    figure, then the bag, one after the other: the bag in a child of its
    own cost more CPU time than it saved in wall time on a loaded machine
    (the lab: about 0.1 s more)."""
    t = time.perf_counter()
    grid, out.grid = make_grid(run, inputs)
    out.grid_s = time.perf_counter() - t
    if plots:
        draw_map(run, grid, inputs.points)
    if inputs.mcap is not None:
        out.mcap_messages, out.mcap_s = write_mcap(run, inputs, grid)


def _draw_trajectory_when_given(inbox: Inbox, niceness: int) -> None:
    import slam.outputs.plots

    slam.outputs.plots.warm_up()
    run = inbox()
    if run is not None:
        _renice(niceness)
        draw_trajectory(run)


def start_subforked(what: str, fn: Callable[..., Any], *args: Any) -> Subforked | None:
    """A :class:`~slam.processes.background.Subforked` child where ``os.fork`` exists, else None."""
    return Subforked(what, fn, *args) if hasattr(os, "fork") else None


def _renice(niceness: int) -> None:
    """Back to ``niceness`` if this process may (raising priority needs a
    privilege on most systems: otherwise the files are made at the lower one)."""
    try:
        os.setpriority(os.PRIO_PROCESS, 0, niceness)
    except OSError:
        pass


def _check_when_given(inbox: Inbox, concurrent: bool) -> Any:
    """The self-check's child: import open3d and the check at the lower
    priority while the parent works, then check the map it is given (None:
    nothing to check)."""
    niceness = os.nice(0)
    if concurrent:
        os.nice(IMPORT_NICENESS)
    from slam.outputs.pointcloud import import_open3d
    from slam.outputs.self_check import check_map

    import_open3d()
    inputs = inbox()
    if inputs is None:
        return None
    if concurrent:
        _renice(niceness)
    return check_map(**inputs)


class SelfChecker:
    """Makes the map's self-check in a second process when ``concurrent``,
    else in this one at :meth:`wait`: :meth:`submit` what
    :func:`~slam.outputs.self_check.check_map` reads, then :meth:`wait`
    for its :class:`~slam.outputs.self_check.SelfCheck`."""

    def __init__(self, concurrent: bool = True):
        self.worker = start("self-check", _check_when_given, concurrent, concurrent=concurrent)
        self.sent = False

    def submit(self, inputs: dict[str, Any] | None) -> None:
        """``check_map``'s keyword arguments (None: nothing to check); once."""
        if not self.sent:
            self.worker.send(inputs)
            self.sent = True

    def wait(self) -> Any:
        """The self-check (None if nothing was submitted); raise what making it raised."""
        self.submit(None)
        return self.worker.result()

    def close(self) -> None:
        self.worker.close()


class ResultWriter:
    """Makes one result's figures (``plots``), occupancy grid and bag
    (``mcap``) in a second process (and its children) when ``concurrent``,
    else in this one, at :meth:`wait`. :meth:`submit` the estimate, then
    :meth:`submit_map` the map's inputs: the trajectory is drawn while they
    are made."""

    def __init__(self, concurrent: bool = True, plots: bool = True, mcap: bool = True):
        self.worker = start("result files", _make_when_given, concurrent, plots, mcap, concurrent=concurrent)
        self.sent = 0  # messages sent: the estimate, then the map's inputs

    def submit(self, run: FinalEstimate | None) -> None:
        """The final estimate (None: nothing to make); once."""
        if self.sent == 0:
            self.worker.send(run)
            self.sent = 1

    def submit_map(self, inputs: MapInputs | None) -> None:
        """What the map's files are made from (None: none); once, after :meth:`submit`."""
        self.submit(None)
        if self.sent == 1:
            self.worker.send(inputs)
            self.sent = 2

    def wait(self) -> MapOutputs:
        """Return when the files are written; raise what making them raised."""
        self.submit_map(None)
        return self.worker.result()

    def close(self) -> None:
        self.worker.close()
