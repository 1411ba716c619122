"""The scan check: the front-end's figures per scan (returns, conditioning
of the point-to-line information) and the unary check that turns them into
IMPLAUSIBLE for the scan-matching modalities a scan cannot constrain."""

from __future__ import annotations

import numpy as np
import pytest

from slam.config import FrontendConfig, load_config
from slam.frontend.kiss import scan_quality
from slam.frontend.scan_geometry import range_ceiling
from slam.commands.inject import inject
from slam.commands.inject import physics
from slam.commands.inject.spec import parse_fault
from slam.pipeline.folder import run_map
from slam.recording import Scans
from tests.conftest import TELEMAX_CONFIG
from tests.synthetic import wall_ranges
from validation.diagnosis.model import Plausibility
from validation.base.errors import ValidationError
from validation.observers import ObserversConfig, observe_steps
from validation.observers.checks import ScanCeilingCheck, ScanDegeneracyCheck, bridged, scan_streams, settled, unary_checks
from validation.observers.config import observers_config
from validation.streams import resample_streams


CORRIDOR = [(0.0, 1.0, 1.5), (0.0, -1.0, 1.5)]
ROOM = [*CORRIDOR, (1.0, 0.0, 3.0), (-1.0, 0.0, 2.0)]


def _scans(kinds: list[str]) -> Scans:
    """One scan a second: ``room``, ``corridor`` (walls left and right) or ``blind``."""
    rows = []
    for kind in kinds:
        r, angles = wall_ranges(ROOM if kind != "corridor" else CORRIDOR)
        rows.append(np.full_like(r, np.inf) if kind == "blind" else r)
    return Scans(np.arange(len(kinds), dtype=float), np.array(rows, dtype=np.float32), angles, 0.1, 30.0)


def _checks() -> list[ScanDegeneracyCheck]:
    cfg = observers_config({"scan": {"enabled": True}, "magnetometer": {"enabled": False}, "gps": {"enabled": False}})
    return unary_checks(cfg)


def test_the_front_end_figures_say_which_direction_a_scan_leaves_free():
    q = scan_quality(_scans(["room", "corridor", "blind"]), FrontendConfig(max_range_m=30.0))
    assert q.returns[0] == 360 and q.returns[2] == 0
    assert q.min_eigenvalue[0] > 0.03 and q.min_eigenvalue[1] < 1e-6
    assert abs(q.weak[1, 0]) == pytest.approx(1.0, abs=1e-6)  # the corridor leaves the forward motion free
    flags = {c.component: c.flags(q).tolist() for c in _checks()}
    assert flags == {"SM_DIST": [False, True, True], "SM_LAT": [False, False, True], "SM_YAW": [False, False, True]}


def test_the_check_and_the_injected_labels_share_one_criterion():
    """The labels of ``gslam inject``'s laser cut are the check's verdict on
    the cut scans: its recall against them is a consistency check."""
    scans = _scans(["room", "room", "corridor", "room"])
    cut = physics.cut_ranges(scans.ranges, 1.6, np.inf)  # keeps the corridor's walls only
    labels = physics.laser_labels(cut, scans.angles, 0.0, 30.0, parse_fault("laser_cut@0:3,range_m=1.6"))
    q = scan_quality(Scans(scans.t, cut, scans.angles, 0.0, 30.0), FrontendConfig(min_range_m=0.0, max_range_m=30.0))
    assert {c.component: c.flags(q).tolist() for c in _checks()} == {m: v.tolist() for m, v in labels.items()}


def test_a_degenerate_scan_makes_both_motions_at_it_implausible_for_its_modality_only():
    checks = _checks()
    q = scan_quality(_scans(["room", "room", "corridor", "room", "room"]), FrontendConfig(max_range_m=30.0))
    step_t = np.arange(0.0, 4.01, 0.1)
    steps = resample_streams(scan_streams(checks, q), step_t, max_gap_s=1.5)
    log = observe_steps(steps, (), checks)
    bad = {c.component: np.array([log.observations(k)[c.name] is Plausibility.IMPLAUSIBLE for k in range(len(step_t))])
           for c in checks}
    # Scan 2 (t = 2 s) is a corridor: the motions from scan 1 and to scan 3 lose their distance.
    assert step_t[bad["SM_DIST"]] == pytest.approx(np.arange(1.1, 2.95, 0.1))
    assert not bad["SM_LAT"].any() and not bad["SM_YAW"].any()


