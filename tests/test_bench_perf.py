"""The perf bench's pieces that need no run: KISS-ICP alone's CARMEN
reading and the speed section's ratios."""

import gzip

import pytest

import numpy as np

from scripts.bench.kiss_only import carmen_scans, is_carmen
from scripts.bench.perf.speed import Sample, report


def test_carmen_scans_reads_flaser_lines(tmp_path):
    log = tmp_path / "tiny-corrected.log.gz"
    lines = [
        "PARAM laser_front_laser_fov 180 nohost 0",
        "FLASER 3 1.0 2.0 3.0 0 0 0 0 0 0 10.5 host 10.5",
        "ODOM 0 0 0 0 0 0 10.6 host 10.6",
        "FLASER 3 4.0 5.0 6.0 0 0 0 0 0 0 11.0 host 11.0",
    ]
    with gzip.open(log, "wt") as f:
        f.write("\n".join(lines) + "\n")
    assert is_carmen(log)
    stamps, angles, ranges = carmen_scans(log)
    assert stamps.tolist() == [10.5, 11.0]
    assert np.allclose(angles, [-np.pi / 2, 0.0, np.pi / 2])
    assert [r.tolist() for r in ranges] == [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]


def test_speed_report_says_the_ratio_to_kiss_slam_and_the_real_time_factor():
    samples = []
    for rnd, (gslam, kiss, peer) in enumerate([(10.0, 4.0, 20.0), (12.0, 4.0, 20.0), (11.0, 5.0, 10.0)], start=1):
        samples += [Sample("intel", "gslam", rnd, gslam, gslam, 0.0, duration_s=1000.0),
                    Sample("intel", "kiss 1 thread", rnd, kiss, kiss, 0.0, duration_s=1000.0),
                    Sample("intel", "kiss-slam", rnd, peer, peer, 0.0, duration_s=1000.0)]
    text = report(samples, ["kiss 1 thread", "gslam", "kiss-slam"], {}, "note", {"intel": "carmen"})
    # Per-round ratios 0.5, 0.6, 1.1: their median, not the ratio of medians.
    assert "- intel, gslam against kiss-slam: 0.60 (worst round 1.10; below the target 1)" in text
    assert "- intel, gslam real-time factor 91x (at least the target 60x)" in text
    assert "against kiss 1 thread" not in text  # its target is the simulated runs'
    lab = report([Sample("lab", p.program, p.round, p.wall_s, p.cpu_s, 0.0, duration_s=220.0) for p in samples],
                 ["kiss 1 thread", "gslam", "kiss-slam"], {}, "note", {"lab": "simulated"})
    assert "- lab, gslam against kiss 1 thread: 2.50 (above the target 1.5)" in lab
    assert "- lab, gslam real-time factor 20x (below the target 80x)" in lab


def test_carmen_inputs_come_from_the_data_folder(tmp_path, monkeypatch):
    """The speed section's CARMEN logs are read where GSLAM_DATA says; a
    folder without any is refused by name, not skipped in silence."""
    from scripts.bench.perf.speed import carmen_inputs
    from slam.errors import GslamError

    monkeypatch.setenv("GSLAM_DATA", str(tmp_path))
    with pytest.raises(GslamError, match=str(tmp_path / "carmen")):
        carmen_inputs()


def test_timed_programs_keep_their_bytecode_in_the_bench_folder(tmp_path, monkeypatch):
    # A host that forbids bytecode caches would have every timed gslam
    # process compile the project again; the bench times them as a user's
    # machine runs them, with the caches kept in its own folder.
    import subprocess
    import sys

    from scripts.bench.perf import speed

    monkeypatch.setenv("PYTHONDONTWRITEBYTECODE", "1")
    monkeypatch.setitem(speed.BYTECODE_ENV, "PYTHONPYCACHEPREFIX", str(tmp_path / "pycache"))
    code = "import sys; print(sys.flags.dont_write_bytecode, sys.pycache_prefix)"
    out = subprocess.run([sys.executable, "-c", code], env=speed.timed_env(), capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["0", str(tmp_path / "pycache")]
    monkeypatch.delitem(speed.BYTECODE_ENV, "PYTHONPYCACHEPREFIX")
    assert speed.timed_env()["PYTHONDONTWRITEBYTECODE"] == "1"  # untouched outside the perf bench


def test_a_run_of_some_sections_leaves_the_published_page_alone(tmp_path, monkeypatch):
    # docs/results/perf.md holds every section; a run of one section must
    # not replace it with that section alone.
    from scripts.bench import common
    from scripts.bench.perf import SECTIONS, write_page

    monkeypatch.setattr(common, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(common, "commit", lambda: "abc")
    written = write_page("ratio figures\n", ["--sections", "ratio"], ["ratio"], tmp_path / "out")
    assert written == tmp_path / "out" / "perf.md"
    assert not (tmp_path / "results").exists()
    assert "ratio figures" in written.read_text() and "--sections ratio" in written.read_text()
    monkeypatch.setattr(common, "REPO", tmp_path)
    assert write_page("every figure\n", [], list(SECTIONS), tmp_path / "out") == tmp_path / "results" / "perf.md"
