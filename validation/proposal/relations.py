"""The relations physics gives between a recording's streams, with the
observers that fit each and their generic starting parameters
(:func:`validation.proposal.propose_model` gathers them into a model).

Each rule pairs streams of different sensors that measure one quantity
(:mod:`validation.proposal` lists them); a relation is named after the
quantity and its two sources, as the shipped models name theirs
(``yaw_compass_gyro``, ``yaw_odo_gyro``, ``distance_odo_sm``), ``_res`` for
its residual observer and ``_off`` for its offset observer.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from validation.observers.config import RelationConfig
from validation.streams.names import source_stream

SourceKind = Literal["gyro", "compass", "odometry", "scan", "gps"]

STEP_PAIR_S = 0.2
"""Windows are whole numbers of this (two steps at the default 10 Hz)."""
MIN_SAMPLES = 4
"""A window holds at least this many samples of its sparser stream."""

# Starting parameters per quantity: (kind, boundary or sigma_floor, sigma_rel, window_s, threshold).
_TREND_YAW = 0.05          # rad/s
_TREND_DISTANCE = 0.1      # m/s
_TREND_SPEED = 0.2         # m/s per s
_RES_YAW = (0.03, 0.05)    # rad, share of the turn
_RES_FORWARD = (0.05, 0.05)
_RES_LATERAL = (0.05, 0.0)
_OFF_YAW = 0.05            # rad about the running level
_OFF_COURSE = 0.2          # rad about 0
_WINDOW_S = 2.0
_SPEED_WINDOW_S = 4.0
_TREND_TH, _QUANT_TH, _HEADROOM = 10, 5, 20

@dataclass(frozen=True)
class Source:
    """One stream of the recording as the proposal sees it.

    ``kind``: gyro, compass, odometry (the odometry or a further source),
    scan or gps. ``name``: its validation prefix (``gyro``, ``compass``,
    ``odo``, ``sm`` for the laser's scan matching, ``gps``, or a further
    odometry source's name). ``origin``: where it comes from, for the
    comments (a topic and type). ``period_s``: its median sample period (s)
    if known. ``magnetometer``: a compass that measures the field (it can be
    checked against the Earth's)."""

    kind: SourceKind
    name: str
    origin: str = ""
    period_s: float | None = None
    magnetometer: bool = False


@dataclass(frozen=True)
class ProposedRelation:
    """An observer and why physics gives it."""

    config: RelationConfig
    why: str


def describe(source: Source) -> str:
    """A source in a few words: ``gyro``, ``odometry 'vo'``, ``scan matching``."""
    if source.kind == "odometry":
        return "odometry" if source.name == "odo" else f"odometry '{source.name}'"
    return {"gyro": "gyro", "compass": "compass", "scan": "scan matching", "gps": "GPS"}[source.kind]


def _window(base: float, *sources: Source) -> float:
    """``base`` s, or :data:`MIN_SAMPLES` samples of the sparser source,
    rounded up to a whole number of step pairs."""
    periods = [s.period_s for s in sources if s.period_s is not None and math.isfinite(s.period_s)]
    w = max([base, *(MIN_SAMPLES * p for p in periods)])
    return round(math.ceil(w / STEP_PAIR_S - 1e-9) * STEP_PAIR_S, 6)


def _trend(name: str, a: str, b: str, boundary: float, window_s: float) -> RelationConfig:
    return RelationConfig(name=name, stream_a=a, stream_b=b, boundary=boundary, window_s=window_s,
                          threshold=_TREND_TH, max_counter=_TREND_TH + _HEADROOM)


def _residual(name: str, a: str, b: str, noise: tuple[float, float], window_s: float) -> RelationConfig:
    return RelationConfig(name=name, kind="residual", stream_a=a, stream_b=b, sigma_floor=noise[0],
                          sigma_rel=noise[1], window_s=window_s, threshold=_QUANT_TH,
                          max_counter=_QUANT_TH + _HEADROOM)


def _offset(name: str, a: str, b: str, sigma: float, window_s: float, level_window_s: float | None) -> RelationConfig:
    return RelationConfig(name=name, kind="offset", stream_a=a, stream_b=b, sigma_floor=sigma, window_s=window_s,
                          level_window_s=level_window_s, threshold=_QUANT_TH, max_counter=_QUANT_TH + _HEADROOM)


# Name order of a relation's two sides, as the shipped models name them
# (yaw_compass_gyro, yaw_odo_gyro, yaw_gyro_sm, distance_odo_sm).
_NAME_ORDER = {"compass": 0, "odometry": 1, "gyro": 2, "scan": 3, "gps": 4}
# The reference side (stream a) of a residual: the sensor that fails least
# often, by the priors below (its changes set the band, and calibration
# learns from the steps where it moves).
_REFERENCE_ORDER = {"gyro": 0, "odometry": 1, "compass": 2, "scan": 3, "gps": 4}


def _yaw_stream(s: Source) -> str:
    return {"gyro": "gyro_yaw", "compass": "compass_yaw"}.get(s.kind, source_stream(s.name, "yaw"))


def _named(a: Source, b: Source) -> tuple[Source, Source]:
    return (a, b) if (_NAME_ORDER[a.kind], a.name) <= (_NAME_ORDER[b.kind], b.name) else (b, a)


def _referenced(a: Source, b: Source) -> tuple[Source, Source]:
    return (a, b) if (_REFERENCE_ORDER[a.kind], a.name) <= (_REFERENCE_ORDER[b.kind], b.name) else (b, a)


def heading_relations(yaws: Sequence[Source]) -> list[ProposedRelation]:
    out = []
    for a, b in itertools.combinations(yaws, 2):
        first, second = _named(a, b)
        ref, other = _referenced(a, b)
        name = f"yaw_{first.name}_{second.name}"
        w = _window(_WINDOW_S, a, b)
        turn = f"heading change: {describe(first)} against {describe(second)}"
        out.append(ProposedRelation(_trend(name, _yaw_stream(first), _yaw_stream(second), _TREND_YAW, w),
                                    f"{turn} (trends, Algorithm 3)"))
        out.append(ProposedRelation(_residual(f"{name}_res", _yaw_stream(ref), _yaw_stream(other), _RES_YAW, w),
                                    f"{turn}: the size of the turns"))
        if "compass" in (a.kind, b.kind):
            integrated = b if a.kind == "compass" else a
            compass = a if a.kind == "compass" else b
            out.append(ProposedRelation(
                _offset(f"{name}_off", _yaw_stream(integrated), _yaw_stream(compass), _OFF_YAW, w, 60.0),
                f"the compass's heading against the {describe(integrated)}'s integrated turns: a heading that "
                "stands off"))
    return out


def travel_relations(movers: Sequence[Source]) -> list[ProposedRelation]:
    out = []
    for a, b in itertools.combinations(movers, 2):
        first, second = _named(a, b)
        ref, other = _referenced(first, second)
        w = _window(_WINDOW_S, a, b)
        pair = f"{describe(first)} against {describe(second)}"
        s = lambda src, q: source_stream(src.name, q)  # noqa: E731
        out += [
            ProposedRelation(_trend(f"distance_{first.name}_{second.name}", s(first, "forward"),
                                    s(second, "forward"), _TREND_DISTANCE, w), f"forward travel: {pair} (trends)"),
            ProposedRelation(_residual(f"distance_{first.name}_{second.name}_res", s(ref, "forward"),
                                       s(other, "forward"), _RES_FORWARD, w), f"forward travel: {pair}, its size"),
            # Sideways travel stays flat on wheels and tracks: a trend would compare the
            # symbols of two noises, so only its size is watched.
            ProposedRelation(_residual(f"lateral_{first.name}_{second.name}_res", s(ref, "lateral"),
                                       s(other, "lateral"), _RES_LATERAL, w),
                             f"sideways travel (none on wheels or tracks): {pair}"),
        ]
    return out


def gps_relations(gps: Source, movers: Sequence[Source], compass: Source | None,
                   odometry: Source | None) -> list[ProposedRelation]:
    out = []
    for m in movers:
        w = _window(_SPEED_WINDOW_S, gps, m)
        out.append(ProposedRelation(
            _trend(f"speed_gps_{m.name}", "gps_speed", source_stream(m.name, "fix_speed"), _TREND_SPEED, w),
            f"speed over ground: GPS against {describe(m)}, derived alike"))
    if compass is not None and odometry is not None:
        w = _window(_SPEED_WINDOW_S, gps, compass)
        out.append(ProposedRelation(
            _offset("yaw_compass_gps", "gps_course", "compass_yaw", _OFF_COURSE, w, None),
            "absolute heading: compass against the GPS course, where the odometry says the course is the heading"))
    return out
