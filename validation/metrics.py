"""How well validation did against the true fault intervals.

The truth is ``faults``: for each component whose truth is known, its true
fault intervals (an empty list: known to be fault-free). A simulated run
knows every component; a BROAD trial the compass; a recording with ground
truth scan matching (``slam.gating.truth``); a plain bag none. A metric that needs
the truth of a component it cannot have is null (JSON ``null``), never 0:
without any truth, everything below but ``alarm_fraction`` is null.

Definitions (validation steps at ``validation.rate_hz``):

* ``alarm_fraction``: steps whose most probable diagnosis blames at least one
  component, or where no diagnosis exists, over all steps (oracle mode:
  steps where the gate acts on any factor).
* ``false_alarm_fraction``: alarm steps at which no component is inside a
  true fault interval, over all steps (equal to ``alarm_fraction`` on a
  fault-free run). Null unless the truth of every component ever blamed is
  known: an alarm about a sensor nobody labelled is neither true nor false.
* ``isolation_precision`` / ``isolation_recall``: per step, the blamed set
  is the most probable diagnosis (oracle: the gated components), the true
  set the components inside a fault interval at that time, both restricted
  to the components whose truth is known; summed over steps, precision =
  |blamed ∩ true| / |blamed|, recall = |blamed ∩ true| / |true|. Null where
  the denominator is 0 (nothing blamed, no fault).
* ``detection_delay_s``: per component with true faults, the mean over its
  fault intervals of the time from onset to the first step, within the
  interval, at which any minimal diagnosis contains the component (null for
  a component whose faults were all missed). ``faults_missed`` counts
  intervals never detected within their span, ``faults_detected`` those
  detected.
* ``blame_end_lag_s``: per component with detected faults, the mean over
  them of the time from the fault's end to the end of the blame (the run of
  steps blaming the component that holds the interval's last blamed step),
  or to the start of the component's next fault if the blame runs on into
  it; negative when the blame ends before the fault. Blame carried across a
  gap between two faults counts in full as false alarm.
* ``truth_components``: the components whose truth is known.

:func:`stretches_found` asks a coarser question of whole stretches (an
injected fault's span, whatever its labels): was any of its components
blamed (in the most probable diagnosis, the one the gating acts on) at any
step within it. :func:`stretch_precision` asks the converse: of the steps
with a blame, the share whose every blamed component was injected at that
step. The labels above mark only the steps an injected fault harmed (a cut
laser's scans that leave a direction free); a sensor blamed within its
injected stretch but outside those labels is faulty all the same.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from validation.diagnosis.reiter import DiagnosisResult
from validation.gating import Actions, GatingAction


def _inside(t: np.ndarray, intervals: Sequence[tuple[float, float]]) -> np.ndarray:
    mask = np.zeros(len(t), dtype=bool)
    for a, b in intervals:
        mask |= (t >= a) & (t <= b)
    return mask


def _blamed(
    results, actions: list[Actions], expand: Mapping[str, Sequence[str]]
) -> tuple[list[set[str]], list[set[str]], np.ndarray]:
    """Per step: the blamed set, the union of all minimal diagnoses, and
    whether the step is an alarm; a blamed sensor counts as all its
    modalities (``expand``)."""

    def parts(comps) -> set[str]:
        return {m for c in comps for m in expand.get(c, (c,))}

    if results is not None:
        # Steps with the same observations share one result: each is read once.
        seen: dict[int, tuple[set[str], set[str], bool]] = {}
        for r in results:
            if id(r) in seen:
                continue
            if r.consistent:
                seen[id(r)] = (parts(r.diagnoses[0]), parts(set().union(*r.diagnoses)), bool(r.diagnoses[0]))
            else:
                seen[id(r)] = (set(), set(), True)
        top, union, alarm = zip(*(seen[id(r)] for r in results)) if results else ((), (), ())
        return list(top), list(union), np.array(alarm, dtype=bool)
    gated = [parts(c for c, a in act.items() if a is not GatingAction.INCLUDE) for act in actions]
    return gated, gated, np.array([bool(c) for c in gated], dtype=bool)


def _blame_end_lag(
    step_t: np.ndarray, blamed: np.ndarray, a: float, b: float, next_start: float = np.inf
) -> float | None:
    """Time from the fault's end ``b`` to the end of the blame run holding the
    last blamed step within ``[a, b]``, at most to ``next_start`` (the next
    fault of the component); None when nothing in it is blamed."""
    inside = np.flatnonzero(blamed & (step_t >= a) & (step_t <= b))
    if not len(inside):
        return None
    k = inside[-1]
    while k + 1 < len(blamed) and blamed[k + 1] and step_t[k + 1] < next_start:
        k += 1
    return float(step_t[k] - b)


def validation_metrics(
    step_t: np.ndarray,
    results: list[DiagnosisResult] | None,
    actions: list[Actions],
    faults: Mapping[str, Sequence[tuple[float, float]]],
    expand: Mapping[str, Sequence[str]] | None = None,
) -> dict:
    """The metrics of the module docstring, JSON-ready; ``expand`` gives the
    modalities a blamed sensor stands for (the model's ``sensors``)."""
    top, union, alarm = _blamed(results, actions, expand or {})
    known = set(faults)
    blamed = [b & known for b in top]
    n = len(step_t)
    true_sets = [set() for _ in range(n)]
    for comp, intervals in faults.items():
        for k in np.flatnonzero(_inside(step_t, intervals)):
            true_sets[k].add(comp)
    tp = sum(len(b & s) for b, s in zip(blamed, true_sets))
    n_blamed = sum(len(b) for b in blamed)
    n_true = sum(len(s) for s in true_sets)

    delays: dict[str, float | None] = {}
    lags: dict[str, float | None] = {}
    missed = detected = 0
    for comp, intervals in faults.items():
        found, ends = [], []
        comp_blamed = np.array([comp in u for u in blamed], dtype=bool)
        comp_suspected = np.array([comp in u for u in union], dtype=bool)
        starts = sorted(a for a, _ in intervals)
        for a, b in intervals:
            next_start = min((s for s in starts if s > b), default=np.inf)
            hits = step_t[(step_t >= a) & (step_t <= b) & comp_suspected]
            if len(hits):
                found.append(hits[0] - a)
                detected += 1
                lag = _blame_end_lag(step_t, comp_blamed, a, b, next_start)
                if lag is not None:
                    ends.append(lag)
            elif np.any((step_t >= a) & (step_t <= b)):
                missed += 1
        if intervals:
            delays[comp] = round(float(np.mean(found)), 3) if found else None
            lags[comp] = round(float(np.mean(ends)), 3) if ends else None

    blamed_counts = {}
    for b in top:
        for c in b:
            blamed_counts[c] = blamed_counts.get(c, 0) + 1
    faulty = np.array([bool(s) for s in true_sets], dtype=bool)
    truth = bool(known) and n > 0
    judged = truth and set(blamed_counts) <= known
    return {
        "validation_steps": n,
        "alarm_fraction": round(float(alarm.mean()) if n else 0.0, 5),
        "false_alarm_fraction": round(float((alarm & ~faulty).mean()), 5) if judged else None,
        "isolation_precision": round(tp / n_blamed, 4) if n_blamed and truth else None,
        "isolation_recall": round(tp / n_true, 4) if n_true and truth else None,
        "detection_delay_s": delays if truth else None,
        "blame_end_lag_s": lags if truth else None,
        "faults_missed": missed if truth else None,
        "faults_detected": detected if truth else None,
        "truth_components": sorted(known),
        "blamed_steps": dict(sorted(blamed_counts.items())),
        "no_diagnosis_steps": int(sum(1 for r in results if not r.consistent)) if results is not None else 0,
    }


def stretches_found(
    step_t: np.ndarray,
    results: list[DiagnosisResult] | None,
    actions: list[Actions],
    stretches: Sequence[tuple[Sequence[str], float, float]],
    expand: Mapping[str, Sequence[str]] | None = None,
) -> int:
    """How many of ``stretches`` (components, start s, end s) had one of
    their components blamed (the most probable diagnosis; oracle: gated) at
    some step within them; a blamed sensor counts as all its modalities
    (``expand``)."""
    top, _, _ = _blamed(results, actions, expand or {})
    t = np.asarray(step_t, dtype=float)
    found = 0
    for comps, a, b in stretches:
        steps = np.flatnonzero((t >= a) & (t <= b))
        found += any(set(comps) & top[k] for k in steps)
    return found


def stretch_precision(
    step_t: np.ndarray,
    results: list[DiagnosisResult] | None,
    actions: list[Actions],
    stretches: Sequence[tuple[Sequence[str], float, float]],
    expand: Mapping[str, Sequence[str]] | None = None,
) -> tuple[int, int]:
    """(right, blamed): the steps whose most probable diagnosis blames some
    component (oracle: gated), and of those the ones where every blamed
    component (a sensor counting as all its modalities, ``expand``) lies in
    a stretch of ``stretches`` (components, start s, end s) holding that
    step. A step without a consistent diagnosis is not counted."""
    expand = expand or {}
    top, _, _ = _blamed(results, actions, expand)
    t = np.asarray(step_t, dtype=float)
    injected: list[set[str]] = [set() for _ in range(len(t))]
    for comps, a, b in stretches:
        parts = {m for c in comps for m in (c, *expand.get(c, ()))}
        for k in np.flatnonzero((t >= a) & (t <= b)):
            injected[k] |= parts
    blamed = [k for k, b in enumerate(top) if b]
    right = sum(1 for k in blamed if top[k] <= injected[k])
    return right, len(blamed)
