"""The loop observer: is a loop closure consistent with the dead-reckoning
chain, and with the other loops?

**Chain check** (Kimera-RPGO's "odometry check"). A loop from keyframe i to
j disagrees with the chain by ``W`` (validation.loops.chain.world_discrepancy);
under the chain's linearised error model ``W`` is zero-mean with covariance
``S(i, j) + N`` (the chain's steps in (i, j] plus the loop's own noise). The
loop passes when ``W^T (S + N)^-1 W`` is within the chi-square quantile at
``chain_probability`` (3 dof; 2 for a position-only loop, tested on its
position).

A chain's sigmas come from its sensors' configured noise, and real drift is
often larger (biases, slip). With ``chain_scale_from_loops``, the chain's
covariance is first inflated by the factor that makes the median loop look
like a median chi-square draw (:func:`chain_scale`; never deflated): the
loops, most of them true, say how far the chain really drifts.

**Pairwise consistency** (PCM, Mangelson et al., ICRA 2018). Two loops a
(i -> j) and b (k -> l) with the chain between them form a cycle; its
residual is ``W_a - W_b``, whose chain part is the sum over the steps in one
interval but not the other (the shared drift cancels), so its covariance is
``S(a) + S(b) - 2 S(a and b) + N_a + N_b``. A pair is consistent when the
normalised residual is within the quantile at ``pcm_probability``. Position-
only loops cannot close a cycle (their yaw is unknown): such a pair is tested
jointly against the chain (4 dof, shared steps correlated). The loops kept
are a maximum clique of the consistency graph (validation.loops.cliques).
A pair whose cycle runs over a long stretch of chain is consistent almost
whatever its loops say; a pair over a short one (two loops of one revisit)
is a strict test. So a loop is kept only with at least ``min_support`` other
kept loops whose cycle with it has at most ``support_path_m`` of chain (as
Karto asks for a chain of matches before it closes a loop); a lone loop is
rejected as ``support``. PCM looks at the whole run at once (offline); the
chain check is causal.

LOOP in the diagnosis and the gate, and the oracle, are in
validation.loops.gating.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from validation.loops.chain import Chain, J, world_covariance, world_discrepancy
from validation.loops.cliques import maximum_clique
from validation.loops.constraint import LoopConstraint, ObserverConfig

WEAK_VARIANCE = 1e6
"""Variance given to a direction a loop does not measure."""


@dataclass
class LoopVerdict:
    """The decision on one loop: ``accepted``, else ``reason`` is ``chain``
    (inconsistent with the chain), ``pcm`` (outside the largest consistent
    set), ``support`` (no other kept loop close enough to check it),
    ``gated`` (LOOP excluded by the diagnosis at its step) or ``oracle``
    (wrong against ground truth). ``chain_chi2``: its normalised
    disagreement with the chain."""

    loop: LoopConstraint
    accepted: bool
    reason: str
    chain_chi2: float


@dataclass
class LoopObservation:
    """The observer's verdicts (in the order of the loops) and bookkeeping;
    ``inflation``: per loop id, the sigma multiplier gating gave an inflated
    loop; ``chain_scale``: the factor on the chain's sigmas the loops
    called for (:func:`chain_scale`)."""

    verdicts: list[LoopVerdict]
    clique_size: int = 0
    clique_proven: bool = True
    time_s: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)
    inflation: dict[int, float] = field(default_factory=dict)
    chain_scale: float = 1.0

    @property
    def accepted(self) -> list[LoopConstraint]:
        return [v.loop for v in self.verdicts if v.accepted]


def chi2_quantile(probability: float, dof: int) -> float:
    """Quantile of the chi-square distribution with ``dof`` (1..8) degrees
    of freedom, by bisection on its CDF (the regularised lower incomplete
    gamma function P(dof/2, x/2), by its recurrence from P(1/2) or P(1))."""

    def cdf(x: float) -> float:
        y = 0.5 * x
        if dof % 2:
            a, p = 0.5, math.erf(math.sqrt(y))
        else:
            a, p = 1.0, 1.0 - math.exp(-y)
        while a < 0.5 * dof:
            p -= math.exp(a * math.log(y) - y - math.lgamma(a + 1.0)) if y > 0 else 0.0
            a += 1.0
        return p

    lo, hi = 0.0, 1.0
    while cdf(hi) < probability:
        hi *= 2.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if cdf(mid) < probability else (lo, mid)
    return 0.5 * (lo + hi)


def position_only(loop: LoopConstraint) -> bool:
    return loop.information[2, 2] == 0.0 and not loop.information[2].any()


def _measured(chain: Chain, loops: list[LoopConstraint]):
    """Per loop: discrepancy W (n, 3) in the chain's error form, the
    projection P (n, 3, 3) onto what the loop measures (identity; for a
    position-only loop, the position of j in world axes, last row zero), and
    the loop's own noise N (n, 3, 3) in that measured space."""
    i = np.array([lp.i for lp in loops])
    j = np.array([lp.j for lp in loops])
    delta = np.array([lp.delta for lp in loops])
    info = np.array([lp.information for lp in loops])
    pos = np.array([position_only(lp) for lp in loops])
    w = world_discrepancy(chain, i, j, delta)
    n = world_covariance(chain, j, info, WEAK_VARIANCE)
    proj = np.repeat(np.eye(3)[None], len(loops), axis=0)
    lever = chain.lever(j) @ J.T  # J p_j
    proj[pos, :2, 2] = lever[pos]
    proj[pos, 2, :] = 0.0
    # A position-only loop's own noise, in world axes at j: sigma^2 I.
    if pos.any():
        c = np.cos(chain.poses[j[pos], 2])
        s = np.sin(chain.poses[j[pos], 2])
        inv_xy = info[pos, :2, :2]
        cov_local = np.linalg.inv(inv_xy)
        rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], 1)
        n_pos = np.zeros((pos.sum(), 3, 3))
        n_pos[:, :2, :2] = rot @ cov_local @ np.transpose(rot, (0, 2, 1))
        n[pos] = n_pos
    return i, j, w, n, proj, pos


