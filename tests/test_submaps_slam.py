"""Scan-to-submap SLAM on a simulated building (slam.submaps): refinement,
local SLAM, the constraint search and its graph, against the true poses."""

from __future__ import annotations

import numpy as np
import pytest

from validation.base.geometry import between, compose
from slam.errors import GslamError
from slam.recording import Scans
from slam.sim.scenario import Region, RegionKind
from slam.sim.world import World
from slam.submaps.build import build_submap_constraints, select_nodes
from slam.config.submaps import SubmapsConfig
from slam.matching.icp import pose_uncertainty, refine
from slam.matching.points import point_map
from slam.config import FrontendConfig
from validation.loops.chain import integrate
from validation.loops.gating import pinned_error

BEAMS = np.radians(np.arange(-90.0, 90.0, 1.0))  # a sparse 180-beam scanner


def world_of(lines: list[list[tuple[float, float]]]) -> World:
    segs = []
    for line in lines:
        p = np.asarray(line, dtype=float)
        segs += [p[i : i + 2] for i in range(len(p) - 1)]
    segments = np.asarray(segs)
    d = segments[:, 1] - segments[:, 0]
    normals = np.column_stack([-d[:, 1], d[:, 0]]) / np.hypot(d[:, 0], d[:, 1])[:, None]
    return World(segments, normals, [], Region(name="all", kind=RegionKind.INDOOR, polygon=[(0, 0), (1, 0), (0, 1)]))


def building() -> World:
    """A ring corridor around a block of rooms, with doors and alcoves that
    make places distinguishable."""
    outer = [(-2, -2), (22, -2), (22, 14), (-2, 14), (-2, -2)]
    inner = [(2, 2), (18, 2), (18, 10), (2, 10), (2, 2)]
    features = [
        [(5, -2), (5, -1.2)], [(9, 2), (9, 1.4)], [(14, -2), (14, -0.9), (15, -0.9)],
        [(22, 5), (21.2, 5)], [(18, 7), (18.8, 7), (18.8, 8)], [(12, 14), (12, 13.1)],
        [(7, 10), (7, 10.7), (6, 10.7)], [(-2, 6), (-1.1, 6)], [(2, 4), (1.3, 4)], [(16, 14), (16, 12.9)],
    ]
    return world_of([outer, inner, *features])


def ring_path(step_m: float, laps: float) -> np.ndarray:
    """Poses along the corridor's centre line, counter-clockwise."""
    corners = np.array([(0, 0), (20, 0), (20, 12), (0, 12), (0, 0)], dtype=float)
    pts = []
    for a, b in zip(corners[:-1], corners[1:]):
        n = int(np.hypot(*(b - a)) / step_m)
        pts.append(a + np.linspace(0, 1, n, endpoint=False)[:, None] * (b - a))
    xy = np.concatenate(pts)
    xy = np.concatenate([xy] * int(np.ceil(laps)))[: int(len(xy) * laps)]
    d = np.diff(xy, axis=0, append=xy[:1] + (xy[1] - xy[0]))
    yaw = np.arctan2(d[:, 1], d[:, 0])
    return np.column_stack([xy, yaw])


def simulate(world: World, poses: np.ndarray, rng) -> Scans:
    ranges = np.empty((len(poses), len(BEAMS)), dtype=np.float32)
    for k, p in enumerate(poses):
        r, _ = world.cast(p[:2], p[2] + BEAMS, 30.0)
        ranges[k] = np.where(np.isfinite(r), r + rng.normal(0.0, 0.01, len(r)), 81.0)
    return Scans(t=np.arange(len(poses), dtype=float), ranges=ranges, angles=BEAMS.copy(), range_min=0.0, range_max=80.0)


