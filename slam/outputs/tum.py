"""TUM trajectory files: one pose per line, ``timestamp x y z qx qy qz qw``.

The format evo and most SLAM benchmarks read. Stamps are absolute UNIX
seconds; the project's trajectories are relative to ``Recording.t0``, so the
writer adds ``t0`` and the reader subtracts it again. Poses are planar: z is
written as 0 and the quaternion is a pure rotation about z by the yaw; the
reader keeps x, y and the yaw of the quaternion and drops z, roll and pitch.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from slam.errors import GslamError
from validation.base.geometry import yaw_from_quaternion
from slam.results.atomic import write_text
from slam.recording import Trajectory

logger = logging.getLogger(__name__)

TUM_HEADER = "# timestamp x y z qx qy qz qw"
_FIELDS = 8


def write_tum(path: str | Path, traj: Trajectory, t0: float) -> None:
    """Write ``traj`` to ``path`` as a TUM file, atomically.

    ``t0`` (s, absolute UNIX time) is added to the trajectory's relative
    times. Stamps keep 9 decimals (ns), positions 6 (um) and quaternion
    components 9, so a round trip loses far less than any error we measure.
    """
    write_text(path, tum_text(traj, t0))
    logger.debug("wrote %d poses to %s", len(traj), path)


def tum_text(traj: Trajectory, t0: float, chunk: int = 65536) -> str:
    """The TUM file of ``traj`` as text (see :func:`write_tum`).

    Vectorised: the quaternions of all poses at once, and one ``%`` format
    per ``chunk`` lines instead of one per line; the text is the same as
    formatting each pose with :func:`validation.base.geometry.quaternion_from_yaw`.
    """
    half = np.asarray(traj.yaw, dtype=np.float64) / 2.0
    # qx = qy = 0 and z = 0 of a planar pose are constant text.
    cols = np.column_stack([t0 + np.asarray(traj.t, dtype=np.float64), traj.x, traj.y, np.sin(half), np.cos(half)])
    line = "%.9f %.6f %.6f 0.000000 0.000000000 0.000000000 %.9f %.9f\n"
    parts = [TUM_HEADER + "\n"]
    for lo in range(0, len(cols), chunk):
        block = cols[lo : lo + chunk]
        parts.append((line * len(block)) % tuple(block.ravel().tolist()))
    return "".join(parts)


def _parse_line(path: Path, lineno: int, line: str) -> list[float]:
    """The 8 numbers of one data line, or a one-line GslamError naming it."""
    parts = line.split()
    if len(parts) != _FIELDS:
        raise GslamError(
            f"{path}:{lineno}: expected {_FIELDS} numbers "
            f"'timestamp x y z qx qy qz qw', got {len(parts)} fields"
        )
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise GslamError(f"{path}:{lineno}: expected numbers, got '{line.strip()}'") from None
    if not all(math.isfinite(v) for v in values):
        raise GslamError(f"{path}:{lineno}: non-finite value in '{line.strip()}'")
    return values


def read_tum(path: str | Path, t0: float | None = None) -> tuple[Trajectory, float]:
    """Read a TUM file into a planar trajectory.

    Returns ``(trajectory, t0)``: times in the trajectory are relative to
    ``t0`` (s, absolute). Pass ``t0`` to put several files on one time base
    (e.g. a recording's ``t0``); by default it is the first stamp. Blank lines
    and lines starting with ``#`` are skipped. Stamps must increase strictly.
    Raises :class:`GslamError` naming ``file:line`` for malformed input.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise GslamError(f"{path}: cannot read TUM trajectory ({exc})") from None

    rows: list[list[float]] = []
    linenos: list[int] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        rows.append(_parse_line(path, lineno, stripped))
        linenos.append(lineno)
    if not rows:
        raise GslamError(f"{path}: no poses (expected lines 'timestamp x y z qx qy qz qw')")

    data = np.asarray(rows, dtype=float)
    stamps = data[:, 0]
    not_increasing = np.flatnonzero(np.diff(stamps) <= 0.0)
    if not_increasing.size:
        k = int(not_increasing[0]) + 1
        raise GslamError(
            f"{path}:{linenos[k]}: timestamp {stamps[k]:.9f} does not increase "
            f"(previous {stamps[k - 1]:.9f})"
        )
    # A zero quaternion has no orientation; a scaled one still does.
    q_norm = np.linalg.norm(data[:, 4:8], axis=1)
    bad = np.flatnonzero(q_norm < 1e-9)
    if bad.size:
        raise GslamError(f"{path}:{linenos[int(bad[0])]}: zero quaternion")

    base = float(stamps[0]) if t0 is None else float(t0)
    qx, qy, qz, qw = (data[:, 4:8] / q_norm[:, None]).T
    traj = Trajectory(
        t=stamps - base,
        x=data[:, 1].copy(),
        y=data[:, 2].copy(),
        yaw=np.asarray(yaw_from_quaternion(qx, qy, qz, qw), dtype=float),
    )
    logger.debug("read %d poses from %s", len(traj), path)
    return traj, base
