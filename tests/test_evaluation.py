"""Trajectory metrics, TUM files and result plots on hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest
from matplotlib.image import imread

from slam.errors import GslamError
from slam.outputs.evaluation import (
    align_se2,
    associate,
    ate,
    evaluate,
    path_pairs,
    rpe,
)
from slam.outputs.tum import read_tum, write_tum
from slam.outputs.plots import plot_map, plot_trajectories
from slam.recording import Trajectory


def traj(t, x, y, yaw=None) -> Trajectory:
    t = np.asarray(t, dtype=float)
    yaw = np.zeros_like(t) if yaw is None else np.asarray(yaw, dtype=float)
    return Trajectory(t=t, x=np.asarray(x, dtype=float), y=np.asarray(y, dtype=float), yaw=yaw)


def transformed(tr: Trajectory, theta: float, tx: float, ty: float) -> Trajectory:
    """``tr`` moved rigidly by a rotation ``theta`` and a translation."""
    c, s = math.cos(theta), math.sin(theta)
    return traj(tr.t, c * tr.x - s * tr.y + tx, s * tr.x + c * tr.y + ty, tr.yaw + theta)


@pytest.fixture
def curve() -> Trajectory:
    """A 60 s curved path with turning heading, 10 Hz."""
    t = np.arange(0.0, 60.0, 0.1)
    return traj(t, 10 * np.sin(0.1 * t) + 0.2 * t, 5 * np.cos(0.07 * t), 0.3 * np.sin(0.05 * t))


# --- ATE ------------------------------------------------------------------


def test_identical_trajectories_have_zero_error(curve):
    m = evaluate(curve, curve, deltas_m=[5.0])
    for key in ("ate_rmse_m", "ate_rmse_unaligned_m", "ate_max_m", "rpe_trans_pct", "final_error_m"):
        assert m[key] == pytest.approx(0.0, abs=1e-9), key
    assert m["rpe_rot_deg_per_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["n_matched"] == len(curve)


def test_heading_error_is_wrapped_and_unaligned(curve):
    # Half the poses 10 deg off, half 350 deg off (= -10 deg): RMSE 10 deg.
    offset = np.where(np.arange(len(curve)) % 2 == 0, np.radians(10.0), np.radians(350.0))
    m = evaluate(traj(curve.t, curve.x, curve.y, curve.yaw + offset), curve, deltas_m=[5.0])
    assert m["yaw_rmse_deg"] == pytest.approx(10.0)
    assert m["yaw_max_deg"] == pytest.approx(10.0)
    assert m["ate_rmse_m"] == pytest.approx(0.0, abs=1e-9)


def test_constant_offset_is_removed_by_alignment(curve):
    est = traj(curve.t, curve.x + 3.0, curve.y - 4.0, curve.yaw)
    assert ate(est, curve, align=False).rmse_m == pytest.approx(5.0)
    assert ate(est, curve, align=False).max_m == pytest.approx(5.0)
    assert ate(est, curve, align=True).rmse_m == pytest.approx(0.0, abs=1e-9)
    assert evaluate(est, curve, [1.0])["final_error_m"] == pytest.approx(5.0)  # unaligned, at the last pose


def test_rigid_copy_aligns_to_zero_and_alignment_is_recovered(curve):
    est = transformed(curve, 0.7, -12.0, 3.5)
    assert ate(est, curve, align=False).rmse_m > 5.0
    assert ate(est, curve, align=True).rmse_m == pytest.approx(0.0, abs=1e-9)
    rot, t = align_se2(est.xy(), curve.xy())
    # The inverse of the applied motion maps est back onto curve.
    c, s = math.cos(-0.7), math.sin(-0.7)
    np.testing.assert_allclose(rot, [[c, -s], [s, c]], atol=1e-12)
    np.testing.assert_allclose(t, -np.array([[c, -s], [s, c]]) @ [-12.0, 3.5], atol=1e-9)
    # RPE does not see a rigid motion of the whole estimate.
    assert rpe(est, curve, 5.0).trans_pct == pytest.approx(0.0, abs=1e-9)


def test_radial_noise_pattern_has_hand_computed_ate():
    # Rectangle corners about the origin; the estimate pushes each corner
    # outward by eps * radius. Opposite corners share eps, so the offsets
    # have zero mean and a symmetric cross-covariance: the optimal alignment
    # is the identity and the errors stay eps * sqrt(5).
    ref = traj([0, 1, 2, 3], [2, -2, 2, -2], [1, -1, -1, 1])
    eps = np.array([0.1, 0.1, 0.2, 0.2])
    est = traj(ref.t, ref.x * (1 + eps), ref.y * (1 + eps))
    rot, t = align_se2(est.xy(), ref.xy())
    np.testing.assert_allclose(rot, np.eye(2), atol=1e-12)
    np.testing.assert_allclose(t, 0.0, atol=1e-12)
    res = ate(est, ref, align=True)
    assert res.rmse_m == pytest.approx(math.sqrt(0.125))  # sqrt(5 * (2*0.01 + 2*0.04) / 4)
    assert res.mean_m == pytest.approx(0.15 * math.sqrt(5))
    assert res.median_m == pytest.approx(0.15 * math.sqrt(5))
    assert res.max_m == pytest.approx(0.2 * math.sqrt(5))


# --- RPE ------------------------------------------------------------------


def test_rpe_scale_error_of_one_percent():
    # 1 m spacing: every pair is exactly 5 m apart, none at the 10 % edge.
    x = np.arange(0.0, 51.0)
    ref = traj(x, x, np.zeros_like(x))
    est = traj(x, 1.01 * x, np.zeros_like(x))
    res = rpe(est, ref, 5.0)
    assert len(res.pairs) == 46
    np.testing.assert_array_equal(res.pairs[:, 1] - res.pairs[:, 0], 5)
    assert res.trans_pct == pytest.approx(1.0)
    assert res.rot_deg_per_m == pytest.approx(0.0, abs=1e-12)


def test_rpe_constant_yaw_drift():
    # Same positions; the estimated heading drifts by 0.01 rad per metre.
    x = np.arange(0.0, 51.0)
    ref = traj(x, x, np.zeros_like(x))
    est = traj(x, x, np.zeros_like(x), 0.01 * x)
    res = rpe(est, ref, 5.0)
    assert res.rot_deg_per_m == pytest.approx(math.degrees(0.01))
    # The 5 m step seen from a frame turned by yaw_i is off by the chord
    # 2 * 5 * sin(yaw_i / 2).
    chord = 10.0 * np.sin(0.01 * x[:46] / 2.0)
    assert res.trans_pct == pytest.approx(100.0 * chord.mean() / 5.0)


def _path_pairs_reference(xy, delta, tol):
    """evo's filter_pairs_by_path(all_pairs=True) as a plain loop."""
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(xy[:-1] - xy[1:], axis=1))])
    pairs = []
    for i in range(len(dist) - 1):
        here = dist[i + 1 :] - dist[i]
        k = int(np.argmin(np.abs(here - delta)))
        if abs(here[k] - delta) <= tol:
            pairs.append((i, k + i + 1))
    return np.array(pairs, dtype=int).reshape(-1, 2)


