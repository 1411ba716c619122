"""Reader for the libRSF data sets (TU Chemnitz), e.g. ``Corridor``.

A data set is a pair of text files with one measurement per line, first
word the type, second the time (s)::

    NAME_Input.txt   odom2 t vx vy wz var_vx var_vy var_wz (10 Hz; m/s, rad/s; variances)
                     loop t t_other weight           (place recognition)
    NAME_GT.txt      point2 t x y c_xx c_xy c_yx c_yy (m)
                     angle t yaw c                    (rad; optional)

Other types are ignored. What becomes of them:

* ``Recording.odometry``: the body velocities integrated exactly on SE(2)
  (constant velocity along an arc within each interval), starting at the
  origin with yaw 0 in the odometry's own frame. The velocities at ``t_k``
  move the robot over ``(t_{k-1}, t_k]``, as libRSF's odometry factors use a
  measurement for the interval that ends at its stamp.
* ``Recording.gyro``: ``wz``, the yaw rate about the body z axis (rad/s).
* ``Recording.place_matches``: the ``loop`` lines, every one of them
  (false matches included): at ``t`` the robot is where it was at
  ``t_other``, with the similarity ``weight``.
* ``Recording.groundtruth``: the ``point2`` positions; yaw from the ``angle``
  lines at the same stamps when present, else the direction of motion
  (``atan2`` of the position change over ``HEADING_BASELINE_M`` of path),
  held while the robot stands still and back-filled before it first moves.

Times are the files' (already relative, ``t0`` = 0). Given either file or
the folder holding exactly one ``*_Input.txt``, the reader finds both.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from slam.config import InputConfig
from slam.errors import GslamError
from validation.base.bounds import shown_beside
from validation.base.geometry import wrap_angle
from slam.readers.carmen import chain_steps
from slam.readers.files import NOT_PLAIN, check_exists, log_lines, unplain_number
from validation.base.yamlio import check_regular_file
from slam.recording import Gyro, PlaceMatches, Recording, Trajectory

log = logging.getLogger(__name__)

INPUT_SUFFIX = "_Input.txt"
GT_SUFFIX = "_GT.txt"
HEADING_BASELINE_M = 0.2

_ODOM2 = "odom2 t vx vy wz var_vx var_vy var_wz"
_POINT2 = "point2 t x y c_xx c_xy c_yx c_yy"
_ANGLE = "angle t yaw c"
_LOOP = "loop t t_other weight"


def dataset_files(path: str | Path) -> tuple[Path, Path | None]:
    """``(input, groundtruth or None)`` for a ``*_Input.txt``, a ``*_GT.txt``
    or a folder holding exactly one ``*_Input.txt``; None when no
    ``*_GT.txt`` is beside the input."""
    path = Path(path)
    check_exists(path)
    if path.is_dir():
        inputs = sorted(path.glob(f"*{INPUT_SUFFIX}"))
        if len(inputs) != 1:
            found = ", ".join(p.name for p in inputs) or "none"
            raise GslamError(f"{path}: expected exactly one *{INPUT_SUFFIX} in the folder, found {found}")
        path = inputs[0]
    name = path.name
    if name.endswith(GT_SUFFIX):
        inp = path.with_name(name[: -len(GT_SUFFIX)] + INPUT_SUFFIX)
        if not inp.is_file():
            raise GslamError(f"{path}: expected the matching input file {inp.name} beside it")
        return inp, path
    if not name.endswith(INPUT_SUFFIX):
        raise GslamError(f"{path}: expected a libRSF *{INPUT_SUFFIX} or *{GT_SUFFIX} file")
    gt = path.with_name(name[: -len(INPUT_SUFFIX)] + GT_SUFFIX)
    if not (gt.exists() or gt.is_symlink()):
        return path, None
    # One there that is no file (a folder, a named pipe, a link to nothing)
    # is named, not taken for none: the run would be scored without truth.
    check_exists(gt)
    check_regular_file(gt, "libRSF ground truth")
    return path, gt


def looks_like_librsf(path: str | Path) -> bool:
    """A ``*_Input.txt`` / ``*_GT.txt`` file, or a folder with one
    ``*_Input.txt``."""
    path = Path(path)
    if path.is_dir():
        return len(list(path.glob(f"*{INPUT_SUFFIX}"))) == 1
    return path.is_file() and path.name.endswith((INPUT_SUFFIX, GT_SUFFIX))


def _read_rows(path: Path, wanted: dict[str, tuple[int, str]]) -> dict[str, np.ndarray]:
    """Rows of the wanted types as float arrays: ``wanted`` maps a type to
    (number of numeric fields used, description for errors)."""
    rows: dict[str, list[list[float]]] = {kind: [] for kind in wanted}
    check_regular_file(path, "libRSF file")
    for lineno, line in enumerate(log_lines(path, "libRSF text file"), start=1):
        parts = line.split()
        if not parts or parts[0] not in wanted:
            continue
        count, expected = wanted[parts[0]]
        try:
            values = [float(v) for v in parts[1 : count + 1]]
        except ValueError:
            raise GslamError(f"{path}:{lineno}: expected {expected}") from None
        odd = unplain_number(parts[1 : count + 1])
        if odd is not None:
            raise GslamError(f"{path}:{lineno}: expected {expected}; {expected.split()[odd + 1]} is "
                             f"{parts[odd + 1]!r}, {NOT_PLAIN}")
        if len(values) < count or not all(np.isfinite(values)):
            raise GslamError(f"{path}:{lineno}: expected {expected}")
        given, known = len(parts) - 1, len(expected.split()) - 1
        if given > known:  # a column more: appended, or inserted, shifting the ones read; which, no one can tell
            raise GslamError(f"{path}:{lineno}: expected {expected} ({known} values, got {given})")
        rows[parts[0]].append(values)
    return {kind: np.asarray(r, dtype=np.float64).reshape(-1, wanted[kind][0]) for kind, r in rows.items()}


def _increasing(path: Path, t: np.ndarray, what: str) -> None:
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        raise GslamError(f"{path}: {what} #{k + 1}: expected increasing times, got {t[k]} after {t[k - 1]}")


MAX_SPEED_M_S = 100.0
"""m/s (360 km/h): no ground robot drives faster (the Corridor's reaches 0.8)."""
_VARIANCES = ("var_vx", "var_vy", "var_wz")


def _physical_odometry(path: Path, rows: np.ndarray) -> None:
    """One-line errors for odom2 lines no robot gives: a speed beyond
    :data:`MAX_SPEED_M_S`, a negative variance (a variance is a square)."""
    speed = np.hypot(rows[:, 1], rows[:, 2])
    if np.any(speed > MAX_SPEED_M_S):
        k = int(np.argmax(speed > MAX_SPEED_M_S))
        raise GslamError(f"{path}: odom2 line #{k + 1}: speed {shown_beside(speed[k], MAX_SPEED_M_S)} m/s "
                         f"(vx {rows[k, 1]:g}, vy {rows[k, 2]:g}); no ground robot drives faster than {MAX_SPEED_M_S:g} m/s (expected m/s)")
    for column, name in zip((4, 5, 6), _VARIANCES):
        if np.any(rows[:, column] < 0.0):
            k = int(np.argmax(rows[:, column] < 0.0))
            raise GslamError(f"{path}: odom2 line #{k + 1}: {name} {rows[k, column]:g} is negative; a variance is "
                             "a square (expected 0 or more)")


MAX_LOOP_WEIGHT = 1e6
"""A loop line's weight multiplies the information of its constraint (the
Corridor's are 0.005-1): beyond a million, as any information scale
(:data:`validation.base.bounds.INFORMATION_SCALE`), its sigma is a
thousandth of ``loops.file.sigma_m`` and its square overflows."""
LOOP_STAMP_SLACK_S = 10.0
"""How far a loop line's stamps may lie outside the odom2 lines' span (s):
the Corridor's last loop is 0.2 s after its last odom2 line."""


def _physical_loops(path: Path, loops: np.ndarray, t: np.ndarray) -> None:
    """One-line errors for loop lines that cannot be: a weight below 0 or
    beyond :data:`MAX_LOOP_WEIGHT`, a pose joined to itself (t equal to
    t_other says nothing), stamps outside the odometry's span by more than
    :data:`LOOP_STAMP_SLACK_S` (another log's, or another unit)."""
    weight = loops[:, 2]
    bad = (weight < 0.0) | (weight > MAX_LOOP_WEIGHT)
    if bad.any():
        k = int(np.argmax(bad))
        raise GslamError(f"{path}: loop line #{k + 1}: weight {weight[k]:g}; expected 0 to {MAX_LOOP_WEIGHT:g} (it "
                         "scales the loop's information)")
    same = loops[:, 0] == loops[:, 1]
    if same.any():
        k = int(np.argmax(same))
        raise GslamError(f"{path}: loop line #{k + 1}: t and t_other are both {loops[k, 0]:g} s, a pose joined to "
                         "itself; expected the times of two visits to one place")
    lo, hi = t[0] - LOOP_STAMP_SLACK_S, t[-1] + LOOP_STAMP_SLACK_S
    outside = (loops[:, :2] < lo) | (loops[:, :2] > hi)
    if outside.any():
        k, c = (int(v[0]) for v in np.nonzero(outside))
        raise GslamError(f"{path}: loop line #{k + 1}: {('t', 't_other')[c]} {loops[k, c]:g} s is outside the "
                         f"odom2 lines' {t[0]:g} to {t[-1]:g} s; expected a time of this log")


def integrate_velocities(t: np.ndarray, vx: np.ndarray, vy: np.ndarray, wz: np.ndarray) -> np.ndarray:
    """Poses (n, 3) from body velocities (m/s, m/s, rad/s) at times ``t`` (s),
    starting at the origin; the velocities at ``t_k`` act over
    ``(t_{k-1}, t_k]`` along a circular arc (exact for constant velocity)."""
    dt = np.diff(t)
    v_x, v_y, w = vx[1:], vy[1:], wz[1:]
    th = w * dt
    small = np.abs(th) < 1e-9
    th_safe = np.where(small, 1.0, th)
    # SE(2) exponential: V(th) = [[sin th, -(1 - cos th)], [1 - cos th, sin th]] / th.
    a = np.where(small, 1.0 - th**2 / 6.0, np.sin(th) / th_safe)
    b = np.where(small, th / 2.0, (1.0 - np.cos(th)) / th_safe)
    steps = np.column_stack([(a * v_x - b * v_y) * dt, (b * v_x + a * v_y) * dt, th])
    return chain_steps(np.zeros(3), steps)


def _heading_from_motion(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Direction of motion (rad) over the next ``HEADING_BASELINE_M`` of path,
    held while standing still, back-filled before the first motion."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(y)))])
    ahead = np.searchsorted(s, s + HEADING_BASELINE_M)
    yaw = np.full(len(x), np.nan)
    moving = ahead < len(x)
    idx = np.flatnonzero(moving)
    yaw[idx] = np.arctan2(y[ahead[idx]] - y[idx], x[ahead[idx]] - x[idx])
    if not moving.any():
        return np.zeros(len(x))
    # The tail (less than a baseline left) holds the last heading.
    last = np.maximum.accumulate(np.where(np.isfinite(yaw), np.arange(len(x)), -1))
    first = int(idx[0])
    yaw = yaw[np.maximum(last, first)]
    return yaw


def read_librsf(path: str | Path, config: InputConfig | None = None) -> Recording:
    """Read a libRSF data set into a :class:`Recording` with ``odometry``,
    ``gyro``, ``place_matches`` (when there are ``loop`` lines) and (when the
    ``*_GT.txt`` exists) ``groundtruth``; see the module docstring. ``config`` is accepted for the reader interface."""
    inp, gt_path = dataset_files(path)
    read = _read_rows(inp, {"odom2": (7, _ODOM2), "loop": (3, _LOOP)})
    rows, loops = read["odom2"], read["loop"]
    if len(rows) < 2:
        raise GslamError(f"{inp}: expected at least 2 '{_ODOM2}' lines, found {len(rows)}")
    t, vx, vy, wz = rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3]
    _increasing(inp, t, "odom2 line")
    _physical_odometry(inp, rows)
    if len(loops):
        _physical_loops(inp, loops, t)
    poses = integrate_velocities(t, vx, vy, wz)
    odometry = Trajectory(t=t.copy(), x=poses[:, 0], y=poses[:, 1], yaw=poses[:, 2])

    groundtruth = None
    if gt_path is None:
        log.warning("%s: no %s beside it; no ground truth", inp, inp.name.replace(INPUT_SUFFIX, GT_SUFFIX))
    else:
        gt = _read_rows(gt_path, {"point2": (3, _POINT2), "angle": (2, _ANGLE)})
        pts, ang = gt["point2"], gt["angle"]
        if len(pts) == 0:
            raise GslamError(f"{gt_path}: expected '{_POINT2}' lines, found none")
        _increasing(gt_path, pts[:, 0], "point2 line")
        if len(ang) == len(pts) and np.allclose(ang[:, 0], pts[:, 0]):
            yaw = wrap_angle(ang[:, 1])
        else:
            if len(ang):
                log.warning("%s: angle lines do not match the point2 stamps; yaw from the direction of motion", gt_path)
            yaw = _heading_from_motion(pts[:, 1], pts[:, 2])
        groundtruth = Trajectory(t=pts[:, 0].copy(), x=pts[:, 1].copy(), y=pts[:, 2].copy(), yaw=yaw)

    name = inp.name[: -len(INPUT_SUFFIX)]
    matches = None
    if len(loops):
        matches = PlaceMatches(t=loops[:, 0].copy(), t_other=loops[:, 1].copy(), weight=loops[:, 2].copy())
    rec = Recording(
        name=name, t0=0.0, odometry=odometry, gyro=Gyro(t=t.copy(), rate=wz.copy()), groundtruth=groundtruth,
        place_matches=matches,
    )
    log.info("%s: %d odometry samples, %d loop lines over %.1f s", inp, len(t), len(loops), rec.duration)
    return rec
