"""What the loop observer works on: a loop constraint between two
keyframes, and the observer's configuration."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import numpy as np
from pydantic import Field

from validation.base import bounds
from validation.base.yamlio import StrictFrozen


@dataclass
class LoopConstraint:
    """Keyframe ``j`` seen from keyframe ``i`` (i < j - 1).

    ``delta``: pose of j in the frame of i (x, y m; yaw rad).
    ``information`` (3, 3): of the error ``Log(delta^-1 * inverse(x_i) x_j)``
    (GTSAM's BetweenFactorPose2 convention: translation in the frame of j),
    possibly singular (a direction the loop does not pin).
    ``source``: ``scans`` (registration), ``file`` (listed by the
    recording) or ``injected`` (a deliberately wrong loop, for tests and
    benchmarks). ``quality``: the verification's figures (overlap, rms_m,
    weak_sigma_m, descriptor_distance), for the log.
    """

    id: int
    i: int
    j: int
    delta: np.ndarray
    information: np.ndarray
    source: str = "scans"
    quality: dict[str, float] = field(default_factory=dict)


class ObserverConfig(StrictFrozen):
    """The loop observer (validation.loops).

    ``chain_probability``: a loop is consistent with the dead-reckoning chain
    when its normalised disagreement is within the chi-square quantile (3
    dof) at this probability. ``pcm_probability``: the same for two loops
    around the cycle they form with the chain (pairwise consistency, PCM);
    the largest set of mutually consistent loops is kept.
    ``max_clique_steps``: work budget of the exact maximum-clique search
    (branch and bound; vertices coloured and tried, about a microsecond
    each); past it the best clique found so far is kept (at least a greedy
    one), and ``clique_proven`` is false in the metrics.
    ``chain_scale_from_loops``: inflate the chain's covariance until the
    median loop's disagreement is a median chi-square draw (the loops, most
    of them true, measure the chain's real drift; never deflated).
    ``min_support``: a kept loop needs this many other kept loops whose cycle
    with it spans at most ``support_path_m`` of chain (their pairwise test is
    strict there); 0 turns the requirement off (needs ``pcm``).
    """

    chain_check: bool = True
    chain_scale_from_loops: bool = True
    min_support: bounds.Count = Field(1, ge=0)
    support_path_m: Annotated[float, bounds.PATH_DELTA_M] = Field(20.0, gt=0.0)
    chain_probability: float = Field(0.999, gt=0.0, lt=1.0)
    pcm: bool = True
    pcm_probability: float = Field(0.99, gt=0.0, lt=1.0)
    max_clique_steps: Annotated[int, bounds.CLIQUE_STEPS] = Field(200_000, ge=1)