def test_without_scans_the_check_has_no_stream_and_names_stay_unique():
    assert scan_streams(_checks(), None) == {}
    assert unary_checks(ObserversConfig()) and not any(isinstance(c, ScanDegeneracyCheck) for c in unary_checks(ObserversConfig()))
    with pytest.raises(ValidationError, match="scan_degenerate_dist"):
        observers_config({"gps": {"name": "scan_degenerate_dist"}, "scan": {"enabled": True}})


@pytest.mark.slow
def test_the_check_blames_scan_matching_where_the_laser_is_cut(short_run, tmp_path):
    cfg = load_config(TELEMAX_CONFIG, ["validation.mode=on", "validation.observers.relations=[]",
                                       "validation.observers.magnetometer.enabled=false",
                                       "validation.observers.gps.enabled=false",
                                       "validation.observers.scan.enabled=true", "output.plots=false"])
    cut = inject(short_run.run_dir, ["laser_cut@16:20,range_m=0.3"], tmp_path / "cut", cfg.input).run_dir
    out = run_map(cut, cfg, tmp_path / "map")
    log = out.validation.observer_log
    implausible = log.unary["scan_degenerate_dist"].implausible
    assert implausible[(log.t > 16.2) & (log.t < 19.8)].all() and not implausible[log.t < 15.0].any()
    assert out.metrics["blamed_steps"].get("SM_DIST", 0) >= 30
    assert out.metrics["observer_coverage"]["scan_degenerate_dist"] > 0.9


def _ceiling_check(**kw) -> ScanCeilingCheck:
    cfg = observers_config({"scan_ceiling": {"enabled": True, **kw}, "magnetometer": {"enabled": False},
                            "gps": {"enabled": False}})
    return next(c for c in unary_checks(cfg) if isinstance(c, ScanCeilingCheck))


def test_a_scan_cut_at_a_range_ends_in_gaps_at_its_farthest_return():
    """A room 3 m by 5 m seen whole, then cut at 2.5 m: the cut scan loses
    the far walls, and every gap it leaves is bordered by returns just short
    of the cut. A window in the side wall (no return through glass) is a gap
    too, but its edges are at the wall, far short of the farthest return."""
    room, angles = wall_ranges(ROOM)
    cut = np.where(room > 2.5, np.inf, room)
    window = np.where(np.abs(angles - np.pi / 2) < 0.3, np.inf, room)
    no_return, edges, share, farthest = range_ceiling(np.vstack([room, cut, window]), 0.1, 30.0)
    assert no_return[0] == 0.0 and edges[0] == 0
    assert no_return[1] > 0.15 and edges[1] >= 2 and share[1] == 1.0
    assert no_return[2] > 0.05 and edges[2] == 2 and share[2] == 0.0
    assert farthest[1] == pytest.approx(2.5, abs=0.05)


