"""The calibrated config as YAML: the input config, every default spelled
out, with its observers replaced by the learnt ones and the measured
figures beside each as comments, the streams' time offsets measured
against the gyro among them. ``gslam map OTHER --config MODEL.yaml``
uses it as it is; :func:`slam.config.load_config` reads it back. The
compass factor's noise, where it was measured, replaces the configured
one."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import yaml

from slam.commands.calibrate.lags import RATE_WINDOW_S, LagEstimate
from slam.commands.calibrate.noise import CompassNoise
from slam.commands.calibrate.propose import Proposal
from slam.commands.calibrate.select import RESOLUTION, CheckChoice, Choice, FieldGyroChoice
from slam.commands.calibrate.support import Support
from slam.config import PipelineConfig
from slam.results.outdir import result_file_mark
from validation.observers.config import RelationConfig

_PLACEHOLDER = "__relations__"
_INDENT = "    "


def _flow(rel: RelationConfig) -> str:
    """One relation as a YAML flow mapping (:meth:`RelationConfig.compact`)."""
    return yaml.safe_dump([rel.compact()], default_flow_style=None, width=10_000, sort_keys=False).strip()


def _pct(x: float) -> str:
    return "not met" if not np.isfinite(x) else f"{100 * x:.2f} %"


def _relation_comment(c: Choice, target: float, runs: int) -> list[str]:
    rel, fit = c.relation, c.fit
    unit = "rad" if "yaw" in rel.stream_b else "m"
    of_runs = f"{runs} run{'s' if runs > 1 else ''}"
    absolute = rel.kind == "offset" and rel.level_window_s is None
    if absolute:
        median, steps = c.offset
        lines = [f"{rel.name} (offset, level 0): {rel.stream_b} - {rel.gain:g} x {rel.stream_a}: median {median:.3g} {unit}, "
                 f"robust sd {c.noise:.3g} {unit} over {steps} steps of {of_runs}; band k_sigma = {c.multiple:g} sds"]
    else:
        lines = [
            f"{rel.name} ({rel.kind}): {rel.stream_b} against {rel.stream_a} over "
            f"{_window_words(rel, fit.window_s)}: "
            f"gain {fit.gain:.4f}, offset {fit.rate_offset:.3g} {unit}/s, residual noise {fit.noise:.3g} {unit} "
            f"(robust sd over {fit.steps} steps of {of_runs}, correlation {fit.corr:.3f})",
        ]
    floored = f" (raised to {100 * RESOLUTION:g} % of its motion)" if c.resolution else ""
    if rel.kind == "trend":
        lines.append(f"slopes differ by {c.noise:.3g} {unit}/s (robust sd{floored}) about {c.slope_offset:.3g} "
                     f"{unit}/s: b = |that offset| + {c.multiple:g} x that sd; smallest visible change "
                     f"{c.visible:.3g} {unit} over the window")
        if rel.mismatch_margin is not None:
            lines.append(f"a mismatch counts where the slopes part by more than {rel.mismatch_margin:g} b")
    elif rel.kind == "residual":
        lines.append(f"band k_sigma = {c.multiple:g} sds{floored}, growing by sigma_rel {rel.sigma_rel:.3g} of the "
                     "motion")
    elif rel.kind == "cusum":
        lines.append(f"CUSUM of the residual in sds, forgetting {rel.cusum_drift:g} a step: limit k_sigma = {c.multiple:g}; "
                     f"sds grow by sigma_rel {rel.sigma_rel:.3g} of the motion")
    elif not absolute:
        held = "" if rel.level_max_rate is None else f", held to {rel.level_max_rate:g} {unit}/s"
        lines.append(f"difference about its {rel.level_window_s:g} s running level{held}: {c.noise:.3g} {unit} "
                     f"(robust sd); band k_sigma = {c.multiple:g} sds")
    if fit.gain < 0 and not absolute:
        lines.append("WARNING: the streams turn opposite ways (negative gain): check input.frames")
    met = "" if c.met else f"; the target of {_pct(target)} could not be met with any candidate"
    lines.append(f"th {rel.threshold} steps: NO_MATCH on {_pct(c.alarm)} of the learning steps "
                 f"(worst run; target {_pct(target)}){met}")
    return lines


def calibrated_config(
    config: PipelineConfig,
    choices: dict[str, Choice | None],
    magnetometer: CheckChoice | None,
    field_gyro: FieldGyroChoice | None,
    proposals: Sequence[Proposal],
    header: Sequence[str],
    target: float,
    runs: int,
    lags: Sequence[LagEstimate] = (),
    compass_noise: CompassNoise | None = None,
    dropped: Mapping[str, Support] | None = None,
) -> str:
    """The YAML text of the module docstring. ``choices`` maps every
    configured relation to its calibration (None: no run had its streams,
    kept as it was); ``dropped`` the relations the data do not support,
    left out of the observers and the model with the reason as a comment."""
    dropped = dropped or {}
    validation = dict(config.validation)
    validation["mode"] = "off"
    if dropped and isinstance(validation.get("model"), dict):
        model = dict(validation["model"])
        model["relations"] = {k: v for k, v in model["relations"].items() if k not in dropped}
        model["failure_masking"] = [m for m in model.get("failure_masking", []) if m["relation"] not in dropped]
        validation["model"] = model
    observers = dict(validation["observers"])
    if magnetometer is not None:
        observers["magnetometer"] = magnetometer.config.model_dump(mode="json")
    if field_gyro is not None:
        observers["field_gyro"] = field_gyro.config.model_dump(mode="json")
    observers["relations"] = _PLACEHOLDER
    validation["observers"] = observers
    sections = config.model_dump(mode="json")
    sections["validation"] = validation
    noise_note = []
    if compass_noise is not None:
        compass = sections["backend"]["factors"]["compass"]
        compass["sigma_yaw_deg"] = float(f"{np.degrees(compass_noise.sd_rad):.3g}")
        compass["correlation_s"] = float(f"{compass_noise.correlation_s:.3g}")
        noise_note = [f"{_INDENT}# {line}" for line in _noise_comment(compass_noise, runs)]
    lag_note = [f"  # {line}" for line in _lag_comment(lags)]
    text = yaml.safe_dump(sections, sort_keys=False, allow_unicode=True, width=120, default_flow_style=None)

    block = [f"{_INDENT}relations:"]
    for rel_data in config.validation["observers"]["relations"]:
        name = rel_data["name"]
        choice = choices.get(name)
        if name in dropped:
            block.append(f"{_INDENT}# {name} ({rel_data.get('kind', 'trend')}, {rel_data['stream_a']} against "
                         f"{rel_data['stream_b']}): dropped, the data do not support it: {dropped[name].reason}")
            continue
        if choice is None:
            block.append(f"{_INDENT}# {name}: not calibrated, no run has both its streams; kept as configured")
            block.append(_INDENT + _flow(RelationConfig.model_validate(rel_data)))
            continue
        block += [f"{_INDENT}# {line}" for line in _relation_comment(choice, target, runs)]
        block.append(_INDENT + _flow(choice.relation))
    if all(line.lstrip().startswith("#") for line in block[1:]):  # every relation dropped: an empty list, not null
        block[0] = f"{_INDENT}relations: []"
    if proposals:
        block.append(f"{_INDENT}# Proposed: streams of different sensors whose rates correlate. To use one, uncomment")
        block.append(f"{_INDENT}# it and add its line under validation.model.relations.")
        for p in proposals:
            block += [f"{_INDENT}# {line}" for line in _relation_comment(p.choice, target, runs)]
            block.append(f"{_INDENT}# model: {p.choice.relation.name}: [{p.components[0]}, {p.components[1]}]")
            block.append(f"{_INDENT}# {_flow(p.choice.relation)}")
    mag_note = []
    if magnetometer is not None:
        mag_note = [f"{_INDENT}# magnetometer check: field strength within {magnetometer.strength_T * 1e6:.3g} uT and dip within "
                    f"{np.degrees(magnetometer.dip_rad):.3g} deg of the reference on all but {_pct(0.5 * target)} "
                    f"each of {magnetometer.steps} learning steps (worst run)"]
        if magnetometer.learnt_reference:
            mag_note.append(f"{_INDENT}# the reference (strength_T, dip_deg): the medians over the learning steps, "
                            "the recording giving none")
    field_note = []
    if field_gyro is not None:
        fg = field_gyro.config
        field_note = [f"{_INDENT}# field-gyro check: the field's change over {fg.window_s:g} s that the gyro's turn does "
                      f"not explain stays within {fg.tolerance_T * 1e6:.3g} uT on all but {_pct(target)} of "
                      f"{field_gyro.steps} learning steps (worst run)"]
    lines, section = [], ""
    for line in text.splitlines():
        if line[:1].isalpha():
            section = line.split(":")[0]
        if line.strip() == f"relations: {_PLACEHOLDER}":
            lines += block
        elif line.strip().startswith("magnetometer:") and line.startswith(_INDENT) and mag_note:
            lines += mag_note + [line]
        elif line.strip().startswith("field_gyro:") and line.startswith(_INDENT) and field_note:
            lines += field_note + [line]
        elif section == "backend" and line.startswith(f"{_INDENT}compass:") and noise_note:
            lines += noise_note + [line]
        elif line.startswith("  time_offsets_s:") and lag_note:
            lines += lag_note + [line]
        else:
            lines.append(line)
    head = [result_file_mark("calibrate") + ": a pipeline config whose observers were learnt from data"]
    head += [f"# {h}" for h in header]
    return "\n".join(head + lines) + "\n"


def _lag_comment(lags: Sequence[LagEstimate]) -> list[str]:
    if not lags:
        return []
    ref = lags[0].reference
    lines = [f"Time offsets against the {ref} (slam.commands.calibrate.lags): RMS of the yaw rates' difference over "
             f"{RATE_WINDOW_S:g} s, at the offsets below -> at the offset found:"]
    for lag in lags:
        verdict = "PROPOSED: add it to the offset below" if lag.proposed else f"not proposed: {lag.why_not()}"
        lines.append(f"{lag.stream}: {lag.offset_s:+.3f} s (halves {lag.halves_s[0]:+.3f} / {lag.halves_s[1]:+.3f} s), "
                     f"{np.degrees(lag.rms_before):.3g} -> {np.degrees(lag.rms_after):.3g} deg/s "
                     f"({-100 * lag.gain:+.0f} %), correlation {lag.correlation:.2f} over {lag.steps} steps; {verdict}")
    return lines


def _noise_comment(noise: CompassNoise, runs: int) -> list[str]:
    return [f"Compass heading minus the integrated gyro's, less a line per clean stretch (slam.commands.calibrate.noise), "
            f"over {noise.steps} steps of {noise.stretches} stretch{'es' if noise.stretches > 1 else ''} "
            f"({runs} run{'s' if runs > 1 else ''}): robust sd {np.degrees(noise.sd_rad):.3g} deg, autocorrelation",
            f"below 1/e after {noise.correlation_s:.3g} s: priors at keyframes dt apart carry "
            f"sigma_yaw_deg * sqrt(2 * correlation_s / dt)."]


def _window_words(rel: RelationConfig, window_s: float) -> str:
    """How long a relation's windows are, in words."""
    if rel.window_travel is None:
        return f"{window_s:g} s windows"
    return f"windows of {rel.window_travel:g} of {rel.stream_a}'s travel (at most {rel.window_s:g} s)"
