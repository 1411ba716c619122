"""The grid of finished submaps' centres finds what a scan over all of them finds."""

import numpy as np

from slam.submaps.near import NearSubmaps


def brute_force(ids, xy, p, radius):
    dist = np.hypot(*(np.asarray(xy) - p).T)
    order = [k for k in np.argsort(dist, kind="stable") if dist[k] <= radius]
    return np.asarray(ids)[order], dist[order]


def test_within_matches_a_scan_over_all_submaps():
    rng = np.random.default_rng(3)
    xy = rng.uniform(-40, 40, size=(300, 2))
    ids = list(range(100, 400))
    index = NearSubmaps(10.0)
    index.place(ids[:200], xy[:200])
    for sid, centre in zip(ids[200:], xy[200:]):
        index.add(sid, centre)
    for p in rng.uniform(-50, 50, size=(100, 2)):
        got_ids, got_dist = index.within(p, 10.0)
        want_ids, want_dist = brute_force(ids, xy, p, 10.0)
        assert got_ids.tolist() == want_ids.tolist()
        assert np.array_equal(got_dist, want_dist)


def test_place_replaces_and_a_point_on_the_rim_counts():
    index = NearSubmaps(5.0)
    index.place([0, 1], np.array([[0.0, 0.0], [100.0, 0.0]]))
    index.place([2], np.array([[5.0, 0.0]]))
    ids, dist = index.within(np.zeros(2), 5.0)
    assert ids.tolist() == [2] and dist.tolist() == [5.0]
    assert len(index.within(np.array([100.0, 0.0]), 5.0)[0]) == 0


def test_equal_distances_keep_the_order_added():
    index = NearSubmaps(2.0)
    index.place([7, 3, 5], np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0]]))
    assert index.within(np.zeros(2), 1.0)[0].tolist() == [7, 3, 5]


def test_adding_after_placing_none_finds_each():
    index = NearSubmaps(3.0)
    index.place([], np.zeros((0, 2)))
    assert len(index.within(np.zeros(2), 3.0)[0]) == 0
    for sid in range(40):  # past the first room made
        index.add(sid, np.array([0.1 * sid, 0.0]))
    ids, dist = index.within(np.zeros(2), 1.0)
    assert ids.tolist() == list(range(11)) and np.allclose(dist, 0.1 * np.arange(11))
