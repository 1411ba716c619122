"""One gating policy per ``validation.mode``, chosen in one place.

Every step of a run that depends on the mode asks its policy
(:func:`gating_policy`); no other code compares the mode:

* :meth:`Gating.weigh`: the weight of every factor's degrees of freedom per
  keyframe (1 kept, > 1 inflated, inf excluded), with what the validator
  logged;
* :meth:`Gating.witnesses`: the sensors the pipeline makes for the
  validator to weigh (local SLAM's submap match, ``sub``);
* :attr:`Gating.learns_scale`: whether the odometry's distance scale is
  learnt where validation keeps the scan matcher (:mod:`slam.gating.odometry_scale`);
* :meth:`Gating.recheck`: offline validation's recheck of the blamed
  measurements (:mod:`slam.gating.recheck`);
* :meth:`Gating.gate_loops`: how the loops' verdicts are gated (LOOP in the
  diagnosis, or ground truth for the tight oracle).

The four policies: :class:`Ungated` (``off``), :class:`Validated` (``on``),
:class:`TightOracle` (``oracle``, from ground truth) and
:class:`IntervalOracle` (``interval_oracle``, from the true fault intervals).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from slam.config import PipelineConfig, validation_sections
from slam.errors import GslamError
from slam.graph.measurements import FACTOR_DOFS, SUBMAP_DOFS, Measurements
from slam.recording import Recording, Trajectory
from validation.base.modes import GatingMode

if TYPE_CHECKING:
    from validation.config import GatingConfig, ValidationConfig

log = logging.getLogger(__name__)


@dataclass
class Weighing:
    """What a policy decided for a run: the weights per factor type
    (keyframes, degrees of freedom), the validator's outcome where it ran,
    metrics, and ``validation.csv`` (text, or a function that writes it).
    ``submaps``: the weights of the submap constraints where
    ``gating.factors.submaps`` gates them apart from scan matching, else
    None (they take scan matching's)."""

    weights: dict[str, np.ndarray]
    validation: Any = None
    metrics: dict[str, Any] = field(default_factory=dict)
    csv: str | Callable[[], str] | None = None
    submaps: np.ndarray | None = None


class Gating:
    """The ungated policy, and the interface of every other."""

    mode = GatingMode.OFF
    learns_scale = False

    def __init__(self, config: PipelineConfig, validation: ValidationConfig, gating: GatingConfig):
        self.config, self.validation, self.gating = config, validation, gating

    def weigh(self, rec: Recording, scan_poses: Trajectory | None, meas: Measurements, source: Path,
              witnesses: dict[str, Trajectory] | None = None) -> Weighing:
        """``witnesses``: the sensors :meth:`witnesses` asked for, by name."""
        from slam.graph.backend import unit_weights

        return Weighing(unit_weights(len(meas)))

    def witnesses(self) -> list[str]:
        """The odometry-like sources the pipeline makes for this policy to
        weigh: ``sub`` where an observer compares one of its streams."""
        return []

    def recheck(self, meas: Measurements, weights: dict[str, np.ndarray], pose0: np.ndarray):
        """The recheck's result (:class:`slam.gating.recheck.Recheck`), or
        None where the policy does not recheck."""
        return None

    def gate_loops(self, obs, weighing: Weighing, keyframe_t: np.ndarray, truth: np.ndarray | None) -> None:
        """Gate the loops' verdicts ``obs`` in place."""


class Ungated(Gating):
    """``off``: every factor enters with its configured noise."""


class _ByValidator(Gating):
    """The policies whose weights the validator computes."""

    learns_scale = True

    def weigh(self, rec: Recording, scan_poses: Trajectory | None, meas: Measurements, source: Path,
              witnesses: dict[str, Trajectory] | None = None) -> Weighing:
        from validation.validator import run_validation

        sensors = with_witnesses(rec, witnesses or {})
        own = "submaps" in self.gating.factors
        dofs = {**FACTOR_DOFS, "submaps": SUBMAP_DOFS} if own else FACTOR_DOFS
        outcome = run_validation(sensors, scan_poses, meas.t, self.validation, self.gating, dofs, rec.faults,
                                 rec.magnetic_reference, self.scan_quality(rec, scan_poses))
        weights = {f: w for f, w in outcome.weights.items() if f != "submaps"}
        return Weighing(weights, outcome, csv=outcome.csv_text, submaps=outcome.weights.get("submaps"))

    def scan_quality(self, rec: Recording, scan_poses: Trajectory | None):
        return None


class Validated(_ByValidator):
    """``on``: sensor validation gates the factors (offline or causal)."""

    mode = GatingMode.ON

    def witnesses(self) -> list[str]:
        return witness_names(self.validation)

    def scan_quality(self, rec: Recording, scan_poses: Trajectory | None):
        obs = self.validation.observers
        if not (obs.scan.enabled or obs.scan_ceiling.enabled) or scan_poses is None:
            return None
        from slam.frontend.kiss import scan_quality

        return scan_quality(rec.scans, self.config.frontend)

    def recheck(self, meas: Measurements, weights: dict[str, np.ndarray], pose0: np.ndarray):
        if not self.validation.offline:
            return None
        from slam.gating.recheck import recheck

        return recheck(meas, weights, pose0, self.config.backend, self.gating)

    def gate_loops(self, obs, weighing: Weighing, keyframe_t: np.ndarray, truth: np.ndarray | None) -> None:
        from validation.loops.gating import gate_loops

        outcome = weighing.validation
        gated = gate_loops(obs, outcome.step_t, keyframe_t, self.validation.model, self.gating, self.validation.offline)
        outcome.extra_columns.update(gated.columns())


class IntervalOracle(_ByValidator):
    """``interval_oracle``: each component's factors gated over its true
    fault intervals, right or wrong."""

    mode = GatingMode.INTERVAL_ORACLE

    def weigh(self, rec: Recording, scan_poses: Trajectory | None, meas: Measurements, source: Path,
              witnesses: dict[str, Trajectory] | None = None) -> Weighing:
        if not any(rec.faults.values()):
            log.info("oracle gating without true fault intervals: nothing will be gated")
        return super().weigh(rec, scan_poses, meas, source, witnesses)


class TightOracle(Gating):
    """``oracle``: exactly the measurements (per degree of freedom) wrong by
    more than ``oracle_k_sigma`` sigmas against the ground truth are
    excluded; loops are judged against it too."""

    mode = GatingMode.ORACLE
    learns_scale = True

    def weigh(self, rec: Recording, scan_poses: Trajectory | None, meas: Measurements, source: Path,
              witnesses: dict[str, Trajectory] | None = None) -> Weighing:
        from slam.gating.truth import tight_oracle_weights

        if rec.groundtruth is None:
            raise GslamError(f"{source}: validation.mode oracle needs ground truth; the input has none")
        oracle = tight_oracle_weights(meas, rec.groundtruth, self.validation.oracle_k_sigma)
        return Weighing(oracle.weights, None, oracle.metrics(), oracle.csv_text())

    def gate_loops(self, obs, weighing: Weighing, keyframe_t: np.ndarray, truth: np.ndarray | None) -> None:
        from validation.loops.gating import oracle_loops

        if truth is None:
            log.info("oracle gating without ground truth: loops are kept as the loop observer decided")
            return
        ev = self.config.evaluation
        oracle_loops(obs, truth, ev.sm_fault_trans_m, np.radians(ev.sm_fault_yaw_deg))


def witness_names(validation: ValidationConfig) -> list[str]:
    """The sensors the pipeline makes for ``validation``'s observers:
    ``sub`` (local SLAM, :meth:`slam.pipeline.core.Mapping.witness`) where a
    relation compares one of its streams."""
    from validation.streams.names import split_source_stream

    sources = {(split_source_stream(s) or ("",))[0] for r in validation.observers.relations
               for s in (r.stream_a, r.stream_b)}
    return ["sub"] if "sub" in sources else []


def with_witnesses(rec: Recording, witnesses: dict[str, Trajectory]) -> Recording:
    """``rec`` with ``witnesses`` among its further odometry sources, as the
    validator reads them (the recording itself unchanged)."""
    return dataclasses.replace(rec, extra_odometry={**rec.extra_odometry, **witnesses}) if witnesses else rec


POLICIES: dict[GatingMode, type[Gating]] = {
    GatingMode.OFF: Ungated,
    GatingMode.ON: Validated,
    GatingMode.ORACLE: TightOracle,
    GatingMode.INTERVAL_ORACLE: IntervalOracle,
}


def gating_policy(config: PipelineConfig) -> Gating:
    """The policy of ``config``'s ``validation.mode``."""
    validation, gating = validation_sections(config)
    return POLICIES[validation.mode](config, validation, gating)
