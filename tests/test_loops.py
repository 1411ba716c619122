"""Loop closing on hand-made cases with known answers: registration,
descriptor, the chain's uncertainty, maximum clique, the loop observer on a
square trajectory with one true and one false loop, LOOP in the diagnosis,
listed (position-only) loops, loop factors and GNC."""

from __future__ import annotations

import itertools

import gtsam
import numpy as np
import pytest

from slam.graph.factors import pose_key
from slam.loops.chain import build_chain
from validation.loops.chain import integrate, world_discrepancy
from validation.base.geometry import between, compose
from slam.config.loops import LoopsConfig, ObserverConfig
from validation.loops.constraint import LoopConstraint
from slam.matching.grid import score_pyramid
from slam.matching.search import branch_and_bound
from slam.matching.descriptor import context_distance, scan_context
from slam.loops.detector import pinned_information
from slam.graph.loop_factors import loop_factor
from slam.loops.file_loops import file_loops
from slam.matching.icp import refine
from slam.matching.points import point_map, scan_normals
from slam.graph.measurements import BetweenMeasurement, Measurements
from slam.recording import PlaceMatches
from validation.loops.cliques import maximum_clique
from validation.loops.gating import gate_loops
from validation.loops.observer import chi2_quantile, observe_loops


# --- helpers ---------------------------------------------------------------


def wall(a, b, step=0.05):
    """Points every ``step`` m on the segment a-b, in order."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = max(int(np.hypot(*(b - a)) / step), 1)
    return a + np.linspace(0, 1, n, endpoint=False)[:, None] * (b - a)


def room_points():
    """An irregular room: walls in beam-like order, so normals can be fitted."""
    corners = [(-3, -2), (4, -2), (4, 1), (2.5, 1), (2.5, 3), (-3, 3), (-3, -2)]
    return np.concatenate([wall(a, b) for a, b in zip(corners[:-1], corners[1:])])


def point_map_of(points):
    normals, _ = scan_normals(points, 2, 0.3)
    return point_map(points, normals)


def transform(points, pose):
    """Points of a frame at ``pose`` expressed in the world: R p + t."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return points @ np.array([[c, -s], [s, c]]).T + pose[:2]


def inverse_transform(points, pose):
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return (points - pose[:2]) @ np.array([[c, -s], [s, c]])


# --- registration ----------------------------------------------------------


def test_registration_recovers_a_known_transform():
    world = room_points()
    pose = np.array([0.3, -0.2, np.radians(5.0)])
    query = inverse_transform(world, pose)  # the room seen from ``pose``
    reg = refine(query, point_map_of(world), np.zeros(3), 1.0, 0.2, 0.05)
    np.testing.assert_allclose(reg.pose[:2], pose[:2], atol=2e-3)
    assert abs(reg.pose[2] - pose[2]) < np.radians(0.1)
    assert reg.inliers > 0.95 and reg.rms_m < 0.01


def test_a_corridor_does_not_pin_its_axis():
    # Two long parallel walls along x: nothing fixes x.
    world = np.concatenate([wall((-10, -1), (10, -1)), wall((10, 1), (-10, 1))])
    world = world + np.random.default_rng(0).normal(0, 0.005, world.shape)
    reg = refine(world, point_map_of(world), np.zeros(3), 1.0, 0.2, 0.05)
    info, dims = pinned_information(reg, length_m=5.0, min_relative=0.05)
    assert dims == 2
    values, vectors = np.linalg.eigh(info)
    weak = vectors[:, np.argmin(np.abs(values))]
    assert abs(weak[0]) > 0.99  # the unpinned direction is x
    # In the room, every direction is pinned.
    room = room_points() + np.random.default_rng(1).normal(0, 0.005, room_points().shape)
    reg = refine(room, point_map_of(room), np.zeros(3), 1.0, 0.2, 0.05)
    assert pinned_information(reg, 5.0, 0.05)[1] == 3


def test_the_likelihood_field_search_brings_a_far_guess_into_icp_range():
    world = room_points()
    pose = np.array([0.8, 0.5, np.radians(12.0)])
    query = inverse_transform(world, pose)
    pyr = score_pyramid(world, 0.1, 0.1, 5, 0.3, 24)
    found = branch_and_bound(pyr, query[::4], np.zeros(3), 1.2, np.radians(15), angular_step_rad=np.radians(1))
    assert np.hypot(*(found.pose[:2] - pose[:2])) < 0.15 and abs(found.pose[2] - pose[2]) < np.radians(1.5)
    assert found.score > 0.5