def drifting_odometry(poses: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """Steps with 2 % scale error and 1.5 deg of yaw noise each, and their covariance."""
    steps = np.zeros_like(poses)
    steps[1:] = np.array([between(a, b) for a, b in zip(poses[:-1], poses[1:])])
    noisy = steps.copy()
    noisy[1:, :2] *= 1.02
    noisy[1:, 2] += rng.normal(0.0, np.radians(1.5), len(poses) - 1)
    cov = np.zeros((len(poses), 3, 3))
    cov[1:] = np.diag([0.05**2, 0.05**2, np.radians(2.0) ** 2])
    return noisy, cov


@pytest.fixture(scope="module")
def run():
    rng = np.random.default_rng(7)
    truth = ring_path(0.7, 2.0)
    scans = simulate(building(), truth, rng)
    steps, cov = drifting_odometry(truth, rng)
    cfg = SubmapsConfig(enabled=True)
    result = build_submap_constraints(scans, np.arange(len(truth)), steps, cov, FrontendConfig(max_range_m=50.0), cfg)
    return truth, steps, result


def rel_error(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    e = np.array([between(between(a, b), between(c, d)) for a, b, c, d in zip(truth[:-1], truth[1:], est[:-1], est[1:])])
    return np.hypot(e[:, 0], e[:, 1])


def test_refinement_recovers_an_offset_and_leaves_a_corridor_axis_free():
    x = np.arange(-10.0, 10.0, 0.05)
    room = np.concatenate([np.column_stack([x, np.full_like(x, 1.0)]), np.column_stack([x, np.full_like(x, -1.0)]),
                           np.column_stack([np.full(40, 3.0), np.linspace(-1, 1, 40)])])
    normals = np.concatenate([np.tile([0.0, 1.0], (2 * len(x), 1)), np.tile([1.0, 0.0], (40, 1))])
    pm = point_map(room, normals)
    rng = np.random.default_rng(3)
    scan = room[rng.choice(len(room), 200, replace=False)]
    ref = refine(scan, pm, np.array([0.05, -0.04, 0.01]))
    assert ref.converged and np.allclose(ref.pose, 0.0, atol=5e-3)
    _, free = pose_uncertainty(ref.information, 5.0, 0.1)
    assert len(free) == 0  # the end wall pins the axis

    corridor = point_map(room[: 2 * len(x)], normals[: 2 * len(x)])
    ref = refine(scan[np.abs(scan[:, 1]) > 0.5], corridor, np.array([0.0, 0.03, 0.0]))
    _, free = pose_uncertainty(ref.information, 5.0, 0.1)
    assert len(free) == 1 and abs(free[0][0]) > 0.99  # free along x only


@pytest.mark.slow
def test_local_slam_is_more_accurate_than_its_odometry(run):
    truth, steps, result = run
    odometry = integrate(truth[0], steps)
    assert rel_error(result.local.poses, truth).mean() < 0.5 * rel_error(odometry, truth).mean()
    assert rel_error(result.local.poses, truth).mean() < 0.03


def test_the_second_lap_closes_loops_and_every_kept_constraint_is_right(run):
    truth, _, result = run
    loops = result.of_kind("loop")
    assert len(loops) >= 10
    for c in result.constraints:
        e = pinned_error(c.information, between(between(truth[c.anchor], truth[c.scan]), c.delta))
        assert np.hypot(e[0], e[1]) <= 0.15 and abs(e[2]) <= np.radians(3.0), (c.kind, c.anchor, c.scan, e)


def test_the_graph_estimate_holds_the_map_together(run):
    truth, steps, result = run
    start = truth[0]
    est = np.array([compose(start, between(result.estimate[0], p)) for p in result.estimate])
    odometry = integrate(start, steps)
    final = np.hypot(*(est[-1, :2] - truth[-1, :2]))
    assert final < 0.2 < np.hypot(*(odometry[-1, :2] - truth[-1, :2]))
    assert np.sqrt(np.mean(np.sum((est[:, :2] - truth[:, :2]) ** 2, axis=1))) < 0.15


def test_local_slam_as_a_witness_keeps_the_heading_where_the_chain_over_turns():
    """The ``sub`` witness (slam.submaps.build.local_witness): the chain
    turns a fifth more than the robot (a wheel slipping in the turns; the
    path turns its corners in one step, 90 deg then 108), and local SLAM's
    headings still follow the walls."""
    from slam.submaps.build import local_witness

    rng = np.random.default_rng(11)
    truth = ring_path(0.7, 1.0)
    scans = simulate(building(), truth, rng)
    steps, cov = drifting_odometry(truth, rng)
    steps[1:, 2] *= 1.2
    t = np.arange(len(truth), dtype=float) * 0.5
    wit = local_witness(scans, np.arange(len(truth)), t, steps, cov, FrontendConfig(max_range_m=50.0),
                        SubmapsConfig(enabled=True))
    nodes = np.round(wit.t / 0.5).astype(int)
    assert nodes[0] == 0 and np.all(np.diff(nodes) > 0)
    turned = np.diff(np.unwrap(wit.yaw))
    true_turn = np.diff(np.unwrap(truth[nodes, 2]))
    chain_turn = np.add.reduceat(steps[1:, 2], nodes[:-1])[: len(true_turn)]
    assert np.degrees(np.abs(chain_turn - true_turn)).max() > 15.0
    assert np.degrees(np.abs(turned - true_turn)).max() < 3.0


def test_nodes_are_taken_by_motion():
    steps = np.zeros((10, 3))
    steps[1:, 0] = 0.1
    steps[5, 2] = np.radians(10)
    nodes = select_nodes(steps, 0.25, np.radians(5))
    assert list(nodes) == [0, 3, 5, 8]


@pytest.mark.slow
@pytest.mark.parametrize("overrides, from_submaps", [
    ((), True),
    (("backend.robust_kernel=dcs", "backend.robust_param=2.0"), False),
    (("backend.optimizer=gnc_tls",), False),
])
def test_the_submaps_estimate_starts_the_graph_unless_a_robust_kernel_judges_it(short_run, tmp_path, monkeypatch,
                                                                                 overrides, from_submaps):
    import slam.graph.backend
    from slam.config import load_config
    from slam.pipeline.folder import MappingPipeline
    from tests.conftest import TELEMAX_CONFIG

    starts = []
    real = slam.graph.backend.optimise

    def spy(*args, **kwargs):
        starts.append(kwargs.get("initial_poses"))
        return real(*args, **kwargs)

    monkeypatch.setattr(slam.graph.backend, "optimise", spy)
    config = load_config(TELEMAX_CONFIG, ["output.plots=false", *overrides])
    pipe = MappingPipeline(short_run.run_dir, config, tmp_path / "out", concurrent=False)
    pipe.run()
    assert pipe.core.submaps is not None and len(starts) == 1
    assert (starts[0] is not None) == from_submaps


@pytest.mark.slow
def test_a_loop_is_made_only_where_the_carriers_scans_confirm_the_submap(monkeypatch):
    import slam.submaps.graph as graph
    from slam.submaps.local import Match

    def match(pose):
        return Match(0, 1, np.asarray(pose, dtype=float), 0.9, 0.02, 0.8, np.eye(3) * 1e-4, np.zeros((0, 3)))

    delta = np.array([1.0, 0.5, 0.2])
    assert graph._agree(match(delta + [0.01, -0.01, np.radians(0.1)]), delta, 0.02, np.radians(0.3))
    assert not graph._agree(None, delta, 0.02, np.radians(0.3))
    assert not graph._agree(match(delta + [0.03, 0.0, 0.0]), delta, 0.02, np.radians(0.3))
    assert not graph._agree(match(delta + [0.0, 0.0, np.radians(0.5)]), delta, 0.02, np.radians(0.3))

    # The carrier's scans never confirm: no loop, while the near constraints stay.
    monkeypatch.setattr(graph, "refine_near", lambda *args, **kwargs: None)
    rng = np.random.default_rng(7)
    truth = ring_path(0.7, 2.0)
    scans = simulate(building(), truth, rng)
    steps, cov = drifting_odometry(truth, rng)
    fe = FrontendConfig(max_range_m=50.0)
    strict = SubmapsConfig.model_validate({"enabled": True, "constraints": {"agree": ["loop"]}})
    found = build_submap_constraints(scans, np.arange(len(truth)), steps, cov, fe, strict)
    assert not found.of_kind("loop") and found.of_kind("near")
    lenient = SubmapsConfig(enabled=True)  # agree: [] by default
    assert len(build_submap_constraints(scans, np.arange(len(truth)), steps, cov, fe, lenient).of_kind("loop")) >= 10


def test_agreement_needs_the_carriers_refinement():
    with pytest.raises(ValueError, match="refine_near"):
        SubmapsConfig.model_validate({"constraints": {"refine_near": False, "agree": ["loop"]}})
    SubmapsConfig.model_validate({"constraints": {"refine_near": False}})


@pytest.mark.slow
def test_a_place_beyond_the_windows_is_recognised_and_its_loops_are_right():
    # No submap is near enough the estimate to be searched: only recognition can close the loops.
    rng = np.random.default_rng(11)
    truth = ring_path(0.7, 2.0)
    scans = simulate(building(), truth, rng)
    steps, cov = drifting_odometry(truth, rng)
    fe = FrontendConfig(max_range_m=50.0)
    narrow = {"max_distance_m": 1e-3}

    def loops(recognition: bool):
        cfg = SubmapsConfig.model_validate({"enabled": True, "constraints": narrow,
                                            "recognition": {"enabled": recognition, "min_path_m": 10.0}})
        result = build_submap_constraints(scans, np.arange(len(truth)), steps, cov, fe, cfg)
        return result, result.of_kind("loop")

    _, blind = loops(False)
    result, seen = loops(True)
    assert not blind and len(seen) >= 5
    for c in seen:
        e = pinned_error(c.information, between(between(truth[c.anchor], truth[c.scan]), c.delta))
        assert np.hypot(e[0], e[1]) <= 0.15 and abs(e[2]) <= np.radians(3.0), (c.anchor, c.scan, e)
    start = truth[0]
    est = np.array([compose(start, between(result.estimate[0], p)) for p in result.estimate])
    assert np.hypot(*(est[-1, :2] - truth[-1, :2])) < 0.3


def _traces_of_blamed_scans(short_run, blamed_scans: str) -> tuple[int, int]:
    """Map the short run with the scan matching of every fourth keyframe
    (from the tenth) excluded; how many submap constraints and loops rest on
    those keyframes' scans, and how many keyframes were blamed."""
    from slam.config import load_config
    from slam.pipeline.core import Mapping, blamed_scans as blamed_of
    from slam.readers.read import read_recording
    from tests.conftest import TELEMAX_CONFIG

    config = load_config(TELEMAX_CONFIG, ["output.plots=false", f"submaps.blamed_scans={blamed_scans}"])
    core = Mapping(read_recording(short_run.run_dir, config.input), config, source=short_run.run_dir)
    core.match_scans()
    core.build_measurements()
    core.validate()
    n = len(core.measurements)
    sm = np.array(core.weights["scan_matching"], dtype=float)
    sm[10::4] = np.inf
    core.weights["scan_matching"] = sm
    blamed = blamed_of(core.weights, n)
    core.build_submaps()
    core.judge_loops(core.find_loops())
    nodes = set(core.submaps.nodes.tolist())
    on_blamed = [k for k in np.flatnonzero(blamed) if k in nodes]
    assert on_blamed  # the test blames scans the submaps would use
    res = core.submaps
    traces = sum(1 for c in [*res.constraints, *res.dropped] if blamed[c.scan])
    traces += sum(1 for c in core.constraints if c.label == "submap" and blamed[c.j])
    if core.loop_observation is not None:
        traces += sum(1 for v in core.loop_observation.verdicts if v.accepted and (blamed[v.loop.i] or blamed[v.loop.j]))
    traces += sum(1 for k, m in enumerate(res.local.matches) if m is not None and blamed[res.nodes[k]])
    return traces, len(on_blamed)


@pytest.mark.slow
def test_a_blamed_scan_leaves_no_trace_in_the_submaps_when_left_out(short_run):
    """With ``submaps.blamed_scans: leave_out``, a scan the gating excluded is
    neither matched nor inserted: no local match, submap constraint (kept or
    dropped), between factor or loop rests on it. With ``keep`` they do."""
    traces, blamed = _traces_of_blamed_scans(short_run, "leave_out")
    assert traces == 0 and blamed > 0
    kept, _ = _traces_of_blamed_scans(short_run, "keep")
    assert kept > 0


def test_the_path_on_dead_reckoning_alone_may_drift_as_the_odometry_does():
    from types import SimpleNamespace

    from slam.config.submaps import RecognitionConfig
    from slam.submaps.graph import LocalFeed, drift_allowance
    from slam.submaps.local import LocalStep

    laser = RecognitionConfig()
    assert drift_allowance(laser, 50.0, 20.0) == (laser.max_drift_per_m * 50.0, laser.max_turn_per_m_deg * 50.0)
    blind = RecognitionConfig(blind_drift_per_m=0.6, blind_turn_per_m_deg=4.0)
    assert drift_allowance(blind, 50.0, 0.0) == drift_allowance(laser, 50.0, 0.0)
    drift_m, turn_deg = drift_allowance(blind, 50.0, 20.0)  # 30 m on the laser, 20 m on odometry alone
    assert drift_m == pytest.approx(0.1 * 30.0 + 0.6 * 20.0) and turn_deg == pytest.approx(1.0 * 30.0 + 4.0 * 20.0)

    # A node's scan with too few points to match (left out, or the laser
    # blind) was reached on dead reckoning: the steps into it count.
    poses = np.column_stack([np.arange(6.0), np.zeros(6), np.zeros(6)])
    sizes = [100, 100, 0, 3, 100, 0]
    points = SimpleNamespace(points=[np.zeros((k, 2)) for k in sizes])
    steps = iter([LocalStep(i, poses[i], None, ((0, poses[i], float(i > 0)),), ()) for i in range(6)] + [None])
    feed = LocalFeed(points, 6, SubmapsConfig(enabled=True).min_points, steps.__next__)
    feed.advance(5)
    assert feed.path.tolist() == [0, 1, 2, 3, 4, 5]
    assert feed.blind_path.tolist() == [0, 0, 1, 2, 2, 3]
    feed.end()
    assert feed.finishing == [0] and feed.submaps[0].scans == list(range(6))


def test_a_loop_within_what_was_mapped_after_a_blind_stretch_pins_none_of_its_drift():
    """Nodes 0-9, the steps into 3, 4 and 5 on dead reckoning alone (1 m
    each). A loop from node 9 to a submap of nodes 6-7 (mapped after the
    stretch) leaves its 3 m unpinned; one to a submap of nodes 0-2 pins it."""
    from types import SimpleNamespace

    from slam.submaps.graph import UnpinnedPath
    from slam.submaps.local import Submap

    blind_path = np.array([0, 0, 0, 1, 2, 3, 3, 3, 3, 3], dtype=float)
    sizes = [100, 100, 100, 0, 0, 0, 100, 100, 100, 100]
    points = SimpleNamespace(points=[np.zeros((k, 2)) for k in sizes])

    def submap(scans, blind_too=()):
        sm = Submap()
        for k in [*blind_too, *scans]:
            sm.insert(k, np.zeros(3), 1.0)
        return sm

    path = UnpinnedPath(blind_path, points, min_points=20)
    for i in range(10):
        path.reach(i)
    assert path.at.tolist() == blind_path.tolist()
    path.tie(9, submap([6, 7], blind_too=[5]))  # its blind scan 5 holds nothing
    assert path.at[9] == 3.0
    path.tie(9, submap([0, 1, 2]))
    assert path.at[9] == 0.0


@pytest.mark.parametrize("constraints", [{}, {"max_distance_m": 1e-3}], ids=["near", "recognised"])
def test_the_walk_beside_local_slam_gives_the_same_result_to_the_bit(constraints):
    """The walk following local SLAM in a second process reads only what
    local SLAM had done by each scan: the result is the plain order's."""
    from slam.processes.background import can_fork

    if not can_fork():
        pytest.skip("no fork here: the walk runs after local SLAM in this process")
    rng = np.random.default_rng(11)
    truth = ring_path(0.7, 2.0)
    scans = simulate(building(), truth, rng)
    steps, cov = drifting_odometry(truth, rng)
    fe = FrontendConfig(max_range_m=50.0)
    cfg = SubmapsConfig.model_validate({"enabled": True, "constraints": constraints,
                                        "recognition": {"min_path_m": 10.0}})
    plain, beside = (build_submap_constraints(scans, np.arange(len(truth)), steps, cov, fe, cfg, concurrent=c)
                     for c in (False, True))
    assert plain.of_kind("near", "loop")  # the walk found something to agree on
    assert plain.estimate.tobytes() == beside.estimate.tobytes()
    assert plain.searches == beside.searches
    for found in ("constraints", "dropped"):
        a, b = getattr(plain, found), getattr(beside, found)
        assert [(c.submap, c.anchor, c.scan, c.kind, c.score) for c in a] == [(c.submap, c.anchor, c.scan, c.kind, c.score) for c in b]
        assert all(x.delta.tobytes() == y.delta.tobytes() and x.information.tobytes() == y.information.tobytes()
                   for x, y in zip(a, b))


def _blamed_core(short_run, blamed_scans: str, monkeypatch=None, figures=None):
    """The short run up to its back end, the scan matching of every fourth
    keyframe (from the tenth) excluded; ``figures``: the return cells and
    free-space figure each pass reports, by the mode it was mapped with."""
    from slam.config import load_config
    from slam.pipeline.core import Mapping
    from slam.readers.read import read_recording
    from tests.conftest import TELEMAX_CONFIG

    config = load_config(TELEMAX_CONFIG, ["output.plots=false", f"submaps.blamed_scans={blamed_scans}"])
    core = Mapping(read_recording(short_run.run_dir, config.input), config, source=short_run.run_dir)
    core.match_scans()
    core.build_measurements()
    core.validate()
    sm = np.array(core.weights["scan_matching"], dtype=float)
    sm[10::4] = np.inf
    core.weights["scan_matching"] = sm
    if figures is not None:
        passes = []
        build = core.build_submaps

        def build_and_note(before_judging=None, blamed_mode=None):
            passes.append(blamed_mode)
            build(before_judging, blamed_mode)

        monkeypatch.setattr(core, "build_submaps", build_and_note)
        monkeypatch.setattr(core, "_map_figures", lambda: figures[passes[-1]])
        core.passes = passes
    core.map_back_end()
    return core


@pytest.mark.slow
@pytest.mark.parametrize("better", ["keep", "leave_out"])
def test_choose_keeps_the_map_whose_returns_take_fewer_cells(short_run, monkeypatch, better):
    """``submaps.blamed_scans: choose`` maps both ways and ends with the
    map, loops and metrics of the one whose returns land in fewer cells,
    whatever the free-space figure says: the same estimate to the bit as
    that mode alone."""
    other = "leave_out" if better == "keep" else "keep"
    figures = {better: (1000, 0.3), other: (1001, 0.2)}
    chosen = _blamed_core(short_run, "choose", monkeypatch, figures)
    assert set(chosen.passes) == {"keep", "leave_out"} and chosen.passes[-1] == better
    assert chosen.extra_metrics["blamed_scans"] == {
        "chosen": better, "return_cells": {better: 1000, other: 1001},
        "free_space_returns": {better: 0.3, other: 0.2}}
    alone = _blamed_core(short_run, better)
    assert np.array_equal(chosen.backend.trajectory.x, alone.backend.trajectory.x)
    assert np.array_equal(chosen.backend.trajectory.yaw, alone.backend.trajectory.yaw)
    assert len(chosen.constraints) == len(alone.constraints)


def test_the_submap_constraints_take_their_own_gating_where_given():
    """``gating.factors.submaps``: the submap constraints' degrees of freedom
    gated apart from scan matching's (slam.pipeline.core.submap_factors);
    without it they take scan matching's."""
    from types import SimpleNamespace

    from slam.pipeline.core import submap_factors

    c = SimpleNamespace(kind="intra", anchor=0, scan=3, submap=0, delta=np.array([1.0, 0.0, 0.1]),
                        information=np.diag([100.0, 100.0, 400.0]))
    submaps = SimpleNamespace(of_kind=lambda *kinds: [c], submap_keyframes=lambda s: np.arange(0, 3))
    n = 4
    sm = np.ones((n, 3))
    sm[1, 2] = np.inf  # the scan matcher's yaw excluded at keyframe 1 (the odometry's slip it followed)
    plain = submap_factors(submaps, {"scan_matching": sm}, n)
    assert plain[0].information[2, 2] == 0.0 and plain[0].information[0, 0] == 100.0
    own = submap_factors(submaps, {"scan_matching": sm}, n, own=np.ones((n, 3)))
    assert np.array_equal(own[0].information, c.information)
    blamed_own = np.ones((n, 3))
    blamed_own[2] = np.inf  # the whole scan out: nothing of the constraint is left
    assert submap_factors(submaps, {"scan_matching": sm}, n, own=blamed_own) == []


def _witness_config(tmp_path, *overrides):
    """configs/telemax.yaml with one more relation: the odometry's turns
    against local SLAM's (``sub_yaw``), in a model that names it."""
    import yaml

    from slam.config import load_config
    from tests.conftest import CONFIGS, TELEMAX_CONFIG

    model = yaml.safe_load((CONFIGS / "validation" / "telemax_model.yaml").read_text())
    model["components"].append("SUB_YAW")
    model["relations"]["yaw_odo_sub"] = ["ODO_YAW", "SUB_YAW"]
    (tmp_path / "model.yaml").write_text(yaml.safe_dump(model))
    tree = yaml.safe_load(TELEMAX_CONFIG.read_text())
    tree["validation"]["model"] = str(tmp_path / "model.yaml")
    tree["validation"]["observers"]["relations"].append(
        {"name": "yaw_odo_sub", "stream_a": "odo_yaw", "stream_b": "sub_yaw", "boundary": 0.05, "window_s": 2.0,
         "threshold": 10})
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(tree))
    return load_config(tmp_path / "c.yaml", ["output.plots=false", "validation.mode=on", *overrides])


def test_the_validator_weighs_local_slam_as_a_sensor_where_an_observer_asks(short_run, tmp_path):
    """A relation on a ``sub_*`` stream makes local SLAM run before the
    validation (slam.pipeline.core.Mapping.witness), along the ungated
    chain; its turns agree with the odometry's on a healthy stretch. A run
    without the front-end cannot make it: one line says so."""
    from slam.pipeline.core import Mapping
    from slam.readers.read import read_recording

    config = _witness_config(tmp_path)
    core = Mapping(read_recording(short_run.run_dir, config.input), config, source=short_run.run_dir)
    core.match_scans()
    core.build_measurements()
    core.validate()
    trace = core.validation.observer_log.relations["yaw_odo_sub"]
    assert trace.valid.mean() > 0.8
    assert trace.no_match[trace.valid].mean() < 0.1

    from slam.commands.calibrate.runs import load_run
    from slam.config import validation_sections

    calibrated = load_run(short_run.run_dir, config, validation_sections(config)[0], None)
    assert "sub_yaw" in calibrated.streams  # gslam calibrate learns its relations too

    blind = _witness_config(tmp_path, "frontend.enabled=false", "backend.factors.scan_matching.enabled=false")
    core = Mapping(read_recording(short_run.run_dir, blind.input), blind, source=short_run.run_dir)
    core.match_scans()
    core.build_measurements()
    with pytest.raises(GslamError, match=r"compare stream sub_\*, local SLAM's submap match, which needs the scans"):
        core.validate()