def _chi2_of(residual: np.ndarray, cov: np.ndarray, dof: np.ndarray) -> np.ndarray:
    """r^T C^-1 r over the first ``dof`` components (2 or 3) of each row."""
    out = np.empty(len(residual))
    for d in (2, 3):
        m = dof == d
        if m.any():
            r, c = residual[m, :d], cov[m, :d, :d]
            out[m] = np.einsum("ni,ni->n", r, np.linalg.solve(c, r[..., None])[..., 0])
    return out


def _chain_chi2(chain: Chain, measured, scale2: float) -> np.ndarray:
    i, j, w, n, proj, pos = measured
    s = scale2 * chain.covariance(i, j)
    m = np.einsum("nij,nj->ni", proj, w)
    cov = proj @ s @ np.transpose(proj, (0, 2, 1)) + n
    return _chi2_of(m, cov, np.where(pos, 2, 3))


def chain_check(chain: Chain, loops: list[LoopConstraint], scale2: float = 1.0) -> np.ndarray:
    """Normalised disagreement (chi-square) of each loop with the chain,
    whose covariance is multiplied by ``scale2``."""
    if not loops:
        return np.zeros(0)
    return _chain_chi2(chain, _measured(chain, loops), scale2)


def chain_scale(chain: Chain, loops: list[LoopConstraint], max_scale: float = 1e4) -> float:
    """How much larger (a variance factor, >= 1) the chain's covariance must
    be for the loops' disagreements to look as a chi-square sample should:
    the factor that brings the median of the loops' normalised disagreements
    (each over its own dof's median) to 1. A median is robust to a minority
    of false loops; the factor only ever inflates, so a chain that already
    explains its loops is left alone."""
    if len(loops) < 3:
        return 1.0
    measured = _measured(chain, loops)
    dof = np.where(measured[5], 2, 3)
    median = np.where(dof == 2, chi2_quantile(0.5, 2), chi2_quantile(0.5, 3))

    def excess(scale2: float) -> float:
        return float(np.median(_chain_chi2(chain, measured, scale2) / median)) - 1.0

    if excess(1.0) <= 0.0:
        return 1.0
    if excess(max_scale) > 0.0:
        return max_scale
    lo, hi = 0.0, np.log(max_scale)
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(float(np.exp(mid))) > 0.0 else (lo, mid)
    return float(np.exp(hi))


PAIRS_PER_CHUNK = 100_000
"""Pairs tested at once (bounds the memory of the pairwise test)."""


def pairwise_consistency(chain: Chain, loops: list[LoopConstraint], probability: float, scale2: float = 1.0) -> np.ndarray:
    """Boolean (n, n): loops a and b are consistent with each other (see the
    module docstring); the diagonal is True. ``scale2`` multiplies the
    chain's covariance."""
    k = len(loops)
    if k == 0:
        return np.zeros((0, 0), dtype=bool)
    measured = _measured(chain, loops)
    a, b = np.triu_indices(k, 1)
    ok = np.zeros(len(a), dtype=bool)
    for lo in range(0, len(a), PAIRS_PER_CHUNK):
        sl = slice(lo, lo + PAIRS_PER_CHUNK)
        ok[sl] = _pairs_consistent(chain, measured, a[sl], b[sl], probability, scale2)
    out = np.eye(k, dtype=bool)
    out[a, b] = ok
    out[b, a] = ok
    return out