def test_path_pairs_match_the_loop_version_with_stops_and_edges():
    rng = np.random.default_rng(3)
    steps = rng.uniform(0.0, 0.4, size=(400, 2))
    steps[rng.random(400) < 0.2] = 0.0  # standing still: plateaus in the path length
    xy = np.cumsum(steps, axis=0)
    for delta in (0.3, 2.0, 5.0, 17.3):
        tol = 0.1 * delta
        np.testing.assert_array_equal(path_pairs(xy, delta, tol), _path_pairs_reference(xy, delta, tol))
    # 0.5 m spacing: the last pair 4.5 m apart is inside the 10 % tolerance.
    line = np.column_stack([np.arange(0.0, 50.5, 0.5), np.zeros(101)])
    pairs = path_pairs(line, 5.0, 0.5)
    assert pairs[-1].tolist() == [91, 100] and len(pairs) == 92


def test_rpe_errors_on_too_short_path(curve):
    with pytest.raises(GslamError, match="no pose pairs"):
        rpe(curve, curve, 1000.0)
    m = evaluate(curve, curve, deltas_m=[1000.0, 2.0])
    assert m["rpe_trans_pct"] is None and m["rpe_trans_pct_1000m"] is None
    assert m["rpe_trans_pct_2m"] == pytest.approx(0.0, abs=1e-9)


# --- association ----------------------------------------------------------


def test_association_with_offsets_and_missing_poses():
    ref = traj(np.arange(10.0), np.arange(10.0), np.zeros(10))
    est_t = [0.004, 1.0, 2.02, 3.0, 5.0, 5.995, 9.01, 12.0]
    est = traj(est_t, est_t, np.zeros(len(est_t)))
    i_est, i_ref = associate(est, ref, max_dt=0.01)
    assert i_est.tolist() == [0, 1, 3, 4, 5, 6]
    assert i_ref.tolist() == [0, 1, 3, 5, 6, 9]
    # With the estimate the longer one, the walk goes over the reference.
    dense = traj(np.arange(0.0, 10.0, 0.25), np.zeros(40), np.zeros(40))
    i_est, i_ref = associate(dense, ref, max_dt=0.01)
    assert i_ref.tolist() == list(range(10))
    assert i_est.tolist() == list(range(0, 40, 4))