# --- descriptor ------------------------------------------------------------


def test_scan_context_finds_the_relative_yaw():
    rng = np.random.default_rng(2)
    a = rng.uniform(-10, 10, (500, 2))
    yaw = np.radians(48.0)
    b = inverse_transform(a, np.array([0.0, 0.0, yaw]))  # seen from a frame turned by yaw
    ca, cb = (scan_context(p, 20, 60, 12.0) for p in (a, b))
    distance, found = context_distance(ca, cb)
    assert distance < 0.05 and abs(found - yaw) < np.radians(6.0)
    other = scan_context(rng.uniform(-10, 10, (500, 2)), 20, 60, 12.0)
    assert context_distance(ca, other)[0] > 0.3


# --- the chain and its uncertainty ----------------------------------------


def square_deltas(side_steps=10, step=1.0):
    """A closed square: ``side_steps`` steps of ``step`` m per side, 90 deg turns."""
    n = 4 * side_steps + 1
    d = np.zeros((n, 3))
    d[1:, 0] = step
    d[side_steps + 1 :: side_steps, 2] = np.pi / 2
    return d


def chain_of(deltas, sigma, start=np.zeros(3)):
    n = len(deltas)
    meas = Measurements(t=np.arange(n, dtype=float), scan_index=None)
    sig = np.tile(sigma, (n, 1))
    meas.odometry = BetweenMeasurement(delta=deltas, sigma=sig, valid=np.r_[False, np.ones(n - 1, bool)])
    return build_chain(meas, None, start)


def test_chain_covariance_matches_monte_carlo():
    rng = np.random.default_rng(3)
    truth_d = square_deltas(6, 0.5)
    truth = integrate(np.array([2.0, -1.0, 0.3]), truth_d)
    sigma = np.array([0.03, 0.01, 0.02])
    i, j = 2, len(truth_d) - 2
    samples = []
    for _ in range(2000):
        d = truth_d.copy()
        d[1:] += rng.normal(0, sigma, (len(d) - 1, 3))
        chain = chain_of(d, sigma, truth[0])
        samples.append(world_discrepancy(chain, np.array([i]), np.array([j]), between(truth[i], truth[j])[None])[0])
    expected = chain_of(truth_d, sigma, truth[0]).covariance(i, j)
    np.testing.assert_allclose(np.cov(np.array(samples).T), expected, rtol=0.1, atol=1e-3)


def test_chi2_quantiles():
    assert chi2_quantile(0.99, 2) == pytest.approx(9.2103, abs=1e-3)
    assert chi2_quantile(0.99, 3) == pytest.approx(11.3449, abs=1e-3)
    assert chi2_quantile(0.999, 4) == pytest.approx(18.4668, abs=1e-3)


# --- maximum clique (PCM) -------------------------------------------------


def brute_force_clique(adj):
    n = len(adj)
    for r in range(n, 0, -1):
        for c in itertools.combinations(range(n), r):
            if all(adj[a, b] for a, b in itertools.combinations(c, 2)):
                return r
    return 0


def test_maximum_clique_of_a_hand_made_consistency_graph():
    # Loops 0-3 agree with each other; 4 and 5 agree with each other and
    # with loop 0 only; 6 agrees with nobody.
    adj = np.zeros((7, 7), dtype=bool)
    for a, b in itertools.combinations([0, 1, 2, 3], 2):
        adj[a, b] = adj[b, a] = True
    for a, b in [(4, 5), (0, 4), (0, 5)]:
        adj[a, b] = adj[b, a] = True
    clique, proven = maximum_clique(adj)
    assert clique == [0, 1, 2, 3] and proven


def test_maximum_clique_agrees_with_brute_force():
    rng = np.random.default_rng(4)
    for _ in range(60):
        n = int(rng.integers(1, 11))
        adj = rng.random((n, n)) < rng.uniform(0.2, 0.9)
        adj = adj | adj.T
        clique, proven = maximum_clique(adj)
        assert proven and len(clique) == brute_force_clique(adj)
        assert all(adj[a, b] for a, b in itertools.combinations(clique, 2))


# --- the loop observer on a square ----------------------------------------


