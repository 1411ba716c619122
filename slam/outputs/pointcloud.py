"""Laser map as a point cloud: a binary PLY file, written with numpy.

The file is byte for byte what open3d's ``write_point_cloud`` writes for a
cloud of points only (its header, little-endian float64 x, y, z), so any
PLY reader, open3d included, reads it; writing it needs no open3d.
:func:`import_open3d` is for the map's self-check
(:mod:`slam.outputs.self_check`, in a process of its own that imports it
while the run is mapped: it costs half a second) and for readers of the files (tests,
notebooks); on Debian open3d's wheel links against libusb-1.0, which a
bare system lacks, so the ``libusb-package`` wheel's copy is loaded first
and open3d imports anywhere.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from slam.errors import GslamError
from slam.config import FrontendConfig
from slam.recording import Recording, Scans, Trajectory
from slam.results.atomic import atomic_path

PLY_HEADER = (
    "ply\nformat binary_little_endian 1.0\ncomment Created by Open3D\nelement vertex {n}\n"
    "property double x\nproperty double y\nproperty double z\nend_header\n"
)


def import_open3d():
    """Import open3d, providing libusb-1.0 from ``libusb-package`` if the
    system has none."""
    try:
        import open3d
    except ImportError as first:
        try:
            import libusb_package

            ctypes.CDLL(str(libusb_package.get_library_path()), mode=ctypes.RTLD_GLOBAL)
            import open3d
        except (ImportError, OSError, TypeError):
            raise GslamError(f"open3d cannot be imported ({first}); install it with pip install open3d") from None
    return open3d


def voxel_downsample(points_xy: np.ndarray, voxel_m: float) -> np.ndarray:
    """One point per occupied voxel (the first), (m, 2); keeps maps small."""
    if len(points_xy) == 0:
        return points_xy
    cells = np.floor(points_xy / voxel_m).astype(np.int64)
    # One integer per cell: unique over a 1-D key is much faster than over rows.
    cells -= cells.min(axis=0)
    key = cells[:, 0] * (int(cells[:, 1].max()) + 1) + cells[:, 1]
    _, first = np.unique(key, return_index=True)  # stable: the first point of each cell
    return points_xy[np.sort(first)]


def ply_bytes(points_xy: np.ndarray) -> bytes:
    """Planar points (n, 2) as a binary PLY point cloud at z = 0."""
    pts = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    xyz = np.zeros((len(pts), 3), dtype="<f8")
    xyz[:, :2] = pts
    return PLY_HEADER.format(n=len(pts)).encode("ascii") + xyz.tobytes()


def write_ply(path: str | Path, points_xy: np.ndarray) -> None:
    """Write planar points (n, 2) as a PLY point cloud at z = 0, atomically."""
    data = ply_bytes(points_xy)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def beam_limits(frontend: FrontendConfig, scans: Scans) -> tuple[float, float]:
    """The ranges (m) a beam must lie within to be a return: the
    front-end's, and the scanner's own maximum."""
    return frontend.min_range_m, min(frontend.max_range_m, scans.range_max)


def map_points(rec: Recording, scan_index: np.ndarray | None, trajectory: Trajectory, frontend: FrontendConfig,
               voxel_m: float, chunk: int = 2048) -> np.ndarray | None:
    """Laser points of every keyframe (``scan_index``: its scan) in its
    optimised pose ``trajectory``, voxel-thinned (world frame, m, (n, 2)).

    Keyframes are projected ``chunk`` at a time and each chunk thinned on
    its own: the first point of a voxel over all chunks is the first of
    the chunks' firsts, so the map does not depend on ``chunk``.
    """
    from slam.frontend.kiss import ScanProjector

    if rec.scans is None or scan_index is None:
        return None
    est = trajectory
    project = ScanProjector(rec.scans.angles, *beam_limits(frontend, rec.scans))
    chunks = []
    for lo in range(0, len(scan_index), chunk):
        k = slice(lo, lo + chunk)
        poses = Trajectory(est.t[k], est.x[k], est.y[k], est.yaw[k])
        chunks.append(voxel_downsample(project.world_points(rec.scans.ranges[scan_index[k]], poses)[0], voxel_m))
    points = np.concatenate(chunks) if chunks else np.zeros((0, 2))
    return voxel_downsample(points, voxel_m)
