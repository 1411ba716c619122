"""New relations proposed from data: two streams of different sensors
whose rates correlate.

Streams that measure the same quantity (a heading, a forward travel, a
sideways travel, a path length) from different sensors are paired when no
configured relation compares them yet. A pair is proposed when their
windowed changes correlate (``|r| >= MIN_CORRELATION``) over steps where
the robot moved well beyond the pair's noise; the proposal is a residual
relation with its parameters learnt as any other
(:func:`slam.commands.calibrate.select.calibrate_relation`), written commented out:
a user adds it, and its components to the model's relations, to use it.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

from slam.commands.calibrate.runs import CalibrationRun
from slam.commands.calibrate.fit import fit_rates
from slam.commands.calibrate.select import Choice, calibrate_relation, candidate_windows
from validation.config import ValidationConfig
from validation.diagnosis.model import SystemModel
from validation.observers.config import RelationConfig
from validation.streams import stream_component

MIN_CORRELATION = 0.9
MIN_MOTION = 3.0
"""The spread of stream a's changes must be this many times the residual's noise."""
QUANTITIES = {
    "yaw": ("compass_yaw", "gyro_yaw", "sm_yaw", "odo_yaw"),
    "forward": ("odo_forward", "sm_forward"),
    "distance": ("odo_distance", "sm_distance"),
}


@dataclass
class Proposal:
    """A relation the data suggest, with its calibration."""

    choice: Choice
    components: tuple[str, str]


def propose(runs: Sequence[CalibrationRun], relations: Sequence[RelationConfig], model: SystemModel,
            vcfg: ValidationConfig, target: float) -> list[Proposal]:
    """Proposals of the module docstring, in a fixed order."""
    present = {name for run in runs for name in run.streams}
    taken = {frozenset(r.streams) for r in relations}
    names = {r.name for r in relations}
    out: list[Proposal] = []
    for quantity, streams in QUANTITIES.items():
        for a, b in itertools.combinations([s for s in streams if s in present], 2):
            ca, cb = stream_component(a), stream_component(b)
            if frozenset((a, b)) in taken or ca not in model.components or cb not in model.components:
                continue
            name = f"{quantity}_{a.split('_')[0]}_{b.split('_')[0]}_res"
            if name in names:
                continue
            rel = RelationConfig(name=name, kind="residual", stream_a=a, stream_b=b, window_s=2.0,
                                 sigma_floor=1.0, threshold=1)
            w = min(candidate_windows(runs, rel, vcfg.rate_hz), key=lambda x: abs(x - rel.window_s))
            fit = fit_rates(runs, a, b, w, vcfg.window, vcfg.rate_hz)
            if fit is None or abs(fit.corr) < MIN_CORRELATION or fit.motion < MIN_MOTION * fit.noise:
                continue
            choice = calibrate_relation(runs, rel, vcfg, target)
            if choice is not None:
                out.append(Proposal(choice, (ca, cb)))
    return out
