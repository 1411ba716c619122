"""Consistency-based diagnosis (Reiter) of the validation model with a SAT solver.

SD (see :mod:`validation.diagnosis.model`) is encoded once as CNF over the variables
ok(S), match(r) and plausible(k). Each *assumable* gets a selector literal:
``¬AB(S)`` for every component and ``CORR(match(r))`` for every failure-masking
rule with ``corr: true``. A set of retracted assumables is a diagnosis when
SD ∪ OBS ∪ {the remaining assumables} is satisfiable; OBS enters the solver as
assumption literals, so one incremental solver serves every time step.

All subset-minimal diagnoses are the minimal hitting sets of the minimal
conflicts (Reiter 1987). They are computed by the implicit hitting-set loop:
a hitting-set solver (PySAT's ``Hitman``, smallest sets first) proposes a
candidate; the SAT solver either accepts it (a diagnosis, blocked with all its
supersets) or returns an unsatisfiable core, shrunk to a minimal conflict and
added as a new set to hit. Because candidates come smallest first and every
diagnosis hits every conflict, each accepted candidate is subset-minimal.

CORR assumptions count as assumables, exactly like components: a diagnosis
may retract CORR(match(r)), i.e. declare the match of ``r`` coincidental, and
minimality is over components and retracted CORRs together. The result keeps
the full :class:`Explanation` s; ``DiagnosisResult.diagnoses`` are their
component parts, which gating acts on. Without CORR (``corr: false``) a match
always implies both components ok, and some observations have no diagnosis at
all; the result then says ``consistent=False`` and names the observations in
conflict instead of raising.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from pysat.examples.hitman import Hitman
from pysat.formula import IDPool
from pysat.solvers import Solver

from validation.diagnosis.model import Observation, Plausibility, SystemModel
from validation.base.errors import ValidationError

log = logging.getLogger(__name__)

ObservationValue = Observation | Plausibility


def corr_name(relation: str) -> str:
    """Name of the assumable CORR(match(relation)) in conflicts and explanations."""
    return f"CORR({relation})"


def trust_name(observer: str) -> str:
    """Name of the assumable TRUST(observer) of a relation or unary check that may raise a false alarm."""
    return f"TRUST({observer})"


@dataclass(frozen=True)
class Explanation:
    """One subset-minimal diagnosis over all assumables.

    ``components``: components assumed abnormal; ``masked``: relations whose
    CORR assumption is retracted (their match is coincidental);
    ``probability``: its prior probability under independent faults;
    ``dismissed``: relations and unary checks whose verdict is taken for a
    false alarm.
    """

    components: frozenset[str]
    masked: frozenset[str]
    probability: float
    dismissed: frozenset[str] = frozenset()


@dataclass(frozen=True)
class DiagnosisResult:
    """The diagnoses of one observation pattern.

    ``diagnoses``: the component sets of the minimal explanations, most
    probable first (then smaller, then by name); ``()`` when ``consistent`` is
    False, ``(frozenset(),)`` when nothing is wrong. ``probabilities`` align
    with ``diagnoses``. ``conflicts``: the minimal conflicts (sets of
    assumable names) found on the way. ``conflicting_observations``: when no
    diagnosis exists, a minimal set of observations that SD cannot explain
    even with every assumable retracted.
    """

    observations: frozenset[tuple[str, ObservationValue]]
    diagnoses: tuple[frozenset[str], ...]
    probabilities: tuple[float, ...]
    explanations: tuple[Explanation, ...]
    consistent: bool
    conflicts: tuple[frozenset[str], ...]
    conflicting_observations: frozenset[str] = frozenset()

    @property
    def ambiguous(self) -> bool:
        """More than one minimal diagnosis."""
        return len(self.diagnoses) > 1

    @property
    def minimum_cardinality(self) -> tuple[frozenset[str], ...]:
        """The diagnoses with the fewest components (in ranking order)."""
        if not self.diagnoses:
            return ()
        least = min(len(d) for d in self.diagnoses)
        return tuple(d for d in self.diagnoses if len(d) == least)


class Diagnoser:
    """Computes all minimal diagnoses of a :class:`SystemModel`, memoised per
    observation pattern (the pattern repeats over many time steps)."""

    def __init__(self, model: SystemModel, solver: str = "glucose3", cache_size: int = 65536) -> None:
        self.model = model
        self._cache: dict[frozenset[tuple[str, ObservationValue]], DiagnosisResult] = {}
        self._cache_size = cache_size
        self._pool = IDPool()
        self._solver = Solver(name=solver, bootstrap_with=self._encode())
        # Assumables in a fixed order: components, then retractable CORRs.
        self._assumables: dict[str, int] = {c: self._var("nab", c) for c in model.components}
        self._masking_prob: dict[str, float] = {}
        for rule in model.failure_masking:
            if rule.corr:
                self._assumables[corr_name(rule.relation)] = self._var("corr", rule.relation)
                self._masking_prob[rule.relation] = rule.masking_prob
        for observer in model.false_alarm:
            self._assumables[trust_name(observer)] = self._var("trust", observer)
        self._name_of = {lit: name for name, lit in self._assumables.items()}

    def _var(self, kind: str, name: str) -> int:
        return self._pool.id((kind, name))

    def _encode(self) -> list[list[int]]:
        """SD as CNF clauses."""
        m, v = self.model, self._var
        cnf = []
        for c in m.components:
            sensor = m.sensor_of(c)
            cnf.append([-v("nab", c), v("ok", c)] if sensor is None else [-v("nab", c), -v("nab", sensor), v("ok", c)])
        for r, (a, b) in m.relations.items():
            trust = [-v("trust", r)] if r in m.false_alarm else []
            cnf.append([-v("ok", a), -v("ok", b), *trust, v("match", r)])
        for k, c in m.unary_checks.items():
            trust = [-v("trust", k)] if k in m.false_alarm else []
            cnf.append([-v("ok", c), *trust, v("plausible", k)])
        for a, b in m.fault_propagation:
            cnf += [[-v("ok", a), v("ok", b)], [-v("ok", b), v("ok", a)]]
        for rule in m.failure_masking:
            a, b = m.relations[rule.relation]
            guard = [-v("corr", rule.relation)] if rule.corr else []
            match = v("match", rule.relation)
            cnf += [guard + [-match, v("ok", a)], guard + [-match, v("ok", b)]]
        return cnf

    def _observation_literals(self, observations: Mapping[str, ObservationValue]) -> dict[str, int]:
        lits = {}
        for name, value in observations.items():
            if name in self.model.relations and isinstance(value, Observation):
                lit = self._var("match", name)
                lits[name] = lit if value is Observation.MATCH else -lit
            elif name in self.model.unary_checks and isinstance(value, Plausibility):
                lit = self._var("plausible", name)
                lits[name] = lit if value is Plausibility.PLAUSIBLE else -lit
            elif name in self.model.relations or name in self.model.unary_checks:
                raise ValidationError(f"observation {name!r}: unexpected value {value!r}")
            else:
                raise ValidationError(
                    f"observation {name!r}: not a relation or unary check of the model "
                    f"(known: {', '.join(self.model.observables)})"
                )
        return lits

    def diagnose(self, observations: Mapping[str, ObservationValue | None]) -> DiagnosisResult:
        """All subset-minimal diagnoses of SD ∪ OBS.

        ``observations`` maps relation names to :class:`Observation` and unary
        check names to :class:`Plausibility`; unobserved ones are left out or
        None. The same pattern returns the same (cached) result object.
        """
        key = frozenset((n, v) for n, v in observations.items() if v is not None)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        result = self._diagnose(key, self._observation_literals(dict(key)))
        if len(self._cache) >= self._cache_size:
            self._cache.pop(next(iter(self._cache)))
        self._cache[key] = result
        return result

    def _diagnose(self, key: frozenset, obs_lits: dict[str, int]) -> DiagnosisResult:
        obs = list(obs_lits.values())
        # 1. Retracting every assumable must leave OBS explainable.
        if not self._solver.solve(assumptions=obs):
            core = set(self._solver.get_core() or obs)
            culprit = self._minimise(core, fixed=[])
            names = frozenset(n for n, lit in obs_lits.items() if lit in culprit)
            log.debug("no diagnosis: observations %s contradict SD", sorted(names))
            return DiagnosisResult(key, (), (), (), False, (), names)

        # 2. Implicit hitting sets: propose, check, learn a conflict or accept.
        conflicts: list[frozenset[str]] = []
        found: list[frozenset[str]] = []
        with Hitman(htype="sorted") as hitman:
            while True:
                candidate = hitman.get()
                if candidate is None:
                    break
                retracted = set(candidate)
                kept = [lit for name, lit in self._assumables.items() if name not in retracted]
                if self._solver.solve(assumptions=obs + kept):
                    found.append(frozenset(retracted))
                    if not retracted:
                        break  # the empty diagnosis is the only minimal one
                    hitman.block(candidate)
                    continue
                core = set(self._solver.get_core()) & set(kept)
                conflict = frozenset(self._name_of[lit] for lit in self._minimise(core, fixed=obs))
                conflicts.append(conflict)
                hitman.hit(sorted(conflict))
        log.debug("%d minimal diagnoses from %d conflicts", len(found), len(conflicts))
        return self._rank(key, found, conflicts)

    def _minimise(self, core: Iterable[int], fixed: list[int]) -> set[int]:
        """Deletion-based shrinking of an unsatisfiable core to a minimal one."""
        core = set(core)
        for lit in sorted(core, key=abs):
            if lit not in core:
                continue
            trial = core - {lit}
            if not self._solver.solve(assumptions=fixed + sorted(trial, key=abs)):
                core = trial & set(self._solver.get_core() or trial)
        return core

    def _rank(self, key: frozenset, found: list[frozenset[str]], conflicts: list[frozenset[str]]) -> DiagnosisResult:
        explanations = []
        for retracted in found:
            comps = frozenset(n for n in retracted if n in self.model.components)
            masked = frozenset(r for r in self._masking_prob if corr_name(r) in retracted)
            dismissed = frozenset(k for k in self.model.false_alarm if trust_name(k) in retracted)
            explanations.append(Explanation(comps, masked, self._probability(comps, masked, dismissed), dismissed))
        explanations.sort(
            key=lambda e: (-e.probability, len(e.components) + len(e.masked) + len(e.dismissed),
                           sorted(e.components), sorted(e.masked), sorted(e.dismissed))
        )
        diagnoses: list[frozenset[str]] = []
        probabilities: list[float] = []
        for e in explanations:
            if e.components not in diagnoses:
                diagnoses.append(e.components)
                probabilities.append(e.probability)
        return DiagnosisResult(
            key, tuple(diagnoses), tuple(probabilities), tuple(explanations), True, tuple(conflicts)
        )

    def _probability(self, components: frozenset[str], masked: frozenset[str],
                     dismissed: frozenset[str] = frozenset()) -> float:
        """prod p(S) over S in D times prod (1 - p(S)) over S not in D; the same
        for coincidental matches with ``masking_prob`` and for dismissed
        observers with ``false_alarm``. Computed in logs."""
        logp = 0.0
        for c in self.model.components:
            p = self.model.prior(c)
            logp += math.log(p) if c in components else math.log1p(-p)
        for r, p in self._masking_prob.items():
            logp += math.log(p) if r in masked else math.log1p(-p)
        for k, p in self.model.false_alarm.items():
            logp += math.log(p) if k in dismissed else math.log1p(-p)
        return math.exp(logp)

    def close(self) -> None:
        """Free the SAT solver."""
        self._solver.delete()

    def __enter__(self) -> "Diagnoser":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