def test_association_tie_takes_the_earlier_stamp():
    ref = traj([0.0, 1.0, 2.0], [0, 0, 0], [0, 0, 0])
    est = traj([0.5, 1.5], [0, 0], [0, 0])
    i_est, i_ref = associate(est, ref, max_dt=0.5)
    assert i_ref.tolist() == [0, 1]


def test_disjoint_time_ranges_are_reported(curve):
    later = traj(curve.t + 100.0, curve.x, curve.y)
    with pytest.raises(GslamError, match="do not overlap"):
        evaluate(later, curve, deltas_m=[5.0])


# --- TUM files ------------------------------------------------------------


def test_tum_round_trip(tmp_path, curve):
    path = tmp_path / "est.tum"
    t0 = 1_700_000_000.123456789
    write_tum(path, curve, t0)
    first = next(line for line in path.read_text().splitlines() if not line.startswith("#"))
    assert first.split()[0] == f"{t0:.9f}" and len(first.split()) == 8
    back, t0_back = read_tum(path)
    assert t0_back == pytest.approx(t0, abs=1e-6)
    np.testing.assert_allclose(back.t, curve.t, atol=1e-6)
    np.testing.assert_allclose(back.x, curve.x, atol=1e-6)
    np.testing.assert_allclose(back.y, curve.y, atol=1e-6)
    np.testing.assert_allclose(back.yaw, curve.yaw, atol=1e-8)
    shifted, _ = read_tum(path, t0=t0 - 2.0)
    np.testing.assert_allclose(shifted.t, curve.t + 2.0, atol=1e-6)
    assert [p.name for p in tmp_path.iterdir()] == ["est.tum"]


@pytest.mark.parametrize(
    "bad_line, message",
    [
        ("3.0 1 2 0 0 0 0", "expected 8 numbers"),
        ("3.0 1 2 0 0 0 zero 1", "expected numbers"),
        ("3.0 1 nan 0 0 0 0 1", "non-finite"),
        ("0.5 1 2 0 0 0 0 1", "does not increase"),
        ("3.0 1 2 0 0 0 0 0", "zero quaternion"),
    ],
)
def test_malformed_tum_line_names_file_and_line(tmp_path, bad_line, message):
    path = tmp_path / "bad.tum"
    path.write_text(f"# header\n1.0 0 0 0 0 0 0 1\n\n{bad_line}\n")
    with pytest.raises(GslamError, match=message) as err:
        read_tum(path)
    assert f"{path}:4:" in str(err.value) and "\n" not in str(err.value)


def test_missing_or_empty_tum_file(tmp_path):
    with pytest.raises(GslamError, match="cannot read"):
        read_tum(tmp_path / "missing.tum")
    (tmp_path / "empty.tum").write_text("# nothing\n")
    with pytest.raises(GslamError, match="no poses"):
        read_tum(tmp_path / "empty.tum")


# --- plots ----------------------------------------------------------------


def test_plots_are_written_and_readable(tmp_path, curve):
    est = transformed(curve, 0.05, 0.5, -0.3)
    traj_png = tmp_path / "plots" / "trajectories.png"
    plot_trajectories(
        traj_png,
        {"gated": est, "odometry": transformed(curve, -0.1, 0.0, 0.0)},
        reference=curve,
        title="test run",
        shaded=[("outdoor", [(20.0, 35.0)]), ("SM fault", [(25.0, 30.0), (50.0, 55.0)])],
    )
    rng = np.random.default_rng(0)
    map_png = tmp_path / "map.png"
    plot_map(map_png, rng.uniform(-10, 10, size=(2000, 2)), curve, title="map")
    for png in (traj_png, map_png):
        assert png.stat().st_size > 10_000
        image = imread(png)
        assert image.ndim == 3 and image.shape[0] > 300 and image.shape[1] > 300
        assert image[..., :3].std() > 0.01  # not a blank canvas
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["map.png", "trajectories.png"]


def test_non_positive_delta_is_rejected(curve):
    with pytest.raises(GslamError, match="must be positive"):
        evaluate(curve, curve, deltas_m=[0.0])
    assert evaluate(curve, curve, deltas_m=[])["rpe_trans_pct"] is None
