"""Validation is never silently inactive: gaps judged by each stream's own
rhythm, coverage per observer, a warning that says why, an error when
nothing is observed at all."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from slam.recording import Recording, Trajectory
from validation.config import parse_sections
from validation.base.errors import ValidationError
from validation.observers import RelationConfig, observe_steps
from validation.observers.coverage import observer_coverage, require_observations, warn_low_coverage
from validation.streams import Stream, resample_streams, stream_max_gap

DISTANCE = RelationConfig(name="distance_odo_sm", stream_a="odo_distance", stream_b="sm_distance",
                          boundary=0.12, window_s=2.0, threshold=10, max_counter=30)
YAW = RelationConfig(name="yaw_odo_sm", stream_a="odo_yaw", stream_b="sm_yaw", boundary=0.05,
                     window_s=2.0, threshold=10, max_counter=30)
MODEL = {
    "components": ["ODO_DIST", "ODO_YAW", "SM_DIST", "SM_YAW"],
    "relations": {"distance_odo_sm": ["ODO_DIST", "SM_DIST"], "yaw_odo_sm": ["ODO_YAW", "SM_YAW"]},
    "priors": {"SM_DIST": 0.05, "SM_YAW": 0.05, "ODO_DIST": 0.02, "ODO_YAW": 0.02},
}


def sparse_stream(period_s: float, duration_s: float = 100.0, speed: float = 0.3, seed: int = 0) -> Stream:
    """A distance stream sampled every ``period_s`` +-50 % (a thinned log)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(period_s * rng.uniform(0.5, 1.5, int(2 * duration_s / period_s)))
    t = t[t <= duration_s]
    return Stream(t, speed * t)


def test_a_sparse_stream_is_judged_by_its_own_sample_period():
    sparse, dense = sparse_stream(2.0), sparse_stream(0.05)
    assert stream_max_gap("sm_distance", sparse, 0.5, None, 3.0) == pytest.approx(3.0 * np.median(np.diff(sparse.t)))
    assert stream_max_gap("sm_distance", dense, 0.5, None, 3.0) == 0.5  # a dense stream keeps max_gap_s
    assert stream_max_gap("sm_distance", sparse, 0.5, None, None) == 0.5  # the old rule
    assert stream_max_gap("sm_distance", sparse, 0.5, {"sm_distance": 0.1}, 3.0) == 0.1  # set outright
    steps = np.arange(sparse.t[0], sparse.t[-1], 0.1)
    assert resample_streams({"s": sparse}, steps, 0.5, None, 3.0).valid["s"].all()
    assert resample_streams({"s": sparse}, steps, 0.5).valid["s"].mean() < 0.01  # only steps on a sample


def test_a_real_gap_in_a_sparse_stream_still_counts():
    s = sparse_stream(2.0)
    keep = (s.t < 40.0) | (s.t > 60.0)  # 20 s without samples: ten periods
    steps = np.arange(s.t[0], s.t[-1], 0.1)
    valid = resample_streams({"s": Stream(s.t[keep], s.values[keep])}, steps, 0.5, None, 3.0).valid["s"]
    assert not valid[(steps > 42.0) & (steps < 58.0)].any() and valid[steps < 38.0].all()


def _coverage(streams, relations, gap_periods=3.0):
    steps = resample_streams(streams, np.arange(0.0, 100.0, 0.1), 0.5, None, gap_periods)
    log = observe_steps(steps, relations, (), "centred", "project", offline=True)
    return observer_coverage(log, steps, streams, relations, {})


def test_coverage_names_the_relation_and_the_reason(caplog):
    odo = sparse_stream(2.0)
    s = sparse_stream(2.0, seed=1)
    keep = s.t < 30.0  # scan matching stops after 30 s
    coverage = _coverage({"odo_distance": odo, "sm_distance": Stream(s.t[keep], s.values[keep])}, [DISTANCE, YAW])
    assert 0.2 < coverage["distance_odo_sm"].fraction < 0.3
    assert "sm_distance has data on" in coverage["distance_odo_sm"].reason
    assert "it spans" in coverage["distance_odo_sm"].reason
    assert coverage["yaw_odo_sm"].fraction == 0.0
    assert "stream odo_yaw is absent: the run has no odometry" in coverage["yaw_odo_sm"].reason
    with caplog.at_level(logging.WARNING, logger="validation.observers.coverage"):
        messages = warn_low_coverage(coverage, 0.5)
    assert len(messages) == 2 and all(m in caplog.text for m in messages)
    assert "observer distance_odo_sm has a valid observation on 2" in caplog.text


def test_gaps_longer_than_a_stream_may_bridge_are_the_reason():
    streams = {"odo_distance": sparse_stream(2.0), "sm_distance": sparse_stream(2.0, seed=1)}
    coverage = _coverage(streams, [DISTANCE], gap_periods=None)
    assert coverage["distance_odo_sm"].fraction == 0.0
    assert "gaps longer than the 0.5 s it may be interpolated across" in coverage["distance_odo_sm"].reason
    with pytest.raises(ValidationError, match="no observer has a valid observation at any step.*distance_odo_sm"):
        require_observations(coverage)
    assert _coverage(streams, [DISTANCE])["distance_odo_sm"].fraction > 0.9


def _thinned_recording(period_s: float) -> Recording:
    """Odometry and scan-matching poses of a robot driving a square, both
    sampled only every ``period_s`` (a thinned log)."""
    rng = np.random.default_rng(3)
    t = np.cumsum(period_s * rng.uniform(0.5, 1.5, 200))
    t = t[t < 200.0]
    yaw = 0.5 * np.pi * np.floor(t / 25.0)
    x, y = np.cumsum(0.3 * np.cos(yaw) * np.gradient(t)), np.cumsum(0.3 * np.sin(yaw) * np.gradient(t))
    return Recording("thinned", odometry=Trajectory(t, x, y, yaw)), Trajectory(t.copy(), x.copy(), y.copy(), yaw.copy())


@pytest.mark.parametrize("gap_periods", [3.0, None])
def test_gating_on_a_thinned_run_observes_or_says_it_cannot(gap_periods):
    from validation.validator import run_validation

    rec, sm = _thinned_recording(2.0)
    observers = {"relations": [DISTANCE.model_dump(), YAW.model_dump()], "gap_periods": gap_periods,
                 "magnetometer": {"enabled": False}, "gps": {"enabled": False}}
    vcfg, gcfg = parse_sections({"mode": "on", "model": MODEL, "observers": observers},
                                {"factors": {"odometry": {"x": ["ODO_DIST"], "y": ["ODO_DIST"], "yaw": ["ODO_YAW"]},
                                             "scan_matching": {"x": ["SM_DIST"], "y": ["SM_DIST"], "yaw": ["SM_YAW"]}}})
    dofs = {"odometry": ("x", "y", "yaw"), "scan_matching": ("x", "y", "yaw")}
    keyframes = rec.odometry.t
    if gap_periods is None:
        with pytest.raises(ValidationError, match=r"yaw_odo_sm: stream odo_yaw has data on 0% of the steps, "
                                                  r"\d+ gaps longer than the 0.5 s"):
            run_validation(rec, sm, keyframes, vcfg, gcfg, dofs)
        return
    out = run_validation(rec, sm, keyframes, vcfg, gcfg, dofs)
    assert min(out.metrics["observer_coverage"].values()) > 0.9
    assert out.metrics["alarm_fraction"] == 0.0
