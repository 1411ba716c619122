"""The observers' per-step log: trends, counters and observations.

:class:`RelationTrace` holds one relation observer (Algorithm 3,
:mod:`validation.observers.relations`) over every validation step,
:class:`UnaryTrace` one unary check (:mod:`validation.observers.checks`), and
:class:`ObserverLog` all of them with the step times; it gives the
observations at one step (for diagnosis) and flat columns (for the CSV log).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from validation.diagnosis.model import Observation, Plausibility
from validation.observers.config import RelationConfig


@dataclass
class RelationTrace:
    """One relation observer over all steps (arrays of length m). A residual
    relation's ``symbol_a`` is 1 on a mismatch (``symbol_b`` 0) and ``z`` its
    normalised residual; a trend relation has no ``z`` and keeps its two
    slopes (``slope_a``, ``slope_b``: Algorithm 2's r1)."""

    relation: RelationConfig
    symbol_a: np.ndarray
    symbol_b: np.ndarray
    valid: np.ndarray
    counter: np.ndarray
    no_match: np.ndarray
    z: np.ndarray | None = None
    slope_a: np.ndarray | None = None
    slope_b: np.ndarray | None = None

    def compared(self) -> tuple[np.ndarray, np.ndarray]:
        """The symbols as Algorithm 3 compares them
        (:meth:`RelationConfig.compared`)."""
        if self.slope_a is None or self.slope_b is None:
            return self.symbol_a, self.symbol_b
        return self.symbol_a, self.relation.compared(self.symbol_a, self.symbol_b, self.slope_a, self.slope_b)

    def observation(self, k: int) -> Observation | None:
        if not self.valid[k]:
            return None
        return Observation.NO_MATCH if self.no_match[k] else Observation.MATCH


@dataclass
class UnaryTrace:
    """One unary check over all steps."""

    name: str
    component: str
    valid: np.ndarray
    deviant: np.ndarray
    implausible: np.ndarray

    def plausibility(self, k: int) -> Plausibility | None:
        if not self.valid[k]:
            return None
        return Plausibility.IMPLAUSIBLE if self.implausible[k] else Plausibility.PLAUSIBLE


@dataclass
class ObserverLog:
    """Per-step trends, counters and observations of every observer."""

    t: np.ndarray
    relations: dict[str, RelationTrace]
    unary: dict[str, UnaryTrace]

    def observations(self, k: int) -> dict[str, Observation | Plausibility]:
        """The observations made at step ``k`` (observers without data left out)."""
        out: dict[str, Observation | Plausibility] = {}
        for name, r in self.relations.items():
            if (obs := r.observation(k)) is not None:
                out[name] = obs
        for name, u in self.unary.items():
            if (p := u.plausibility(k)) is not None:
                out[name] = p
        return out

    def patterns(self) -> tuple[list[dict[str, Observation | Plausibility]], np.ndarray]:
        """The distinct observations over the steps, as :meth:`observations`
        gives them, and each step's index into that list: a run has a few
        dozen patterns over thousands of steps, and each is diagnosed once."""
        names: list[str] = []
        values: list[tuple[Observation, Observation] | tuple[Plausibility, Plausibility]] = []
        codes: list[np.ndarray] = []  # 0: no data, 1: the first value, 2: the second
        for name, r in self.relations.items():
            names.append(name)
            values.append((Observation.MATCH, Observation.NO_MATCH))
            codes.append(np.where(r.valid, np.where(r.no_match, 2, 1), 0))
        for name, u in self.unary.items():
            names.append(name)
            values.append((Plausibility.PLAUSIBLE, Plausibility.IMPLAUSIBLE))
            codes.append(np.where(u.valid, np.where(u.implausible, 2, 1), 0))
        if not codes:
            return [{}], np.zeros(len(self.t), dtype=np.intp)
        table = np.ascontiguousarray(np.stack(codes, axis=1), dtype=np.int8)
        rows = table.view(np.dtype((np.void, table.shape[1]))).ravel()  # a row as one value: a quick unique
        unique, index = np.unique(rows, return_inverse=True)
        unique = unique.view(np.int8).reshape(-1, table.shape[1])
        patterns = [{n: v[c - 1] for n, v, c in zip(names, values, row) if c} for row in unique.tolist()]
        return patterns, index.reshape(-1)

    def columns(self) -> dict[str, np.ndarray]:
        """Flat named columns (for the per-step CSV log)."""
        cols: dict[str, np.ndarray] = {"t": self.t}
        for name, r in self.relations.items():
            if r.z is not None:
                cols[f"{name}.z"] = np.round(np.where(r.valid, r.z, np.nan), 3)
            else:
                cols[f"{name}.trend_a"] = r.symbol_a
                cols[f"{name}.trend_b"] = r.symbol_b
            cols[f"{name}.valid"] = r.valid
            cols[f"{name}.counter"] = r.counter
            cols[f"{name}.no_match"] = r.no_match
        for name, u in self.unary.items():
            cols[f"{name}.valid"] = u.valid
            cols[f"{name}.implausible"] = u.implausible
        return cols