def _pairs_consistent(chain: Chain, measured, a: np.ndarray, b: np.ndarray, probability: float, scale2: float) -> np.ndarray:
    """The pairwise test for the pairs of loops (a[k], b[k])."""
    i, j, w, n, proj, pos = measured
    s_a, s_b = scale2 * chain.covariance(i[a], j[a]), scale2 * chain.covariance(i[b], j[b])
    lo, hi = np.maximum(i[a], i[b]), np.minimum(j[a], j[b])
    s_ab = np.where((hi > lo)[:, None, None], scale2 * chain.covariance(lo, np.maximum(hi, lo)), 0.0)
    ok = np.zeros(len(a), dtype=bool)
    both_pose = ~pos[a] & ~pos[b]
    if both_pose.any():
        m = both_pose
        r = w[a[m]] - w[b[m]]
        cov = s_a[m] + s_b[m] - 2.0 * s_ab[m] + n[a[m]] + n[b[m]]
        ok[m] = _chi2_of(r, cov, np.full(m.sum(), 3)) <= chi2_quantile(probability, 3)
    # Otherwise a joint test of what each loop measures (2 components for a
    # position-only loop, 3 for a pose), correlated through shared steps.
    for pos_a, pos_b in ((True, True), (True, False), (False, True)):
        m = (pos[a] == pos_a) & (pos[b] == pos_b)
        if not m.any():
            continue
        da, db = (2 if pos_a else 3), (2 if pos_b else 3)
        pa, pb = proj[a[m]][:, :da], proj[b[m]][:, :db]
        ma = np.einsum("nij,nj->ni", pa, w[a[m]])
        mb = np.einsum("nij,nj->ni", pb, w[b[m]])
        caa = pa @ s_a[m] @ np.transpose(pa, (0, 2, 1)) + n[a[m]][:, :da, :da]
        cbb = pb @ s_b[m] @ np.transpose(pb, (0, 2, 1)) + n[b[m]][:, :db, :db]
        cab = pa @ s_ab[m] @ np.transpose(pb, (0, 2, 1))
        r = np.concatenate([ma, mb], axis=1)
        cov = np.concatenate([np.concatenate([caa, cab], axis=2), np.concatenate([np.transpose(cab, (0, 2, 1)), cbb], axis=2)], axis=1)
        value = np.einsum("ni,ni->n", r, np.linalg.solve(cov, r[..., None])[..., 0])
        ok[m] = value <= chi2_quantile(probability, da + db)
    return ok


def short_cycles(chain: Chain, loops: list[LoopConstraint], max_path_m: float) -> np.ndarray:
    """Boolean (n, n): the chain in the cycle of loops a and b (the steps in
    one interval but not the other) is at most ``max_path_m`` long, so their
    pairwise test is strict. The diagonal is True."""
    i = np.array([lp.i for lp in loops])
    j = np.array([lp.j for lp in loops])
    s = chain.path_m
    lo, hi = np.maximum(i[:, None], i[None]), np.minimum(j[:, None], j[None])
    shared = np.where(hi > lo, s[np.maximum(hi, lo)] - s[lo], 0.0)
    own = s[j] - s[i]
    return own[:, None] + own[None] - 2.0 * shared <= max_path_m


def observe_loops(chain: Chain, loops: list[LoopConstraint], config: ObserverConfig) -> LoopObservation:
    """Chain check, then the largest pairwise-consistent set; see the module docstring."""
    start = time.perf_counter()
    scale2 = chain_scale(chain, loops) if config.chain_scale_from_loops else 1.0
    chi = chain_check(chain, loops, scale2)
    dof = np.array([2 if position_only(lp) else 3 for lp in loops])
    passed = np.ones(len(loops), dtype=bool)
    if config.chain_check and len(loops):
        passed = chi <= np.array([chi2_quantile(config.chain_probability, int(d)) for d in dof])
    kept = passed.copy()
    supported = np.ones(len(loops), dtype=bool)
    clique_size, proven = int(passed.sum()), True
    if config.pcm and passed.sum() > 1:
        idx = np.flatnonzero(passed)
        chosen = [loops[k] for k in idx]
        adjacency = pairwise_consistency(chain, chosen, config.pcm_probability, scale2)
        clique, proven = maximum_clique(adjacency, config.max_clique_steps)
        kept = np.zeros(len(loops), dtype=bool)
        kept[idx[clique]] = True
        clique_size = len(clique)
        if config.min_support > 0:
            close = short_cycles(chain, [chosen[c] for c in clique], config.support_path_m)
            support = (close & adjacency[np.ix_(clique, clique)]).sum(axis=1) - 1
            supported[idx[clique]] = support >= config.min_support
    elif config.min_support > 0:
        supported[:] = False
    verdicts = []
    for k, lp in enumerate(loops):
        reason = "" if kept[k] and supported[k] else ("chain" if not passed[k] else "pcm" if not kept[k] else "support")
        verdicts.append(LoopVerdict(lp, bool(kept[k] and supported[k]), reason, round(float(chi[k]), 3)))
    obs = LoopObservation(verdicts, clique_size, proven, time.perf_counter() - start)
    obs.chain_scale = float(np.sqrt(scale2))
    obs.counts = count_reasons(verdicts)
    return obs


def count_reasons(verdicts: list[LoopVerdict]) -> dict[str, int]:
    out = {"found": len(verdicts), "accepted": sum(v.accepted for v in verdicts)}
    for v in verdicts:
        if not v.accepted:
            out[f"rejected_{v.reason}"] = out.get(f"rejected_{v.reason}", 0) + 1
    return out
