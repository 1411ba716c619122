"""The loop observer: is a loop closure consistent with the dead-reckoning
chain, and with the other loops? Then LOOP as a component of the diagnosis.

**Chain check** (Kimera-RPGO's "odometry check"). A loop from keyframe i to
j disagrees with the chain by ``W`` (slam.loops.chain.world_discrepancy);
under the chain's linearised error model ``W`` is zero-mean with covariance
``S(i, j) + N`` (the chain's steps in (i, j] plus the loop's own noise). The
loop passes when ``W^T (S + N)^-1 W`` is within the chi-square quantile at
``chain_probability`` (3 dof; 2 for a position-only loop, tested on its
position).

**Pairwise consistency** (PCM, Mangelson et al., ICRA 2018). Two loops a
(i -> j) and b (k -> l) with the chain between them form a cycle; its
residual is ``W_a - W_b``, whose chain part is the sum over the steps in one
interval but not the other (the shared drift cancels), so its covariance is
``S(a) + S(b) - 2 S(a and b) + N_a + N_b``. A pair is consistent when the
normalised residual is within the quantile at ``pcm_probability``. Position-
only loops cannot close a cycle (their yaw is unknown): such a pair is tested
jointly against the chain (4 dof, shared steps correlated). The loops kept
are a maximum clique of the consistency graph (validation.loop_cliques).
PCM looks at the whole run at once (offline); the chain check is causal.

**LOOP in the diagnosis.** With validation on, each validation step gets a
unary observation ``loop_consistency`` of component LOOP: implausible when a
loop found in the step was rejected by the observer, plausible when its
loops were kept. The model's diagnosis and the gate (hold-off included) turn
that into a decision for the ``loop`` factors of each step: loops of a step
where LOOP is excluded are rejected as ``gated``. LOOP has no relation to
another component, so its diagnosis composes with the sensors' (a product of
independent parts) and is run on its own. In oracle mode a loop is kept when
it agrees with ground truth.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import math

import numpy as np

from slam.loops.chain import Chain, J, world_covariance, world_discrepancy
from slam.loops.config import ObserverConfig
from slam.loops.constraints import LoopConstraint
from validation.loop_cliques import maximum_clique

LOOP_COMPONENT = "LOOP"
LOOP_CHECK = "loop_consistency"
WEAK_VARIANCE = 1e6
"""Variance given to a direction a loop does not measure."""


@dataclass
class LoopVerdict:
    """The decision on one loop: ``accepted``, else ``reason`` is ``chain``
    (inconsistent with the chain), ``pcm`` (outside the largest consistent
    set), ``gated`` (LOOP excluded by the diagnosis at its step) or
    ``oracle`` (wrong against ground truth). ``chain_chi2``: its normalised
    disagreement with the chain."""

    loop: LoopConstraint
    accepted: bool
    reason: str
    chain_chi2: float


@dataclass
class LoopObservation:
    """The observer's verdicts (in the order of the loops) and bookkeeping;
    ``inflation``: per loop id, the sigma multiplier gating gave an inflated
    loop."""

    verdicts: list[LoopVerdict]
    clique_size: int = 0
    clique_proven: bool = True
    time_s: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)
    inflation: dict[int, float] = field(default_factory=dict)

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


def _position_only(loop: LoopConstraint) -> bool:
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
    pos = np.array([_position_only(lp) for lp in loops])
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


def chain_check(chain: Chain, loops: list[LoopConstraint]) -> np.ndarray:
    """Normalised disagreement (chi-square) of each loop with the chain."""
    if not loops:
        return np.zeros(0)
    i, j, w, n, proj, pos = _measured(chain, loops)
    s = chain.covariance(i, j)
    m = np.einsum("nij,nj->ni", proj, w)
    cov = proj @ s @ np.transpose(proj, (0, 2, 1)) + n
    return _chi2_of(m, cov, np.where(pos, 2, 3))


def pairwise_consistency(chain: Chain, loops: list[LoopConstraint], probability: float) -> np.ndarray:
    """Boolean (n, n): loops a and b are consistent with each other (see the
    module docstring); the diagonal is True."""
    k = len(loops)
    if k == 0:
        return np.zeros((0, 0), dtype=bool)
    i, j, w, n, proj, pos = _measured(chain, loops)
    a, b = np.triu_indices(k, 1)
    s_a, s_b = chain.covariance(i[a], j[a]), chain.covariance(i[b], j[b])
    lo, hi = np.maximum(i[a], i[b]), np.minimum(j[a], j[b])
    s_ab = np.where((hi > lo)[:, None, None], chain.covariance(lo, np.maximum(hi, lo)), 0.0)
    ok = np.zeros(len(a), dtype=bool)
    both_pose = ~pos[a] & ~pos[b]
    if both_pose.any():
        m = both_pose
        r = w[a[m]] - w[b[m]]
        cov = s_a[m] + s_b[m] - 2.0 * s_ab[m] + n[a[m]] + n[b[m]]
        ok[m] = _chi2_of(r, cov, np.full(m.sum(), 3)) <= chi2_quantile(probability, 3)
    other = ~both_pose
    if other.any():
        # Joint test of what each loop measures, correlated through shared steps.
        m = other
        pa, pb = proj[a[m]], proj[b[m]]
        ma = np.einsum("nij,nj->ni", pa, w[a[m]])
        mb = np.einsum("nij,nj->ni", pb, w[b[m]])
        caa = pa @ s_a[m] @ np.transpose(pa, (0, 2, 1)) + n[a[m]]
        cbb = pb @ s_b[m] @ np.transpose(pb, (0, 2, 1)) + n[b[m]]
        cab = pa @ s_ab[m] @ np.transpose(pb, (0, 2, 1))
        da = np.where(pos[a[m]], 2, 3)
        db = np.where(pos[b[m]], 2, 3)
        values = np.empty(m.sum())
        for idx in range(m.sum()):
            x, y = da[idx], db[idx]
            r = np.concatenate([ma[idx, :x], mb[idx, :y]])
            c = np.block([[caa[idx, :x, :x], cab[idx, :x, :y]], [cab[idx, :x, :y].T, cbb[idx, :y, :y]]])
            values[idx] = r @ np.linalg.solve(c, r) - chi2_quantile(probability, int(x + y))
        ok[m] = values <= 0.0
    out = np.eye(k, dtype=bool)
    out[a, b] = ok
    out[b, a] = ok
    return out


def observe_loops(chain: Chain, loops: list[LoopConstraint], config: ObserverConfig) -> LoopObservation:
    """Chain check, then the largest pairwise-consistent set; see the module docstring."""
    start = time.perf_counter()
    chi = chain_check(chain, loops)
    dof = np.array([2 if _position_only(lp) else 3 for lp in loops])
    passed = np.ones(len(loops), dtype=bool)
    if config.chain_check and len(loops):
        passed = chi <= np.array([chi2_quantile(config.chain_probability, int(d)) for d in dof])
    kept = passed.copy()
    clique_size, proven = int(passed.sum()), True
    if config.pcm and passed.sum() > 1:
        idx = np.flatnonzero(passed)
        adjacency = pairwise_consistency(chain, [loops[k] for k in idx], config.pcm_probability)
        clique, proven = maximum_clique(adjacency, config.max_clique_steps)
        kept = np.zeros(len(loops), dtype=bool)
        kept[idx[clique]] = True
        clique_size = len(clique)
    verdicts = []
    for k, lp in enumerate(loops):
        reason = "" if kept[k] else ("chain" if not passed[k] else "pcm")
        verdicts.append(LoopVerdict(lp, bool(kept[k]), reason, round(float(chi[k]), 3)))
    obs = LoopObservation(verdicts, clique_size, proven, time.perf_counter() - start)
    obs.counts = count_reasons(verdicts)
    return obs


def count_reasons(verdicts: list[LoopVerdict]) -> dict[str, int]:
    out = {"found": len(verdicts), "accepted": sum(v.accepted for v in verdicts)}
    for v in verdicts:
        if not v.accepted:
            out[f"rejected_{v.reason}"] = out.get(f"rejected_{v.reason}", 0) + 1
    return out


# --- LOOP in the diagnosis and the gate -----------------------------------


@dataclass
class LoopGating:
    """Per validation step: the LOOP observation, its diagnosis and the
    ``loop`` factors' decision, and the loops found in the step (for the
    log)."""

    observations: list[str]
    diagnoses: list[str]
    decisions: list[str]
    step_loops: list[str]

    def columns(self) -> dict[str, list]:
        return {
            LOOP_CHECK: self.observations,
            "loop_diagnosis": self.diagnoses,
            "gate.loop": self.decisions,
            "loops": self.step_loops,
        }


def check_model(model) -> None:
    """Loops under validation need LOOP and its check in the model."""
    from validation.errors import ValidationError

    if model is None or LOOP_COMPONENT not in model.components or model.unary_checks.get(LOOP_CHECK) != LOOP_COMPONENT:
        raise ValidationError(
            f"validation.model: loop closing with validation on needs a component {LOOP_COMPONENT} "
            f"and a unary check '{LOOP_CHECK}: {LOOP_COMPONENT}'"
        )
    for name, pair in model.relations.items():
        if LOOP_COMPONENT in pair:
            raise ValidationError(f"validation.model: relation '{name}': {LOOP_COMPONENT} takes no relations, only its check")


def _step_of(step_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The validation step (t_{k-1}, t_k] each time falls in."""
    return np.clip(np.searchsorted(step_t, t, side="left"), 0, len(step_t) - 1)


