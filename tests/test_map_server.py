"""map.pgm + map.yaml (slam.outputs.map_server): what nav2's map_server reads
back is the grid written, and the parser follows map_server's rules."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from slam.errors import GslamError
from slam.outputs.map_server import read_map, read_pgm, write_map
from slam.outputs.occupancy import FREE, OCCUPIED, UNKNOWN, GridMap


def random_grid(rows: int = 7, cols: int = 11, seed: int = 0) -> GridMap:
    cells = np.random.default_rng(seed).choice(np.array([OCCUPIED, FREE, UNKNOWN], dtype=np.int8), (rows, cols))
    return GridMap(cells, np.array([-3.25, 12.5]), 0.05)


def test_written_map_reads_back_to_the_same_cells(tmp_path):
    grid = random_grid()
    write_map(tmp_path, grid)
    doc = yaml.safe_load((tmp_path / "map.yaml").read_text())
    assert doc == {"image": "map.pgm", "mode": "trinary", "resolution": 0.05, "origin": [-3.25, 12.5, 0.0],
                   "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}
    loaded = read_map(tmp_path / "map.yaml")
    np.testing.assert_array_equal(loaded.data, grid.cells)
    assert loaded.resolution == 0.05 and loaded.origin == (-3.25, 12.5, 0.0)


def test_the_image_is_upside_down_and_in_map_savers_shades(tmp_path):
    cells = np.array([[OCCUPIED, FREE, UNKNOWN], [FREE, FREE, FREE]], dtype=np.int8)  # row 0 at the origin
    write_map(tmp_path, GridMap(cells, np.zeros(2), 0.1))
    image = read_pgm(tmp_path / "map.pgm")
    np.testing.assert_array_equal(image, [[254, 254, 254], [0, 254, 205]])
    assert (tmp_path / "map.pgm").read_bytes().startswith(b"P5\n3 2\n255\n")


def test_parser_follows_map_server_modes(tmp_path):
    # Shades 0 (black), 100, 205 (map_saver's grey), 254: occ = 1 - shade/255.
    (tmp_path / "m.pgm").write_bytes(b"P5\n# a comment\n4 1\n255\n" + bytes([0, 100, 205, 254]))
    base = {"image": "m.pgm", "resolution": 0.1, "origin": [0, 0, 0], "occupied_thresh": 0.65, "free_thresh": 0.25}
    for mode, negate, expected in (
        ("trinary", 0, [OCCUPIED, UNKNOWN, FREE, FREE]),  # nav2's 0.25 reads the grey as free
        ("trinary", 1, [FREE, UNKNOWN, OCCUPIED, OCCUPIED]),
        ("scale", 0, [OCCUPIED, 89, FREE, FREE]),  # (0.6078 - 0.25) / 0.4 * 100 = 89.46
        ("raw", 0, [0, 100, UNKNOWN, UNKNOWN]),
    ):
        (tmp_path / "m.yaml").write_text(yaml.safe_dump({**base, "mode": mode, "negate": negate}))
        data = read_map(tmp_path / "m.yaml").data
        assert data.tolist() == [expected], (mode, negate)


def test_a_malformed_map_is_a_clear_error(tmp_path):
    (tmp_path / "m.pgm").write_bytes(b"P2\n1 1\n255\n0\n")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0, 0]\noccupied_thresh: 0.65\n"
                                     "free_thresh: 0.2\n")
    with pytest.raises(GslamError, match=r"m\.pgm: not a binary PGM"):
        read_map(tmp_path / "m.yaml")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: 0.1\norigin: [0, 0]\n")
    with pytest.raises(GslamError, match=r"m\.yaml: missing key 'occupied_thresh'"):
        read_map(tmp_path / "m.yaml")
