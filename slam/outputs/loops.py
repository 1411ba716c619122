"""What a result says of its loops and submaps: ``loops.csv`` and the
``loops`` and ``submaps`` sections of ``metrics.json``."""

from __future__ import annotations

import csv
import io
from typing import Any

import numpy as np

from slam.config import EvaluationConfig


def loops_csv(observation, t: np.ndarray) -> str:
    """One row per loop: where, what, how well verified, and the decision;
    ``t``: the keyframes' times."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["id", "i", "j", "t_i", "t_j", "source", "dx_m", "dy_m", "dyaw_deg", "quality", "chain_chi2", "decision",
                "reason", "free"])
    for v in observation.verdicts:
        lp = v.loop
        quality = " ".join(f"{k}={val}" for k, val in lp.quality.items())
        w.writerow([
            lp.id, lp.i, lp.j, round(float(t[lp.i]), 4), round(float(t[lp.j]), 4), lp.source,
            round(float(lp.delta[0]), 4), round(float(lp.delta[1]), 4), round(float(np.degrees(lp.delta[2])), 3),
            quality, v.chain_chi2, "accepted" if v.accepted else "rejected", v.reason, free_directions(lp.information),
        ])
    return buf.getvalue()


def free_directions(information: np.ndarray) -> str:
    """The directions (x y yaw, unit vectors in the frame of the loop's later
    keyframe, ``;``-separated) a loop's information leaves free; empty when
    it pins all three."""
    values, vectors = np.linalg.eigh(0.5 * (information + information.T))
    free = vectors[:, values <= 1e-9 * max(values.max(), 1e-300)]
    return ";".join(" ".join(f"{c:.4f}" for c in v) for v in free.T)


def loop_metrics(search, observation, truth: np.ndarray | None, evaluation: EvaluationConfig) -> dict[str, Any]:
    """Counts of loops by decision, detection's work, and, with the
    keyframes' true poses ``truth``, how many kept loops are wrong and
    rejected ones right."""
    obs = observation
    out: dict[str, Any] = {"source": search.source, **obs.counts}
    det = search.detection
    if det is not None:
        out.update(places=len(det.places), candidates=det.candidates, registrations=det.registrations)
        out["verification_rejected"] = dict(sorted(det.rejected.items()))
    out["clique_proven"] = obs.clique_proven
    out["chain_scale"] = round(obs.chain_scale, 3)
    if truth is not None:
        from validation.loops.gating import loop_is_true

        ev = evaluation
        ok = [loop_is_true(v.loop, truth, ev.sm_fault_trans_m, np.radians(ev.sm_fault_yaw_deg)) for v in obs.verdicts]
        out["true_found"] = int(sum(ok))
        out["wrong_accepted"] = int(sum(1 for v, good in zip(obs.verdicts, ok) if v.accepted and not good))
        out["true_rejected"] = int(sum(1 for v, good in zip(obs.verdicts, ok) if not v.accepted and good))
    return out


def submap_metrics(submaps, truth: np.ndarray | None, evaluation: EvaluationConfig) -> dict[str, Any]:
    """Submaps, searches and constraints by kind; with the keyframes' true
    poses ``truth``, how many kept and dropped constraints are wrong (as
    for loops)."""
    res = submaps
    out: dict[str, Any] = {"submaps": len(res.local.submaps), "nodes": len(res.nodes), "searches": res.searches}
    kinds = ("intra", "near", "loop")
    out["kept"] = {k: len(res.of_kind(k)) for k in kinds}
    out["dropped"] = {k: sum(c.kind == k for c in res.dropped) for k in kinds}
    if truth is not None:
        from validation.base.geometry import between
        from validation.loops.gating import pinned_error

        ev = evaluation

        def wrong(c) -> bool:
            e = pinned_error(c.information, between(between(truth[c.anchor], truth[c.scan]), c.delta))
            return bool(np.hypot(e[0], e[1]) > ev.sm_fault_trans_m or abs(e[2]) > np.radians(ev.sm_fault_yaw_deg))

        out["wrong_kept"] = {k: sum(wrong(c) for c in res.of_kind(k)) for k in kinds}
        out["wrong_dropped"] = {k: sum(wrong(c) for c in res.dropped if c.kind == k) for k in kinds}
    return out