def square_case(rng_seed=5):
    """A 4 x 10 m square driven once with drifting odometry; a true loop
    from the end back to the start and a false one (3 m off)."""
    rng = np.random.default_rng(rng_seed)
    truth_d = square_deltas(10, 1.0)
    truth = integrate(np.zeros(3), truth_d)
    sigma = np.array([0.02, 0.02, np.radians(0.5)])
    measured = truth_d.copy()
    measured[1:] += rng.normal(0, sigma, (len(truth_d) - 1, 3))
    chain = chain_of(measured, sigma)
    info = np.diag([1 / 0.02**2, 1 / 0.02**2, 1 / np.radians(0.5) ** 2])
    end = len(truth) - 1
    true_loop = LoopConstraint(0, 0, end, between(truth[0], truth[end]), info)
    false_delta = compose(between(truth[5], truth[end - 12]), np.array([3.0, 0.0, 0.0]))
    false_loop = LoopConstraint(1, 5, end - 12, false_delta, info)
    return truth, chain, true_loop, false_loop


def test_observer_keeps_the_true_loop_and_rejects_the_false_one():
    truth, chain, true_loop, false_loop = square_case()
    alone = ObserverConfig(min_support=0)
    obs = observe_loops(chain, [true_loop, false_loop], alone)
    assert [v.accepted for v in obs.verdicts] == [True, False]
    assert obs.verdicts[1].reason == "chain"
    # Without the chain check, PCM alone must choose; two loops that disagree
    # are each a clique of one, so add a second true loop that agrees.
    second = LoopConstraint(2, 10, len(truth) - 3, between(truth[10], truth[-3]), true_loop.information)
    obs = observe_loops(chain, [true_loop, false_loop, second], ObserverConfig(chain_check=False, min_support=0))
    assert [v.accepted for v in obs.verdicts] == [True, False, True]
    assert obs.verdicts[1].reason == "pcm"


def test_a_loop_needs_a_close_consistent_loop_to_support_it():
    truth, chain, true_loop, _ = square_case()
    end = len(truth) - 1
    # A second loop of the same revisit: the cycle of the two spans 2 m of chain.
    neighbour = LoopConstraint(2, 1, end - 1, between(truth[1], truth[end - 1]), true_loop.information)
    obs = observe_loops(chain, [true_loop, neighbour], ObserverConfig(support_path_m=5.0))
    assert [v.accepted for v in obs.verdicts] == [True, True]
    # A lone loop has no support; loops 30 m of chain apart do not support each other.
    obs = observe_loops(chain, [true_loop], ObserverConfig())
    assert [v.reason for v in obs.verdicts] == ["support"]
    far = LoopConstraint(3, 10, 30, between(truth[10], truth[30]), true_loop.information)
    obs = observe_loops(chain, [true_loop, far], ObserverConfig(support_path_m=5.0))
    assert [v.reason for v in obs.verdicts] == ["support", "support"]