def gate_loops(obs: LoopObservation, step_t: np.ndarray, keyframe_t: np.ndarray, model, gating) -> LoopGating:
    """Diagnose LOOP per validation step from the observer's verdicts and
    gate the loops (see the module docstring); updates ``obs`` in place."""
    from validation.diagnosis import Diagnoser
    from validation.gating import Gate, GatingAction
    from validation.model import Plausibility

    check_model(model)
    steps = _step_of(step_t, keyframe_t[[v.loop.j for v in obs.verdicts]]) if obs.verdicts else np.zeros(0, int)
    by_step: dict[int, list[LoopVerdict]] = {}
    for k, v in zip(steps, obs.verdicts):
        by_step.setdefault(int(k), []).append(v)
    loop_gating = gating.model_copy(update={"factors": {"loop": [LOOP_COMPONENT]}})
    gate = Gate(loop_gating, model)
    diagnoser = Diagnoser(model)
    out = LoopGating([], [], [], [])
    for k, t in enumerate(step_t):
        here = by_step.get(k, [])
        value = None
        if here:
            value = Plausibility.IMPLAUSIBLE if any(not v.accepted for v in here) else Plausibility.PLAUSIBLE
        result = diagnoser.diagnose({LOOP_CHECK: value})
        decision = gate.step(float(t), result)["loop"]
        for v in here:
            if v.accepted and decision.action is GatingAction.EXCLUDE:
                v.accepted, v.reason = False, "gated"
            elif v.accepted and decision.action is GatingAction.INFLATE:
                obs.inflation[v.loop.id] = decision.sigma_scale
        out.observations.append("" if value is None else value.value)
        out.diagnoses.append(" | ".join("{" + ",".join(sorted(d)) + "}" for d in result.diagnoses) if result.consistent else "none")
        out.decisions.append(decision.action.value)
        out.step_loops.append(" ".join(f"{v.loop.id}:{'accepted' if v.accepted else 'rejected(' + v.reason + ')'}" for v in here))
    diagnoser.close()
    obs.counts = count_reasons(obs.verdicts)
    return out


def oracle_loops(obs: LoopObservation, truth: np.ndarray, max_trans_m: float, max_yaw_rad: float) -> None:
    """Keep exactly the loops that agree with ground truth (``truth``: the
    true keyframe poses (K, 3)), within ``max_trans_m`` and ``max_yaw_rad``
    (position only for a position-only loop); updates ``obs`` in place."""
    for v in obs.verdicts:
        v.accepted, v.reason = loop_is_true(v.loop, truth, max_trans_m, max_yaw_rad), ""
        if not v.accepted:
            v.reason = "oracle"
    obs.counts = count_reasons(obs.verdicts)


def loop_is_true(loop: LoopConstraint, truth: np.ndarray, max_trans_m: float, max_yaw_rad: float) -> bool:
    """Whether ``loop`` agrees with the true keyframe poses (K, 3)."""
    from slam.loops.chain import between

    if _position_only(loop):
        return bool(np.hypot(*(truth[loop.i, :2] - truth[loop.j, :2])) <= max_trans_m)
    err = between(between(truth[loop.i], truth[loop.j]), loop.delta)
    return bool(np.hypot(err[0], err[1]) <= max_trans_m and abs(err[2]) <= max_yaw_rad)