def test_the_ceiling_check_flags_cut_scans_and_bridges_short_gaps():
    scans = _scans(["room"] * 6)
    r = scans.ranges.copy()
    r[[1, 3, 4]] = np.where(r[[1, 3, 4]] > 1.8, np.inf, r[[1, 3, 4]])
    q = scan_quality(Scans(scans.t, r, scans.angles, 0.1, 30.0), FrontendConfig(max_range_m=30.0))
    assert _ceiling_check().flags(q).tolist() == [False, True, False, True, True, False]
    # Scan 2 lies between two cut scans 2 s apart: a range limit persists.
    assert _ceiling_check(fill_s=2.0).flags(q).tolist() == [False, True, True, True, True, False]
    assert bridged(np.arange(5.0), np.array([1, 0, 0, 0, 1], bool), 3.0).tolist() == [True, False, False, False, True]
    # The scan matcher settles for 1.5 s after the laser sees again: scan 5 is 1 s after scan 4.
    assert _ceiling_check(settle_s=1.5).flags(q).tolist() == [False, True, True, True, True, True]
    assert settled(np.arange(6.0), np.array([0, 1, 0, 0, 0, 0], bool), 2.0).tolist() == [False, True, True, False, False, False]
    # One scan cut off (a wall in front of the laser) is no cut to settle from; two seconds of them are.
    assert not settled(np.arange(6.0), np.array([0, 1, 0, 0, 0, 0], bool), 2.0, 2.0)[2:].any()
    assert settled(np.arange(6.0), np.array([1, 1, 1, 0, 0, 0], bool), 2.0, 2.0).tolist() == [True] * 4 + [False] * 2
    assert _ceiling_check(settle_s=1.5, settle_after_s=1.0).flags(q).tolist() == [False, True, False, True, True, True]
    # The same room ten times larger, cut at 18 m: the laser still sees a hall.
    hall = Scans(scans.t, 10.0 * scans.ranges, scans.angles, 0.1, 80.0)
    hall.ranges[[1, 3, 4]] = np.where(hall.ranges[[1, 3, 4]] > 18.0, np.inf, hall.ranges[[1, 3, 4]])
    q = scan_quality(hall, FrontendConfig(max_range_m=80.0))
    assert not _ceiling_check().flags(q).any()
    assert _ceiling_check(max_ceiling_m=20.0).flags(q).tolist() == [False, True, False, True, True, False]


def test_a_laser_whose_reach_ends_in_the_gaps_is_not_cut_off():
    """The room five times larger, seen by a laser of 10 m range: its far
    walls lie beyond the laser's reach, so every scan ends in gaps at about
    10 m, as a cut one does. The laser sees what it can: no cut. The same
    scans cut at 8.5 m are cut off, and so is the room seen by a 30 m laser
    and cut at 9.5 m, far short of that laser's reach (unless a cut must
    be within 0.3 of the reach, 9 m)."""
    scans = _scans(["room"] * 4)
    big = np.where(5.0 * scans.ranges >= 10.0, np.inf, 5.0 * scans.ranges)
    q = scan_quality(Scans(scans.t, big, scans.angles, 0.1, 10.0), FrontendConfig(max_range_m=30.0))
    assert q.reach_m == 10.0 and np.all(q.no_return > 0.1) and np.all(q.edges_at_ceiling == 1.0)
    assert not _ceiling_check().flags(q).any()
    cut = np.where(big > 8.5, np.inf, big)
    q = scan_quality(Scans(scans.t, cut, scans.angles, 0.1, 10.0), FrontendConfig(max_range_m=30.0))
    assert _ceiling_check().flags(q).all()
    cut = np.where(5.0 * scans.ranges > 9.5, np.inf, 5.0 * scans.ranges)
    q = scan_quality(Scans(scans.t, cut, scans.angles, 0.1, 30.0), FrontendConfig(max_range_m=30.0))
    assert _ceiling_check().flags(q).all() and not _ceiling_check(reach_share=0.3).flags(q).any()


def test_the_ceiling_check_names_the_whole_scan_matcher_in_the_model():
    from validation.config import parse_sections

    model = {"components": ["ODO_DIST", "SM_DIST", "SM"], "sensors": {"SM": ["SM_DIST"]},
             "relations": {"distance_odo_sm": ["ODO_DIST", "SM_DIST"]}, "unary_checks": {"scan_ceiling": "SM_DIST"}}
    section = {"mode": "on", "model": model, "observers": {
        "relations": [{"name": "distance_odo_sm", "stream_a": "odo_distance", "stream_b": "sm_distance",
                       "window_s": 2.0, "boundary": 0.1, "threshold": 10, "max_counter": 30}],
        "magnetometer": {"enabled": False}, "gps": {"enabled": False}, "scan_ceiling": {"enabled": True}}}
    with pytest.raises(ValidationError, match="scan_ceiling.*tests SM, the model says SM_DIST"):
        parse_sections(section, {"factors": {"scan_matching": {"x": ["SM_DIST"]}}})
