"""The true fault intervals ``gslam inject`` writes beside a recording."""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from slam.recording import Interval
from slam.recording import intervals_from_mask, union_intervals

MERGE_GAP_S = 0.5
"""Flagged samples closer than this are one interval, as the simulator merges them."""


class Labels:
    """Fault intervals per component, collected from flagged samples."""

    def __init__(self) -> None:
        self._spans: dict[str, list[Interval]] = defaultdict(list)

    def add(self, component: str, t: np.ndarray, mask: np.ndarray) -> None:
        """The runs of ``mask`` over sample times ``t`` (s) are faults of ``component``."""
        found = intervals_from_mask(np.asarray(t, float), np.asarray(mask, bool), MERGE_GAP_S, 0.0)
        self._spans[component] = union_intervals(self._spans[component], found)

    def intervals(self) -> dict[str, list[Interval]]:
        return {c: list(v) for c, v in self._spans.items()}
