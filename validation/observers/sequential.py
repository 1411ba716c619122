"""Sequential relation observers: a CUSUM on a relation's windowed residual.

A residual relation (:mod:`validation.observers.quantitative`) judges each step on its
own: ``|z| > k_sigma`` with ``z`` the normalised residual of the two streams'
changes over a window. An error smaller than ``k_sigma`` sds, but standing
(a scale a few percent off, a heading that creeps), never crosses it. A
*cusum* relation (``RelationConfig.kind: cusum``) accumulates the same ``z``
instead, in Page's two-sided cumulative sum:

    S+ = max(0, S+ + z - drift),   S- = max(0, S- - z - drift),

and the step is a mismatch while ``max(S+, S-) > k_sigma`` (the decision
limit ``h``, in sds). ``drift`` (``cusum_drift``, sds per step) is what the
sums forget each step: noise averages below it and is forgotten, an error
of ``e`` sds above it adds ``e - drift`` a step and is seen after about
``h / (e - drift)`` steps, however small ``e`` is. A short pass of large
residuals fills the sum in a few steps, as the residual test would see it;
a standing one fills it slowly, which the residual test never does. Each
sum is capped at twice the limit (as ``max_counter`` caps Algorithm 3's
counter), so a long error is let go about ``h / drift`` steps after it
ends, not as many steps as it lasted. The sums start at zero and start again after every step without a valid
residual (a gap, a window cut short). The mismatches feed Algorithm 3 like
the residual relation's.
"""

from __future__ import annotations

import numpy as np


class Cusum:
    """Page's two-sided CUSUM, one step at a time (module docstring)."""

    def __init__(self, drift: float, limit: float) -> None:
        self.drift = drift
        self.limit = limit
        self.up = 0.0
        self.down = 0.0

    def reset(self) -> None:
        self.up = self.down = 0.0

    def update(self, z: float | None) -> tuple[float, bool]:
        """``(statistic, mismatch)`` after the step with normalised residual
        ``z``; None (no valid residual) starts the sums again."""
        if z is None or not np.isfinite(z):
            self.reset()
            return 0.0, False
        cap = 2.0 * self.limit
        self.up = min(cap, max(0.0, self.up + z - self.drift))
        self.down = min(cap, max(0.0, self.down - z - self.drift))
        stat = max(self.up, self.down)
        return stat, stat > self.limit


def cusum(z: np.ndarray, valid: np.ndarray, drift: float, limit: float) -> tuple[np.ndarray, np.ndarray]:
    """``(statistic, mismatch)`` of :class:`Cusum` over every step; steps
    where ``valid`` is False start the sums again and are no mismatch."""
    test = Cusum(drift, limit)
    stat = np.zeros(len(z))
    mismatch = np.zeros(len(z), dtype=bool)
    for k in range(len(z)):
        stat[k], mismatch[k] = test.update(float(z[k]) if valid[k] else None)
    return stat, mismatch
