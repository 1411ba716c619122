"""Whether a scenario's route can be driven. The simulator plans the
motion without looking at the world, so it would drive through whatever
stands on the route; this check says so before anything is simulated:

* a waypoint inside an obstacle: an error naming both (the robot would
  stand inside it);
* a leg that crosses a wall or an obstacle (doors are gaps): a warning
  naming the waypoints and the wall, since the run can still be simulated
  (the shipped ``hall_clean`` crosses a container on one leg).
* waypoints that are all one point: a warning naming the key, since a robot
  standing still still makes a bag (of its sensors at rest) that maps.

Legs are the straight lines between consecutive waypoints (and, for more
than one lap, from the last waypoint back to the second); corners are
turned on arcs a little inside them, which the check does not follow.
"""

from __future__ import annotations

import logging

import numpy as np

from slam.errors import GslamError
from slam.sim.scenario import Scenario
from slam.sim.world import _cut_doors, point_in_polygon

log = logging.getLogger(__name__)

_EPS = 1e-9


def _labelled_segments(scenario: Scenario) -> list[tuple[str, np.ndarray]]:
    """Every wall and obstacle segment (2, 2) with the key that made it,
    doors cut out."""
    world = scenario.world
    out: list[tuple[str, np.ndarray]] = []
    for kind, shapes, closed in (("walls", world.walls, False), ("obstacles", world.obstacles, True)):
        for k, shape in enumerate(shapes):
            p = np.asarray(shape, dtype=float)
            if closed:
                p = np.vstack([p, p[:1]])
            segs = [p[i : i + 2] for i in range(len(p) - 1) if np.hypot(*(p[i + 1] - p[i])) > _EPS]
            out += [(f"world.{kind}.{k}", s) for s in _cut_doors(segs, world.doors)]
    return out


def _crossing(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray | None:
    """Where segment ab properly crosses segment cd (not merely touching an
    end), or None."""
    r, s = b - a, d - c
    denom = r[0] * s[1] - r[1] * s[0]
    if abs(denom) < _EPS:
        return None
    q = c - a
    t = (q[0] * s[1] - q[1] * s[0]) / denom
    u = (q[0] * r[1] - q[1] * r[0]) / denom
    if 1e-6 < t < 1 - 1e-6 and 1e-6 < u < 1 - 1e-6:
        return a + t * r
    return None


def legs(scenario: Scenario) -> list[tuple[int, int]]:
    """The waypoint index pairs the robot drives between."""
    n, laps = len(scenario.robot.waypoints), scenario.robot.laps
    pairs = [(i, i + 1) for i in range(n - 1)]
    if laps > 1 and n > 2:
        pairs.append((n - 1, 1))
    return pairs


def check_route(scenario: Scenario, source: str) -> None:
    """See the module docstring: errors and warnings name ``source``."""
    pts = np.array([w[:2] for w in scenario.robot.waypoints], dtype=float)
    for k, poly in enumerate(scenario.world.obstacles):
        inside = point_in_polygon(pts, np.asarray(poly, dtype=float))
        if inside.any():
            i = int(np.flatnonzero(inside)[0])
            raise GslamError(f"{source}: robot.waypoints.{i} ({pts[i, 0]:g}, {pts[i, 1]:g}) lies inside "
                             f"world.obstacles.{k}; move it out")
    if np.all(pts == pts[0]):
        log.warning("%s: robot.waypoints are all (%g, %g): the simulated robot stands still for the whole run",
                    source, pts[0, 0], pts[0, 1])
        return
    segments = _labelled_segments(scenario)
    for i, j in legs(scenario):
        for key, seg in segments:
            hit = _crossing(pts[i], pts[j], seg[0], seg[1])
            if hit is not None:
                log.warning("%s: the leg from robot.waypoints.%d to robot.waypoints.%d crosses %s at (%.3g, %.3g): "
                            "the simulated robot drives through it (add a waypoint around it, or a door)",
                            source, i, j, key, hit[0], hit[1])
                break
