"""Deliberately wrong loops, to test that validation rejects them.

Half of them copy a genuine loop's keyframes and shift its relative pose,
as perceptual aliasing does (the right place seen one door further on); the
other half join two keyframes far apart along the path, with the relative
pose the chain predicts for them, shifted. Shifts are 1-3 m in a random
direction and 3-15 deg of yaw, random sign: close enough to the chain's
prediction to look plausible. Every wrong loop claims the information of a
genuine one. Deterministic for a given ``seed``.
"""

from __future__ import annotations

import numpy as np

from slam.loops.chain import Chain
from validation.base.geometry import between, compose
from validation.loops.constraint import LoopConstraint


def wrong_loops(chain: Chain, genuine: list[LoopConstraint], count: int, seed: int, min_separation_m: float = 10.0) -> list[LoopConstraint]:
    """``count`` wrong loops (source ``injected``), numbered after ``genuine``."""
    rng = np.random.default_rng(seed)
    n = len(chain)
    out: list[LoopConstraint] = []
    next_id = max((lp.id for lp in genuine), default=-1) + 1
    for k in range(count):
        model = genuine[int(rng.integers(len(genuine)))] if genuine else None
        info = model.information if model is not None else np.diag([1e4, 1e4, 1e4])
        if k % 2 == 0 and model is not None:
            i, j, delta = model.i, model.j, model.delta
        else:
            for _ in range(1000):
                i, j = sorted(int(x) for x in rng.integers(0, n, 2))
                if chain.path_m[j] - chain.path_m[i] >= min_separation_m:
                    break
            delta = between(chain.poses[i], chain.poses[j])
        wrong = compose(np.asarray(delta, float), wrong_shift(rng))
        out.append(LoopConstraint(next_id + k, i, j, wrong, info.copy(), "injected"))
    return out


def wrong_shift(rng: np.random.Generator) -> np.ndarray:
    """A shift (x, y, yaw) that makes a loop wrong but plausible: 1-3 m in
    a random direction and 3-15 deg of yaw, random sign."""
    angle = rng.uniform(0.0, 2.0 * np.pi)
    shift = rng.uniform(1.0, 3.0) * np.array([np.cos(angle), np.sin(angle)])
    yaw = np.radians(rng.uniform(3.0, 15.0)) * rng.choice([-1.0, 1.0])
    return np.array([shift[0], shift[1], yaw])
