"""Laser map as a point cloud, written with open3d.

open3d is imported here only, lazily: it is heavy, and on Debian its wheel
links against libusb-1.0, which a bare system lacks. The ``libusb-package``
wheel ships that library; it is loaded first so open3d imports anywhere.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from slam.errors import GslamError
from slam.io.atomic import atomic_path


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


def write_ply(path: str | Path, points_xy: np.ndarray) -> None:
    """Write planar points (n, 2) as a PLY point cloud at z = 0, atomically."""
    o3d = import_open3d()
    cloud = o3d.geometry.PointCloud()
    xyz = np.column_stack([points_xy, np.zeros(len(points_xy))]) if len(points_xy) else np.zeros((0, 3))
    cloud.points = o3d.utility.Vector3dVector(xyz)
    with atomic_path(path) as tmp:
        if not o3d.io.write_point_cloud(str(tmp), cloud):
            raise GslamError(f"{path}: open3d could not write the point cloud")
