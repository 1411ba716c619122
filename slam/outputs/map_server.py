"""Occupancy grids in the map_server format: an 8-bit PGM image and a YAML
file, as ROS's map_server and nav2's map_server and AMCL load them.

The YAML holds ``image`` (relative to the YAML file), ``mode``,
``resolution`` (m per cell), ``origin`` (x, y, yaw of the lower-left
corner of the lower-left pixel, m and rad), ``negate``, ``occupied_thresh``
and ``free_thresh``. In ``trinary`` mode, nav2 reads a pixel of shade
``s = value / 255`` as occupied where ``1 - s > occupied_thresh``, free where
``1 - s < free_thresh`` and unknown otherwise (with ``negate``, ``s`` for
``1 - s``). The image's first row is the map's top (largest y).

Cells are written as map_saver writes them: 0 (black) occupied, 254
(white) free, 205 (grey) unknown, with the thresholds the grid was
classified with (:data:`slam.outputs.occupancy.FREE_BELOW`, ``OCCUPIED_ABOVE``).
``free_thresh`` is ROS map_saver's 0.196, just under the grey's 0.19608:
nav2's saver writes 0.25, which reads its own unknown grey back as free.

:func:`read_map` parses the format as nav2's ``loadMapYaml`` and
``loadMapFromFile`` do (trinary, scale and raw modes; binary PGM images),
so a test can check that what is written reads back to the same cells.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from slam.errors import GslamError
from slam.results.atomic import atomic_path, write_text
from slam.outputs.occupancy import FREE, FREE_BELOW, OCCUPIED, OCCUPIED_ABOVE, UNKNOWN, GridMap

PIXELS = {OCCUPIED: 0, FREE: 254, UNKNOWN: 205}
"""Pixel value of each cell value in trinary mode, as map_saver writes them."""

MODES = ("trinary", "scale", "raw")


@dataclass(frozen=True)
class MapServerMap:
    """A map as map_server loads it: ``data`` (height, width) int8 cell
    values (100 occupied, 0 free, -1 unknown; 0..100 in between for scale
    mode), row 0 at the origin (``nav_msgs/OccupancyGrid`` order), the
    resolution (m), the origin (x, y, yaw) and the YAML's fields."""

    data: np.ndarray
    resolution: float
    origin: tuple[float, float, float]
    fields: dict


def map_image(cells: np.ndarray) -> np.ndarray:
    """The trinary image (uint8, first row on top) of cell values (int8,
    ``nav_msgs/OccupancyGrid`` order)."""
    image = np.full(cells.shape, PIXELS[UNKNOWN], dtype=np.uint8)
    image[cells == OCCUPIED] = PIXELS[OCCUPIED]
    image[cells == FREE] = PIXELS[FREE]
    return np.ascontiguousarray(image[::-1])


def pgm_bytes(image: np.ndarray) -> bytes:
    """An 8-bit image (rows, cols) as a binary PGM (P5) file."""
    rows, cols = image.shape
    return f"P5\n{cols} {rows}\n255\n".encode("ascii") + np.ascontiguousarray(image, dtype=np.uint8).tobytes()


def map_yaml(image_name: str, resolution_m: float, origin_xy: np.ndarray) -> str:
    """The map_server YAML of a trinary image; numbers as Python prints them,
    so they read back exactly."""
    x, y = (float(v) for v in origin_xy)
    return (
        f"image: {image_name}\n"
        "mode: trinary\n"
        f"resolution: {float(resolution_m)!r}\n"
        f"origin: [{x!r}, {y!r}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {OCCUPIED_ABOVE}\n"
        f"free_thresh: {FREE_BELOW}\n"
    )


def write_map(folder: str | Path, grid: GridMap, name: str = "map") -> None:
    """Write ``name.pgm`` and ``name.yaml`` into ``folder``, each atomically."""
    folder = Path(folder)
    with atomic_path(folder / f"{name}.pgm") as tmp:
        tmp.write_bytes(pgm_bytes(map_image(grid.cells)))
    write_text(folder / f"{name}.yaml", map_yaml(f"{name}.pgm", grid.resolution_m, grid.origin))


def read_map(yaml_path: str | Path) -> MapServerMap:
    """Load a map as nav2's map_server does (see the module docstring);
    a malformed file raises :class:`GslamError` naming it."""
    yaml_path = Path(yaml_path)
    try:
        doc = yaml.safe_load(yaml_path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise GslamError(f"{yaml_path}: not a readable map YAML ({e})") from None
    if not isinstance(doc, dict):
        raise GslamError(f"{yaml_path}: expected a mapping of map_server fields")
    for key in ("image", "resolution", "origin", "occupied_thresh", "free_thresh"):
        if key not in doc:
            raise GslamError(f"{yaml_path}: missing key '{key}'")
    origin = doc["origin"]
    if not isinstance(origin, list) or len(origin) != 3:
        raise GslamError(f"{yaml_path}: 'origin' must be a list of 3 numbers (x, y, yaw)")
    mode = str(doc.get("mode", "trinary"))
    if mode not in MODES:
        raise GslamError(f"{yaml_path}: unknown mode '{mode}' (expected one of {', '.join(MODES)})")
    image_path = Path(str(doc["image"]))
    if not image_path.is_absolute():
        image_path = yaml_path.parent / image_path
    shade = read_pgm(image_path).astype(np.float64) / 255.0
    occ = shade if int(doc.get("negate", 0)) else 1.0 - shade
    occupied, free = float(doc["occupied_thresh"]), float(doc["free_thresh"])
    if mode == "raw":
        value = np.round(shade * 255.0)
        data = np.where(value <= 100, value, UNKNOWN)
    else:
        data = np.full(occ.shape, UNKNOWN, dtype=np.float64)
        if mode == "scale":  # a PGM has no alpha: every pixel is opaque
            data = np.rint((occ - free) / (occupied - free) * 100.0)
        data[occupied < occ] = OCCUPIED
        data[occ < free] = FREE
    return MapServerMap(data.astype(np.int8)[::-1].copy(), float(doc["resolution"]),
                        tuple(float(v) for v in origin), doc)


_PGM_HEADER = re.compile(rb"P5(?:\s+|#[^\n]*\n)+(\d+)(?:\s+|#[^\n]*\n)+(\d+)(?:\s+|#[^\n]*\n)+(\d+)\s")


def read_pgm(path: str | Path) -> np.ndarray:
    """An 8-bit binary PGM (P5) image as uint8 (rows, cols)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as e:
        raise GslamError(f"{path}: cannot read the map image ({e.strerror})") from None
    m = _PGM_HEADER.match(data)
    if m is None:
        raise GslamError(f"{path}: not a binary PGM (P5) image")
    cols, rows, maxval = (int(g) for g in m.groups())
    if maxval != 255 or len(data) - m.end() != rows * cols:
        raise GslamError(f"{path}: expected {rows} x {cols} 8-bit pixels after the header")
    return np.frombuffer(data, dtype=np.uint8, offset=m.end()).reshape(rows, cols)