def odometry_graph(chain):
    """The square's odometry as a GTSAM graph anchored at the origin, and
    the chain as its initial values."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.PriorFactorPose2(pose_key(0), gtsam.Pose2(0, 0, 0), gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)))
    sigma = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.02, 0.02, np.radians(0.5)]))
    for k in range(1, len(chain)):
        graph.add(gtsam.BetweenFactorPose2(pose_key(k - 1), pose_key(k), gtsam.Pose2(*chain.deltas[k]), sigma))
    for k in range(len(chain)):
        values.insert(pose_key(k), gtsam.Pose2(*chain.poses[k]))
    return graph, values


def test_loop_factors_close_the_square():
    truth, chain, true_loop, _ = square_case()
    graph, values = odometry_graph(chain)
    end = len(chain) - 1
    before = np.hypot(*(chain.poses[end, :2] - truth[end, :2]))
    graph.add(loop_factor(true_loop))
    result = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize().atPose2(pose_key(end))
    after = np.hypot(result.x() - truth[end, 0], result.y() - truth[end, 1])
    assert after < 0.2 * before


def test_gnc_drops_a_false_loop_the_observer_let_through():
    from slam.graph.backend import _optimise_gnc_loops

    truth, chain, true_loop, false_loop = square_case()
    graph, values = odometry_graph(chain)
    graph.add(loop_factor(true_loop))
    graph.add(loop_factor(false_loop))
    result, _ = _optimise_gnc_loops(graph, values, [graph.size() - 2, graph.size() - 1])
    k = false_loop.j
    p = result.atPose2(pose_key(k))
    assert np.hypot(p.x() - truth[k, 0], p.y() - truth[k, 1]) < 0.3


# --- LOOP in the diagnosis ------------------------------------------------


def test_a_rejected_loop_makes_loop_the_diagnosis_and_gates_the_next():
    from validation.gating import GatingConfig
    from validation.diagnosis.model import SystemModel

    truth, chain, true_loop, false_loop = square_case()
    model = SystemModel(components=("ODO", "LOOP"), unary_checks={"loop_consistency": "LOOP"})
    keyframe_t = np.arange(len(truth), dtype=float)  # one keyframe per second
    later = LoopConstraint(2, 0, len(truth) - 1, true_loop.delta, true_loop.information)
    false_loop.j, true_loop.j = 20, 22  # the false loop 2 s before a true one
    true_loop.delta = between(truth[0], truth[22])
    obs = observe_loops(chain, [false_loop, true_loop, later], ObserverConfig(min_support=0))
    assert [v.accepted for v in obs.verdicts] == [False, True, True]
    step_t = np.arange(0.0, len(truth), 0.5)
    gated = gate_loops(obs, step_t, keyframe_t, model, GatingConfig(holdoff_s=5.0))
    assert [v.reason for v in obs.verdicts] == ["chain", "gated", ""]
    k = int(np.searchsorted(step_t, 20.0))
    assert gated.observations[k] == "implausible" and gated.diagnoses[k] == "{LOOP}"
    assert gated.decisions[k] == "exclude" and "1:rejected(chain)" in gated.step_loops[k]
    assert obs.counts == {"found": 3, "accepted": 1, "rejected_chain": 1, "rejected_gated": 1}


def test_validation_model_without_loop_is_an_error():
    from validation.base.errors import ValidationError
    from validation.gating import GatingConfig
    from validation.diagnosis.model import SystemModel

    truth, chain, true_loop, _ = square_case()
    obs = observe_loops(chain, [true_loop], ObserverConfig(min_support=0))
    with pytest.raises(ValidationError, match="needs a component LOOP"):
        gate_loops(obs, np.arange(5.0), np.arange(len(truth), dtype=float), SystemModel(components=("ODO",)), GatingConfig())


# --- listed (position-only) loops ------------------------------------------


def test_listed_loops_are_position_only_and_the_false_one_is_rejected():
    truth, chain, _, _ = square_case()
    t = np.arange(len(truth), dtype=float)
    end = len(truth) - 1
    # Back at the start at the end (twice, one weaker); a false match
    # between keyframes 3 and 25; a match below min_weight.
    matches = PlaceMatches(t=np.array([end, end - 0.2, 25.0, 1.0]), t_other=np.array([0.0, 0.1, 3.0, 5.0]),
                           weight=np.array([1.0, 0.8, 0.9, 0.2]))
    loops = file_loops(matches, t, LoopsConfig().file, max_gap_s=0.5)
    assert [(lp.i, lp.j) for lp in loops] == [(0, end), (0, end), (3, 25)]
    assert all(lp.information[2, 2] == 0 for lp in loops)
    assert loops[1].information[0, 0] == pytest.approx(0.8 / 0.5**2)
    obs = observe_loops(chain, loops, ObserverConfig(min_support=0))
    # Keyframes 3 and 25 are 12 m apart: that match is false.
    assert [v.accepted for v in obs.verdicts] == [True, True, False]


def test_loops_config_rejects_unknown_keys():
    from slam.config import load_config
    from slam.errors import GslamError

    with pytest.raises(GslamError, match="unknown config key 'loops.search_radius'"):
        load_config(None, ["loops.search_radius=2"])
    cfg = load_config(None, ["loops.enabled=true", "loops.observer.pcm=false"])
    assert cfg.loops.enabled and not cfg.loops.observer.pcm
    # Loops gated by validation need LOOP in the model: said before any work.
    model = "validation.model={components: [ODO_DIST, ODO_YAW, ODO, IMU_GYRO, IMU_YAW, SM_DIST, SM_LAT, SM_YAW, SM, GPS]}"
    none = ["validation.observers.relations=[]", "validation.observers.magnetometer.enabled=false",
            "validation.observers.gps.enabled=false"]
    with pytest.raises(GslamError, match="needs a component LOOP"):
        load_config(None, ["loops.enabled=true", "validation.mode=on", model, *none])
    load_config(None, ["loops.enabled=false", "validation.mode=on", model, *none])
