"""The map's self-check: whether a result says, without ground truth, that
it cannot be trusted.

Each figure is measured on the result alone (the keyframes' scans at
their optimised poses, the kept loops, the odometry) and held against a
bound (:class:`SelfCheckBounds`); the verdict fails when any figure is
outside its bound, and a figure that does not apply (no laser, no kept
loop, no odometry) passes. The check only reads: the map is the same with
or without it. Definitions and bounds are in ``docs/cli.md`` (The
self-check); the values measured on the CARMEN logs, the Husky bag and the
demo in ``docs/results/self_check.md`` (``python -m scripts.bench
self_check``).

Judged figures:

* ``scan_agreement``: the share of keyframes whose scan agrees with the map
  the other keyframes make. Each scan is projected at its optimised pose
  and thinned to one point per ``voxel_m`` cell; a point agrees when a
  point of another keyframe's scan lies within ``agreement_radius_m``; a
  scan agrees when at least ``agreeing_points_min`` of its points do. A
  scan laid at a wrong pose lands where no other scan saw anything. On a
  log of more than ``checked_scans_max`` keyframes, evenly spaced ones are
  checked (against every keyframe's points).
* ``loop_residual_m``: the ``loop_residual_quantile`` quantile of the kept
  loops' translation residuals after optimisation: how far the final map
  puts a loop's later keyframe from where the loop measured it, in the
  directions the loop pins. A map that kept a loop it could not close is
  torn.
* ``free_space_returns``: the share of the keyframes' laser returns that
  land where the map's beams see free space: cast from the optimised poses
  into a grid of ``free_space_cell_m`` cells (:func:`slam.outputs.occupancy.beam_counts`),
  a return is in free space when more scans cross its cell than end in it
  and the cells around it; only beams that returned count as crossing. On a log of more than ``free_space_scans_max``
  keyframes, evenly spaced ones are cast. A map torn into pieces that each hold together
  lays the walls of one piece across the rooms another saw empty; the
  scans' local agreement does not see that.
* ``odometry_disagreement``: the share of steps where the odometry's
  motion and the map's motion between consecutive keyframes differ by more
  than ``odometry_step_m`` plus ``odometry_step_per_m`` of the step, or by
  more than ``odometry_step_deg``.

Reported, not judged: ``stamps_synthesised`` (the reader made the times,
which says nothing of the geometry: belgioioso's stamps are all zero and
it maps within 0.1 m) and ``blame_share`` (the validator's
``alarm_fraction``: a gated run that blames a faulty sensor reacted as it
should).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np

from slam.graph.measurements import BetweenMeasurement
from slam.recording import Scans, Trajectory, relative_poses
from validation.base.geometry import between, wrap_angle
from validation.loops.constraint import LoopConstraint


@dataclass(frozen=True)
class SelfCheckBounds:
    """What each figure is measured with, and its bound (m, deg, shares in
    [0, 1]). Chosen on the CARMEN logs (docs/cli.md): orebro, an 18 m blob,
    fails; the eight logs mapped within 0.2 m pass."""

    voxel_m: float = 0.05  # the map's own voxel (output.map_voxel_m's default)
    agreement_radius_m: float = 0.1  # twice the voxel: a wall seen twice within a scanner's noise
    agreeing_points_min: float = 0.8  # a scan agrees when this share of its points does
    scan_agreement_min: float = 0.85  # good logs 0.968-1, orebro 0.68
    checked_scans_max: int = 500  # FR079's 4,791 keyframes: every 10th checked, 1.6 s rather than 8 s
    neighbours: int = 16  # first nearest-neighbour query; doubled where a scan's own points fill it
    loop_residual_quantile: float = 0.95
    loop_residual_max_m: float = 0.2  # good logs 0.011-0.025 m: a loop the map did not close
    free_space_cell_m: float = 0.1  # twice the map's voxel: a wall seen from two sides stays one cell thick
    free_space_returns_max: float = 0.5  # the CARMEN logs as mapped 0.11-0.28, orebro 0.96
    free_space_scans_max: int = 1000  # FR079's 4,791 keyframes: every 5th cast, 0.2 s rather than 0.8 s
    odometry_step_m: float = 0.3  # raw odometry is off by up to 0.5 m a step on the thinned logs
    odometry_step_per_m: float = 0.2
    odometry_step_deg: float = 10.0  # and up to 30 deg
    odometry_disagreement_max: float = 0.35  # csail's raw odometry: 0.175


class Side(str, Enum):
    """Which side of its bound a figure must lie on."""

    AT_LEAST = "at_least"
    AT_MOST = "at_most"


@dataclass
class CheckedFigure:
    """One figure: its value, its bound (``at_least`` or ``at_most``), how
    many samples it rests on and whether it passes; None where it does not
    apply (no scans, no kept loop, no odometry)."""

    name: str
    value: float | None
    bound: float
    side: Side
    samples: int
    unit: str = ""

    @property
    def passed(self) -> bool | None:
        if self.value is None:
            return None
        return self.value >= self.bound if self.side is Side.AT_LEAST else self.value <= self.bound

    def as_dict(self) -> dict[str, Any]:
        return {"value": self.value, "bound": self.bound, "side": self.side.value, "unit": self.unit,
                "samples": self.samples, "passed": self.passed}


@dataclass
class SelfCheck:
    """The figures, the reported notes and the verdict (``pass``/``fail``);
    ``time_s``, its seconds, goes to ``timings_s`` (not into the check, which
    is the same on every run of the same map)."""

    figures: list[CheckedFigure]
    notes: dict[str, Any] = field(default_factory=dict)
    time_s: float = 0.0

    @property
    def failed(self) -> list[CheckedFigure]:
        return [f for f in self.figures if f.passed is False]

    @property
    def verdict(self) -> str:
        return "fail" if self.failed else "pass"

    def as_dict(self) -> dict[str, Any]:
        return {"verdict": self.verdict, "failed": [f.name for f in self.failed],
                "figures": {f.name: f.as_dict() for f in self.figures}, **self.notes}

    def warning(self) -> str | None:
        """One line naming the failed figures, or None when it passes."""
        return warning_line(self.as_dict()) if self.failed else None


def warning_line(check: dict[str, Any]) -> str:
    """The one line a failed check ``check`` (metrics.json's ``self_check``)
    is reported with: each failed figure, its value and its bound."""
    parts = [_figure_text(name, check["figures"][name]) for name in check["failed"]]
    return "self-check failed: " + "; ".join(parts) + "; the map is written, but it is unreliable"


def summary_line(check: dict[str, Any]) -> str:
    """The one line a check ``check`` that passed is shown with: each figure
    that applies, its value and its bound."""
    parts = [_figure_text(name, f) for name, f in check["figures"].items() if f["value"] is not None]
    return f"self-check: {check['verdict']}" + (f" ({'; '.join(parts)})" if parts else " (no figure applies)")


def _figure_text(name: str, f: dict[str, Any]) -> str:
    op = ">=" if f["side"] == Side.AT_LEAST.value else "<="
    unit = f" {f['unit']}" if f["unit"] else ""
    return f"{name} {f['value']:g}{unit} (bound {op} {f['bound']:g}{unit})"


SELF_CHECK_NOTE = (
    "Each variant's map checked without ground truth (metrics.json's self_check): the share of keyframe scans "
    "that agree with the other keyframes' map, the kept loops' residual after optimisation, the share of steps "
    "where the odometry disagrees with the map; each beside its bound (docs/cli.md). A failed check names a "
    "map not to trust; the map is written all the same."
)


def self_check_table(checks: dict[str, dict[str, Any] | None]):
    """``report.html``'s table of the self-checks ``checks`` (per name,
    metrics.json's ``self_check``; None: the result has none): the verdict,
    then each figure's value beside its bound (– where it does not apply)."""
    from slam.outputs.report import Table

    names = [n for c in checks.values() if c is not None for n in c["figures"]]
    figures = list(dict.fromkeys(names))
    rows = []
    for variant, check in checks.items():
        if check is None:
            rows.append([variant, "–", *("–" for _ in figures)])
            continue
        cells = []
        for name in figures:
            f = check["figures"].get(name)
            if f is None or f["value"] is None:
                cells.append("–")
                continue
            op = "≥" if f["side"] == Side.AT_LEAST.value else "≤"
            mark = "" if f["passed"] else " FAIL"
            cells.append(f"{f['value']:g} ({op} {f['bound']:g}){mark}")
        rows.append([variant, check["verdict"], *cells])
    return Table(["variant", "verdict", *figures], rows)


# -- the figures --------------------------------------------------------------


def scan_points(ranges: np.ndarray, angles: np.ndarray, beam_limits: tuple[float, float], poses: Trajectory,
                voxel_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The keyframes' scans ``ranges`` (K, beams) at ``poses`` in the world
    frame (m, (n, 2)), each scan thinned on its own to one point per
    ``voxel_m`` cell, and the keyframe of each point (n,)."""
    from slam.frontend.kiss import ScanProjector

    pts, row = ScanProjector(angles, *beam_limits).world_points(ranges, poses)
    if len(pts) == 0:
        return pts, row
    cells = np.floor(pts / voxel_m).astype(np.int64)
    cells -= cells.min(axis=0)
    span = cells.max(axis=0) + 1
    key = (row.astype(np.int64) * span[0] + cells[:, 0]) * span[1] + cells[:, 1]
    _, first = np.unique(key, return_index=True)
    first.sort()
    return pts[first], row[first]


def point_agreement(points: np.ndarray, keyframe: np.ndarray, queries: np.ndarray, radius_m: float,
                    neighbours: int) -> np.ndarray:
    """Per point of ``queries`` (indices into ``points``), bool: whether a
    point of another keyframe lies within ``radius_m`` (open3d's
    nearest-neighbour search over all ``points``). Of the ``neighbours``
    nearest, the first of another keyframe decides; where all are of the
    point's own scan and the farthest is still within the radius, the
    search is repeated with twice as many."""
    from slam.outputs.pointcloud import import_open3d

    o3d = import_open3d()
    n = len(points)
    agree = np.zeros(len(queries), dtype=bool)
    if n == 0 or len(queries) == 0:
        return agree
    xyz = np.zeros((n, 3))
    xyz[:, :2] = points
    nns = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(xyz))
    nns.knn_index()
    todo = np.arange(len(queries))
    k = neighbours
    while len(todo):
        k_eff = min(k, n)
        q = queries[todo]
        idx, d2 = nns.knn_search(o3d.core.Tensor(xyz[q]), k_eff)
        idx, d2 = idx.numpy().astype(np.int64), d2.numpy()
        other = keyframe[idx] != keyframe[q, None]
        within = d2 <= radius_m * radius_m
        agree[todo] = np.any(other & within, axis=1)
        # Undecided: every neighbour of its own scan, the farthest still inside.
        undecided = ~agree[todo] & ~np.any(other, axis=1) & within[:, -1]
        if k_eff >= n:
            break
        todo, k = todo[undecided], 2 * k
    return agree


def checked_keyframes(n_keyframes: int, at_most: int) -> np.ndarray:
    """Every keyframe, or every s-th one (s the smallest step leaving at
    most ``at_most``): a share over a few hundred scans is as telling, and
    a 4.5 Hz log has thousands."""
    step = max(1, -(-n_keyframes // at_most))
    return np.arange(0, n_keyframes, step)


def scan_agreement(points: np.ndarray, keyframe: np.ndarray, n_keyframes: int,
                   bounds: SelfCheckBounds) -> tuple[float | None, int, np.ndarray]:
    """The share of the checked keyframes (:func:`checked_keyframes`) with
    points whose scan agrees with the other keyframes' map, how many such
    keyframes there are, and each checked keyframe's share of agreeing
    points (K,), NaN without points or not checked."""
    checked = np.zeros(n_keyframes, dtype=bool)
    checked[checked_keyframes(n_keyframes, bounds.checked_scans_max)] = True
    queries = np.flatnonzero(checked[keyframe])
    agree = point_agreement(points, keyframe, queries, bounds.agreement_radius_m, bounds.neighbours)
    count = np.bincount(keyframe[queries], minlength=n_keyframes).astype(float)
    hits = np.bincount(keyframe[queries], weights=agree.astype(float), minlength=n_keyframes)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(count > 0, hits / count, np.nan)
    seen = count > 0
    if seen.sum() < 2 or len(np.unique(keyframe)) < 2:
        return None, int(seen.sum()), share
    return float(np.mean(share[seen] >= bounds.agreeing_points_min)), int(seen.sum()), share


def loop_residuals(loops: Sequence[LoopConstraint], poses: np.ndarray) -> np.ndarray:
    """Per kept loop (n,), m: the translation between where the optimised
    map puts keyframe j seen from i and where the loop measured it, in the
    directions the loop's information pins (a free direction is projected
    out)."""
    out = []
    for lp in loops:
        err = between(np.asarray(lp.delta, dtype=float), between(poses[lp.i], poses[lp.j]))
        values, vectors = np.linalg.eigh(0.5 * (lp.information + lp.information.T))
        pinned = vectors[:, values > 1e-9 * max(values.max(), 1e-300)]
        e = pinned @ (pinned.T @ err)
        out.append(float(np.hypot(e[0], e[1])))
    return np.asarray(out)


def odometry_disagreement(odometry: BetweenMeasurement | None, poses: np.ndarray,
                          bounds: SelfCheckBounds) -> tuple[float | None, int]:
    """The share of valid odometry steps (keyframe k-1 to k) whose motion
    differs from the map's by more than the bounds, and how many there are."""
    if odometry is None or len(poses) < 2:
        return None, 0
    valid = np.asarray(odometry.valid, dtype=bool).copy()
    valid[0] = False
    if not valid.any():
        return None, 0
    est = relative_poses(poses[:-1], poses[1:])
    odo = np.asarray(odometry.delta)[1:]
    ok = valid[1:]
    d_xy = np.hypot(*(odo[:, :2] - est[:, :2]).T)
    d_yaw = np.degrees(np.abs(wrap_angle(odo[:, 2] - est[:, 2])))
    step = np.hypot(est[:, 0], est[:, 1])
    off = (d_xy > bounds.odometry_step_m + bounds.odometry_step_per_m * step) | (d_yaw > bounds.odometry_step_deg)
    return float(off[ok].mean()), int(ok.sum())


def free_space_returns(ranges: np.ndarray, angles: np.ndarray, beam_limits: tuple[float, float],
                       poses: Trajectory, bounds: SelfCheckBounds) -> tuple[float | None, int]:
    """The share of returns of scans ``ranges`` (K, beams) at ``poses`` that
    land in free space (``free_space_returns`` above), and how many returns
    there are; None without any or where the grid is too large."""
    from numpy.lib.stride_tricks import sliding_window_view

    from slam.outputs.occupancy import beam_counts

    lo, hi = beam_limits
    with np.errstate(invalid="ignore"):
        hit = np.isfinite(ranges) & (ranges >= lo) & (ranges < hi)
    if not hit.any():
        return None, 0
    # Only beams that returned say what is free: a laser cut off short, or
    # facing an open yard, says nothing of what lies beyond its last return.
    counts = beam_counts(ranges, angles, poses, lo, hi, bounds.free_space_cell_m, no_return_m=0.0)
    if counts is None:
        return None, 0
    k, b = np.nonzero(hit)
    heading = poses.yaw[k] + np.asarray(angles)[b]
    row, col = counts.cells(poses.x[k] + ranges[k, b] * np.cos(heading), poses.y[k] + ranges[k, b] * np.sin(heading))
    # Scans, not beams, on both sides: a scan crosses a cell about once
    # (beam_counts thins the fan near the laser) but may end several beams
    # in it; around a return, the most scans that end in one cell.
    shape = counts.hits.shape
    cell = row * shape[1] + col
    seen = np.unique(cell * len(ranges) + k) // len(ranges)
    scans_ending = np.bincount(seen, minlength=counts.hits.size).reshape(shape)
    around = sliding_window_view(np.pad(scans_ending, 1), (3, 3)).max(axis=(2, 3))
    free = counts.misses[row, col] > around[row, col]
    return float(free.mean()), int(len(free))


# -- the check ----------------------------------------------------------------


def check_map(trajectory: Trajectory, scans: Scans | None = None, scan_index: np.ndarray | None = None,
              beam_limits: tuple[float, float] | None = None, loops: Sequence[LoopConstraint] = (),
              odometry: BetweenMeasurement | None = None,
              stamps_synthesised: str | None = None, blame_share: float | None = None,
              bounds: SelfCheckBounds = SelfCheckBounds()) -> SelfCheck:
    """The self-check of a map: ``trajectory`` the optimised keyframe poses;
    ``scans``, ``scan_index`` and ``beam_limits`` the keyframes' scans
    (None: no laser); ``loops`` the kept loop constraints; ``odometry`` the
    odometry's between measurements per keyframe step (None: none)."""
    start = time.perf_counter()
    poses = np.column_stack([trajectory.x, trajectory.y, trajectory.yaw])
    b = bounds
    figures = []
    agreement, n_scans = None, 0
    in_free, n_returns = None, 0
    if scans is not None and scan_index is not None:
        pts, kf = scan_points(scans.ranges[scan_index], scans.angles, beam_limits, trajectory, b.voxel_m)
        agreement, n_scans, _ = scan_agreement(pts, kf, len(scan_index), b)
        in_free, n_returns = map_free_space_returns(trajectory, scans, scan_index, beam_limits, b)
    figures.append(CheckedFigure("scan_agreement", _round(agreement), b.scan_agreement_min, Side.AT_LEAST, n_scans))
    figures.append(CheckedFigure("free_space_returns", _round(in_free), b.free_space_returns_max, Side.AT_MOST,
                                 n_returns))
    res = loop_residuals(loops, poses) if len(loops) else np.zeros(0)
    q = float(np.quantile(res, b.loop_residual_quantile)) if len(res) else None
    figures.append(CheckedFigure("loop_residual_m", _round(q), b.loop_residual_max_m, Side.AT_MOST, len(res), "m"))
    share, n_steps = odometry_disagreement(odometry, poses, b)
    figures.append(CheckedFigure("odometry_disagreement", _round(share), b.odometry_disagreement_max, Side.AT_MOST,
                                 n_steps))
    notes = {"stamps_synthesised": stamps_synthesised, "blame_share": blame_share}
    return SelfCheck(figures, notes, time.perf_counter() - start)


def return_cells(ranges: np.ndarray, angles: np.ndarray, beam_limits: tuple[float, float], poses: Trajectory,
                 cell_m: float) -> int:
    """How many ``cell_m`` cells the returns of scans ``ranges`` (K, beams)
    at ``poses`` land in: the area of the map's walls. A map that holds
    together lays a wall seen again on the cells it was seen on before; a
    torn map lays it again elsewhere, across a room another piece saw empty
    (:func:`free_space_returns`) or apart from the rest, where nothing
    contradicts it but its walls take twice the cells. Only comparable
    between estimates of the same scans."""
    from slam.frontend.kiss import ScanProjector

    pts, _ = ScanProjector(angles, *beam_limits).world_points(ranges, poses)
    if len(pts) == 0:
        return 0
    return len(np.unique(np.floor(pts / cell_m).astype(np.int64), axis=0))


def map_free_space_returns(trajectory: Trajectory, scans: Scans, scan_index: np.ndarray,
                           beam_limits: tuple[float, float], bounds: SelfCheckBounds = SelfCheckBounds()
                           ) -> tuple[float | None, int]:
    """:func:`free_space_returns` of the keyframes' scans
    ``scans.ranges[scan_index]`` at their poses ``trajectory``, every one
    of them or evenly spaced ones beyond ``bounds.free_space_scans_max``."""
    ranges, poses = _cast_keyframes(trajectory, scans, scan_index, bounds)
    return free_space_returns(ranges, scans.angles, beam_limits, poses, bounds)


def map_return_cells(trajectory: Trajectory, scans: Scans, scan_index: np.ndarray,
                     beam_limits: tuple[float, float], bounds: SelfCheckBounds = SelfCheckBounds()) -> int:
    """:func:`return_cells` of the keyframes cast by
    :func:`map_free_space_returns`, in its cells."""
    ranges, poses = _cast_keyframes(trajectory, scans, scan_index, bounds)
    return return_cells(ranges, scans.angles, beam_limits, poses, bounds.free_space_cell_m)


def _cast_keyframes(trajectory: Trajectory, scans: Scans, scan_index: np.ndarray,
                    bounds: SelfCheckBounds) -> tuple[np.ndarray, Trajectory]:
    cast = checked_keyframes(len(scan_index), bounds.free_space_scans_max)
    poses = Trajectory(t=trajectory.t[cast], x=trajectory.x[cast], y=trajectory.y[cast], yaw=trajectory.yaw[cast])
    return scans.ranges[scan_index[cast]], poses


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 4)
