"""The starter config ``gslam inspect --config-out`` writes.

Three parts, each commented for the reader who will check it:

1. the input: for a bag, the topics :mod:`slam.commands.inspect.topic_choice` guessed and
   the IMU's mounting; for the other formats (CARMEN, BROAD, libRSF), or
   with ``--config BASE``, the base config as it is (its comments kept),
   only its ``validation`` and ``gating`` sections replaced;
2. the system model proposed for the streams the recording holds as that
   input reads them (:func:`validation.proposal.propose_model`), inline
   under ``validation.model``, with its observers under
   ``validation.observers.relations`` and the factors each component gates
   under ``gating.factors``; the other keys of the base's two sections are
   kept;
3. the reason when nothing can be validated.

The observers' parameters are generic starting points: ``gslam calibrate``
learns them, and drops the relations the data do not support.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from slam.config import PipelineConfig
from slam.results.outdir import result_file_mark
from slam.recording import Recording
from slam.commands.inspect.topic_choice import TopicChoice
from validation.proposal import ModelProposal, Source

_COLUMN = 40
MODEL_KEYS = ("model",)


def _period(t: np.ndarray) -> float | None:
    return float(np.median(np.diff(t))) if len(t) > 1 else None


def recording_sources(rec: Recording, config: PipelineConfig, origins: Mapping[str, str] | None = None,
                      shared: Mapping[str, str] | None = None) -> list[Source]:
    """The streams ``rec`` holds as sources of the proposal: those the
    pipeline reads with ``config`` (scan matching only where the front-end
    runs). ``origins``: per stream (``scan``, ``gyro``, ``compass``,
    ``odometry``, ``gps``, a further source's name), where it comes from;
    ``shared``: streams that are another stream's sensor (libRSF's yaw rate
    is its odometry's), left out."""
    origins, shared = origins or {}, shared or {}
    out: list[Source] = []
    if rec.gyro is not None and len(rec.gyro.t) and "gyro" not in shared:
        out.append(Source("gyro", "gyro", origins.get("gyro", ""), _period(rec.gyro.t)))
    if rec.compass is not None and len(rec.compass.t) and "compass" not in shared:
        out.append(Source("compass", "compass", origins.get("compass", ""), _period(rec.compass.t),
                          magnetometer=rec.compass.field is not None))
    if rec.odometry is not None and len(rec.odometry.t) and "odometry" not in shared:
        out.append(Source("odometry", "odo", origins.get("odometry", ""), _period(rec.odometry.t)))
    for name, traj in rec.extra_odometry.items():
        if len(traj.t):
            out.append(Source("odometry", name, origins.get(name, ""), _period(traj.t)))
    matched = config.frontend.enabled and config.backend.factors.scan_matching.enabled
    if rec.scans is not None and len(rec.scans.t) and matched:
        out.append(Source("scan", "sm", origins.get("scan", ""), _period(rec.scans.t)))
    if rec.gps is not None and len(rec.gps.t) > 1:
        out.append(Source("gps", "gps", origins.get("gps", ""), _period(rec.gps.t)))
    return out


# --- YAML helpers -----------------------------------------------------------------------


def _flow(value: Any) -> str:
    """``value`` as one line of YAML (flow style)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10_000, sort_keys=False).strip()
    return text.removesuffix("...").strip()  # a scalar document's end marker


def _commented(line: str, comment: str, column: int = _COLUMN) -> str:
    return f"{line:<{column - 1}} # {comment}" if comment else line


def _block(mapping: Mapping[str, Any], indent: str) -> list[str]:
    """``mapping`` as YAML lines at ``indent``: a nested mapping of
    mappings in block style, anything else in flow style."""
    lines = []
    for key, value in mapping.items():
        if isinstance(value, Mapping) and any(isinstance(v, Mapping) for v in value.values()):
            lines += [f"{indent}{key}:", *_block(value, indent + "  ")]
        else:
            lines.append(f"{indent}{key}: {_flow(value)}")
    return lines


# --- the two sections ---------------------------------------------------------------------


def _model_lines(p: ModelProposal, indent: str) -> list[str]:
    i2 = indent + "  "
    origin = {s.name: s.origin for s in p.sources}
    lines = [
        f"{indent}# The logical model SD (validation/diagnosis/model.py), proposed from the streams found",
        f"{indent}# (validation/proposal/): not AB(S) -> ok(S);  relation(Si, Sj) and ok(Si) and ok(Sj) ->",
        f"{indent}# match(Si, Sj);  ok(S) -> plausible(S) for a unary check.",
        f"{indent}model:",
        f"{i2}# One component per modality, as in the paper's Table 1.",
        f"{i2}components: {_flow(p.components)}",
    ]
    if p.sensors:
        lines.append(f"{i2}# Sensors with several modalities: one fault may take all of them, or one alone.")
        lines.append(f"{i2}sensors:")
        for sensor, parts in p.sensors.items():
            src = next((s for s in p.sources if s.kind in ("odometry", "scan") and
                        (s.name.upper() == sensor or {"odo": "ODO", "sm": "SM"}.get(s.name) == sensor)), None)
            where = origin.get(src.name, "") if src is not None else ""
            lines.append(_commented(f"{i2}  {sensor}: {_flow(parts)}", where))
    lines.append(f"{i2}# One relation per observer: the two components whose streams it compares.")
    lines.append(f"{i2}relations:" + ("" if p.relations else " {}"))
    for r in p.relations:
        lines.append(_commented(f"{i2}  {r.config.name}: {_flow(list(r.config.components))}", r.why, 56))
    lines.append(f"{i2}unary_checks:" + ("" if p.unary_checks else " {}"))
    what = {"mag_plausible": "field strength and dip against the Earth field's",
            "mag_field_gyro": "the field's turn against the gyro's (observers.field_gyro)",
            "gps_plausible": "the receiver's own sigma", "loop_consistency": "loop closures (loops.enabled)",
            "scan_degenerate_dist": "a scan with too few returns, or one that leaves",
            "scan_degenerate_lat": "  this direction unconstrained (observers.scan)",
            "scan_degenerate_yaw": "",
            "scan_ceiling": "a laser that sees too little (observers.scan_ceiling)"}
    for name, comp in p.unary_checks.items():
        lines.append(_commented(f"{i2}  {name}: {comp}", what.get(name, ""), 56))
    lines += [
        f"{i2}fault_propagation: []",
        f"{i2}failure_masking: []",
        f"{i2}# Prior fault probabilities: they rank ambiguous diagnoses.",
        f"{i2}priors: {_flow(p.priors)}",
    ]
    return lines


def _observer_lines(p: ModelProposal, base: Mapping[str, Any], indent: str) -> list[str]:
    i2 = indent + "  "
    lines = [f"{indent}observers:"]
    # The proposal writes its relations and every check it knows (on or
    # off); the base keeps its other keys, so none is written twice.
    kept = {k: v for k, v in base.items() if k not in {"relations", *p.checks}}
    field_gyro = kept.get("field_gyro")
    if isinstance(field_gyro, Mapping) and field_gyro.get("enabled") \
            and field_gyro.get("name", "mag_field_gyro") not in p.unary_checks:
        kept["field_gyro"] = {**field_gyro, "enabled": False}  # the proposed model has no magnetometer and gyro
    lines += _block(kept, i2)
    lines.append(f"{i2}# Starting parameters, generic: gslam calibrate learns them from the recording.")
    lines.append(f"{i2}relations:" + ("" if p.relations else " []"))
    for r in p.relations:
        lines.append(f"{i2}  # {r.why}")
        lines.append(f"{i2}  - {_flow(r.config.compact())}")
    why = {"magnetometer": ("field strength and dip of the magnetometer", "no magnetometer field"),
           "gps": ("the GPS receiver's reported sigma", "no GPS"),
           "scan": ("the scans' returns and geometry (slam/frontend/scan_geometry.py)", "no laser"),
           "scan_ceiling": ("a scan cut off at a range ceiling (slam/frontend/scan_geometry.py)", "no laser")}
    for check, on in p.checks.items():
        entry = dict(base.get(check) or {})
        entry["enabled"] = on
        lines.append(_commented(f"{i2}{check}: {_flow(entry)}", why[check][0 if on else 1]))
    return lines


def validation_sections(p: ModelProposal, base_validation: Mapping[str, Any] | None,
                        base_gating: Mapping[str, Any] | None) -> str:
    """The ``validation`` and ``gating`` sections with the proposal in
    them, the bases' other keys kept."""
    base_validation, base_gating = dict(base_validation or {}), dict(base_gating or {})
    lines = ["validation:"]
    nothing = p.nothing_to_validate()
    if nothing:
        lines.append(f"  # Nothing can be validated: {nothing}.")
    lines.append(_commented('  mode: "off"', "--gating on maps gated, once gslam calibrate has learnt the observers"))
    rest = {k: v for k, v in base_validation.items() if k not in ("mode", "model", "observers")}
    rest.setdefault("pass", "offline")
    lines += _block(rest, "  ")
    lines += _model_lines(p, "  ")
    lines += _observer_lines(p, dict(base_validation.get("observers") or {}), "  ")
    for note in p.unvalidated:
        lines.append(f"  # Not validated: {note}.")
    lines.append("")
    lines.append("gating:")
    lines += _block({k: v for k, v in base_gating.items() if k != "factors"}, "  ")
    lines.append("  factors:                             # the components each factor's degrees of freedom depend on")
    for factor, dofs in p.gating_factors.items():
        lines.append(f"    {factor}: {_flow(dofs)}")
    if not p.gating_factors:
        lines[-1] = "  factors: {}"
    return "\n".join(lines) + "\n"


def replace_sections(text: str, sections: str, names: tuple[str, ...] = ("validation", "gating")) -> str:
    """``text`` (a config's YAML) without its top-level ``names`` blocks
    (and the comment lines just above them), ``sections`` appended."""
    out: list[str] = []
    skipping = False
    for line in text.splitlines():
        top = line[:1].isalpha()
        if top:
            skipping = line.split(":", 1)[0].strip() in names
            if skipping:
                while out and out[-1].startswith("#"):
                    out.pop()
        if not skipping:
            out.append(line)
    while out and not out[-1].strip():
        out.pop()
    return "\n".join(out) + "\n\n" + sections


# --- the starter for a bag ----------------------------------------------------------------


def bag_input(choice: TopicChoice) -> dict[str, Any]:
    """The ``input`` section of the guess."""
    data: dict[str, Any] = {
        "format": "auto",
        "topics": {"scan": choice.scan, "gyro": choice.gyro, "compass": choice.compass, "odometry": choice.odometry,
                   "gps": choice.gps, "groundtruth": choice.groundtruth},
        "gyro": {"axis": choice.gyro_axis},
        "compass": {"source": choice.compass_source, "declination_deg": 0.0, "mounting_yaw_deg": 0.0},
    }
    if choice.gyro_frame:
        data["frames"] = {"gyro": dict(choice.gyro_frame)}
    if choice.extra_odometry:
        data["extra_odometry"] = {name: {"topic": topic} for name, topic in choice.extra_odometry.items()}
    return data


def bag_starter(path: Path, choice: TopicChoice, proposal: ModelProposal) -> str:
    """The whole starter config for a bag."""
    t = choice

    def topic(key: str, value: str | None, what: str) -> str:
        others = t.others.get(key) or []
        note = what + (f"; also in the bag: {', '.join(others)}" if others else "") if value else f"{what}: none in the bag"
        return _commented(f"    {key}: {value or 'null'}", note, 31)

    notes = "\n".join(f"#   {n}" for n in t.notes)
    extra = ""
    if t.extra_odometry:
        extra = ("  extra_odometry:              # further odometry sources: validated as sensors of their own\n"
                 + "\n".join(f"    {name}: {{topic: {topic_name}}}" for name, topic_name in t.extra_odometry.items())
                 + "\n")
    frames = ""
    if t.gyro_frame:
        frames = f"  frames:\n    gyro: {_flow(t.gyro_frame)}\n"
    sm = "true" if t.scan else "false"
    initial = "groundtruth" if t.groundtruth else "origin"
    max_range = min(t.max_range_m, 100.0) if t.max_range_m is not None else 30.0
    on = lambda x: "true" if x else "false"  # noqa: E731
    head = f"""\
{result_file_mark('inspect')}: a starter config for {path.name}, written by `gslam inspect`.
# Every key is optional and has a default (docs; configs/telemax.yaml is a
# fully commented example). Check the sigmas against your sensors before
# trusting a result. The three commands:
#   gslam calibrate {path} --config THIS.yaml --out learnt.yaml
#   gslam map {path} --config learnt.yaml --out runs/gated --gating on
#   gslam map {path} --config learnt.yaml --out runs/ungated
"""
    if notes:
        head += "# What inspect read from the bag:\n" + notes + "\n"
    return head + f"""
input:
  format: auto
  topics:                      # null = stream not used
{topic("scan", t.scan, "sensor_msgs/LaserScan")}
{topic("gyro", t.gyro, "sensor_msgs/Imu: its yaw rate")}
{topic("compass", t.compass, "MagneticField, or an Imu's orientation (compass.source)")}
{topic("odometry", t.odometry, "nav_msgs/Odometry")}
{topic("gps", t.gps, "sensor_msgs/NavSatFix")}
{topic("groundtruth", t.groundtruth, "Odometry or PoseStamped, for evaluation only")}
  gyro:
{_commented(f"    axis: {t.gyro_axis}", "z | x | y | world_z (an IMU mounted tilted or rolled)", 31)}
  compass:
{_commented(f"    source: {t.compass_source}", "magnetic_field | imu_orientation", 31)}
    declination_deg: 0.0       # local magnetic declination, east positive
    mounting_yaw_deg: 0.0      # yaw of the heading against the robot's (gslam calibrate learns it from GPS)
{frames}{extra}
frontend:                      # KISS-ICP on the 2D scans
  enabled: {sm}
{_commented(f"  max_range_m: {max_range:g}", "at most the laser's range_max", 31)}

keyframes:
  period_s: 0.5                # a keyframe every 0.5 s (or set distance_m / yaw_deg)

backend:
  optimizer: batch             # batch | isam2 (long runs) | gnc_tls | gnc_gm
{_commented(f"  initial_pose: {initial}", "groundtruth | origin", 31)}
  factors:                     # sigmas: the defaults; measure yours
    odometry: {{enabled: {on(t.odometry)}}}
    gyro: {{enabled: {on(t.gyro)}}}
    compass: {{enabled: {on(t.compass)}}}
    scan_matching: {{enabled: {sm}}}
    gps: {{enabled: {on(t.gps)}}}

loops:                         # loop closing (docs/loops.md): with a laser, the loops of the
  enabled: {sm}                # scan-to-submap search, judged by GNC over the submap graph
  source: auto
  observer: {{chain_check: false, pcm: false, min_support: 0}}

submaps:                       # scan-to-submap constraints on the laser (slam/submaps)
  enabled: {sm}

""" + validation_sections(proposal, None, None)


def base_starter(path: Path, base_path: Path, base_text: str, proposal: ModelProposal, why: str) -> str:
    """The base config's text with the proposal's sections in place of its own."""
    tree = yaml.safe_load(base_text) or {}
    lines = base_text.splitlines()
    if lines and lines[0].startswith("# gslam "):  # an earlier result's mark: this file has its own
        lines = lines[1:]
    head = (f"{result_file_mark('inspect')}: a starter config for {path.name}, written by `gslam inspect`\n"
            f"# from {why} ({base_path.name}); its validation and gating sections proposed\n"
            f"# for the streams the recording holds. Learn the observers, then map gated:\n"
            f"#   gslam calibrate {path} --config THIS.yaml --out learnt.yaml\n"
            f"#   gslam map {path} --config learnt.yaml --out runs/gated --gating on\n")
    sections = validation_sections(proposal, tree.get("validation"), tree.get("gating"))
    return head + replace_sections("\n".join(lines), sections)
