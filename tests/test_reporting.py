"""What a result says about itself: the comparison table's missed faults and
false alarms, one runtime figure with its definition, fault bands only from
the recording's truth, the real-time factor only on real stamps, progress
bars only on a terminal, and report.html's provenance."""

from __future__ import annotations

import csv
import hashlib
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import slam.outputs.plots
from conftest import TELEMAX_CONFIG, real_data
from slam.cli import main
from slam.config import dump_config, load_config
from slam.outputs.provenance import UNKNOWN, command_line, git_commit
from slam.pipeline.folder import realtime_factor, run_map
from slam.readers.carmen import read_carmen
from slam.readers.read import load_sidecar
from test_carmen import three_scan_log, write

REPO = Path(__file__).resolve().parents[1]
# What a tqdm bar writes: carriage returns and its "| n/N [" counter.
BAR = re.compile(r"\r|\d+%\||\| *\d+/\d+ \[")


@pytest.fixture(scope="module")
def compared(short_run, tmp_path_factory):
    """gslam compare of the short run, ungated and gated, as the CLI runs it."""
    out = tmp_path_factory.mktemp("reporting") / "cmp"
    argv = ["-q", "compare", str(short_run.run_dir), "--config", str(TELEMAX_CONFIG), "--out", str(out),
            "--only", "ungated,gated"]
    assert main(argv) == 0
    return out, argv


def metrics_of(folder: Path) -> dict:
    return json.loads((folder / "metrics.json").read_text())


def table_rows(markdown: str) -> dict[str, dict[str, str]]:
    """comparison.md's table: variant -> header -> cell."""
    lines = [ln for ln in markdown.splitlines() if ln.startswith("| ")]
    headers = [h.strip() for h in lines[0].strip("|").split("|")]
    rows = [[c.strip() for c in ln.strip("|").split("|")] for ln in lines[1:]]
    return {r[0]: dict(zip(headers, r)) for r in rows}


# --- 1. the table: missed faults and false alarms -----------------------------


def test_the_table_shows_missed_faults_and_false_alarms_from_metrics_json(compared):
    out, _ = compared
    md = (out / "comparison.md").read_text()
    rows = table_rows(md)
    gated, ungated = metrics_of(out / "gated"), rows["ungated"]
    missed, detected = gated["faults_missed"], gated["faults_detected"]
    assert missed is not None and detected is not None
    assert rows["gated"]["faults missed"] == f"{missed} of {missed + detected}"
    assert rows["gated"]["false alarm fraction"] == f"{gated['false_alarm_fraction']:.3f}"
    assert ungated["faults missed"] == "–" and ungated["false alarm fraction"] == "–"  # no validation, no figure
    assert "- faults missed: " in md and "- false alarm fraction: " in md  # defined under the table
    csv_rows = {r["variant"]: r for r in csv.DictReader((out / "comparison.csv").open())}
    assert int(csv_rows["gated"]["faults_missed"]) == missed
    assert csv_rows["ungated"]["faults_missed"] == ""


# --- 4. one runtime figure ------------------------------------------------------


def test_the_tables_runtime_is_metrics_jsons_runtime_with_shared_s(compared):
    out, _ = compared
    md = (out / "comparison.md").read_text()
    rows = table_rows(md)
    first, second = metrics_of(out / "ungated"), metrics_of(out / "gated")
    for name, m in (("ungated", first), ("gated", second)):
        assert rows[name]["runtime [s]"] == f"{m['runtime_with_shared_s']:.2f}"
        # duration_s is rounded to the millisecond: the factor's last digit may differ
        assert m["realtime_factor"] == pytest.approx(m["duration_s"] / m["runtime_with_shared_s"], abs=0.011)
    # The first variant read and matched the scans; the second reused them and counts their seconds in.
    assert first["runtime_with_shared_s"] == first["runtime_s"]
    shared = first["timings_s"]["read"] + first["timings_s"]["frontend"]
    assert second["timings_s"]["read"] == 0.0 and second["timings_s"]["frontend"] == 0.0
    assert second["runtime_with_shared_s"] == pytest.approx(second["runtime_s"] + shared, abs=2e-4)
    assert "- runtime [s]: runtime_with_shared_s, " in md


# --- 2. fault bands only from truth -------------------------------------------


def legends(figures) -> list[str]:
    return [t.get_text() for fig in figures for ax in fig.axes if ax.get_legend() is not None
            for t in ax.get_legend().get_texts()]


def map_capturing(monkeypatch, source: Path, out: Path):
    """Map ``source`` in this process, its figures collected instead of
    saved; scan matching judged wrong against ground truth almost everywhere
    (1 mm), so the pipeline's own fault labels are there to be left out."""
    figures: list = []
    monkeypatch.setattr(slam.outputs.plots, "save_figure", lambda fig, path: figures.append(fig))
    config = load_config(TELEMAX_CONFIG, ["evaluation.sm_fault_trans_m=0.001"])
    return run_map(source, config, out, concurrent=False), figures


@pytest.mark.slow
def test_a_run_without_truth_draws_no_true_fault(short_run, tmp_path, monkeypatch):
    res, figures = map_capturing(monkeypatch, short_run.run_dir / "bag", tmp_path / "bare")  # the bag alone
    assert res.recording.fault_truth is None
    assert any(res.recording.faults.get(c) for c in ("SM_DIST", "SM_LAT"))  # labelled by the pipeline, not truth
    drawn = legends(figures)
    assert "estimate" in drawn
    assert not [label for label in drawn if label.startswith("true ")]


@pytest.mark.slow
def test_fault_bands_are_truth_jsons_intervals(short_run, tmp_path, monkeypatch):
    res, figures = map_capturing(monkeypatch, short_run.run_dir, tmp_path / "folder")
    rec = res.recording
    sidecar = load_sidecar(short_run.run_dir / "truth.json")
    shift = sidecar.t0 - rec.t0
    truth = {c: [(a + shift, b + shift) for a, b in iv] for c, iv in sidecar.faults.items() if iv}
    assert truth and set(truth) == {"IMU_YAW"}
    assert any(rec.faults.get(c) for c in ("SM_DIST", "SM_LAT"))  # more than the truth, none of it drawn
    (trajectory,) = [fig for fig in figures if "true IMU_YAW fault" in legends([fig])]
    bands = {ln.get_label(): ln for ln in trajectory.axes[0].get_lines() if ln.get_label().startswith("true ")}
    assert set(bands) == {f"true {c} fault" for c in truth}
    ref = rec.groundtruth
    inside = np.zeros(len(ref), dtype=bool)
    for a, b in truth["IMU_YAW"]:
        inside |= (ref.t >= a) & (ref.t <= b)
    x = np.asarray(bands["true IMU_YAW fault"].get_xdata(), dtype=float)
    np.testing.assert_array_equal(x[np.isfinite(x)], ref.x[inside])


# --- 3. the real-time factor only on real stamps ----------------------------------


def test_synthesised_stamps_give_no_realtime_factor_but_a_reason(tmp_path):
    made_up = read_carmen(write(tmp_path / "zero.log", three_scan_log(stamps=(0, 0, 0))))
    assert "synthesised" in made_up.stamps_synthesised
    factor = realtime_factor(made_up, 0.5)
    assert factor["realtime_factor"] is None and "synthesised" in factor["realtime_factor_unavailable"]
    real = read_carmen(write(tmp_path / "real.log", three_scan_log()))
    assert real.stamps_synthesised is None
    assert realtime_factor(real, 0.5) == {"realtime_factor": round(real.duration / 0.5, 2)}


@pytest.mark.slow
def test_a_log_with_synthesised_stamps_maps_without_a_realtime_factor(tmp_path, capsys):
    """orebro's stamps are all zero: its first 40 scans mapped, metrics.json
    and the terminal say why there is no factor."""
    import gzip

    lines, scans = [], 0
    with gzip.open(real_data("carmen/orebro-corrected.log.gz"), "rt") as f:
        for line in f:
            scans += line.startswith("FLASER")
            if scans > 40:
                break
            lines.append(line)
    log = tmp_path / "orebro40.log"
    log.write_text("".join(lines))
    code = main(["-q", "map", str(log), "--config", "configs/datasets/carmen.yaml", "--out", str(tmp_path / "m")])
    assert code == 0
    m = metrics_of(tmp_path / "m")
    assert m["realtime_factor"] is None and "synthesised" in m["realtime_factor_unavailable"]
    printed = capsys.readouterr().out
    assert '"realtime_factor": null' in printed and '"realtime_factor_unavailable": ' in printed


# --- 5. no progress bar into a pipe -------------------------------------------------


def gslam(*argv: str) -> subprocess.CompletedProcess:
    """gslam as a user's script runs it, its output into pipes."""
    return subprocess.run([sys.executable, "-m", "slam.cli", *argv], capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=600, cwd=REPO)


@pytest.mark.slow
def test_no_progress_bar_into_a_pipe(short_scenario_yaml, tmp_path):
    run = tmp_path / "run"
    spec = tmp_path / "spec.yaml"
    spec.write_text(yaml.safe_dump({
        "name": "tiny", "config": str(TELEMAX_CONFIG),
        "inputs": {"scenarios": [{"path": str(short_scenario_yaml), "seeds": [1]}]},
        "variants": {"ungated": {"validation.mode": "off"}},
    }))
    commands = {
        "simulate": ["simulate", str(short_scenario_yaml), "--out", str(run)],
        "map": ["map", str(run), "--config", str(TELEMAX_CONFIG), "--out", str(tmp_path / "map")],
        "compare": ["compare", str(run), "--config", str(TELEMAX_CONFIG), "--out", str(tmp_path / "cmp"),
                    "--only", "ungated,gated"],
        "ablate": ["ablate", str(spec), "--out", str(tmp_path / "sweep"), "--workers", "1"],
    }
    for name, argv in commands.items():
        done = gslam(*argv)
        assert done.returncode == 0, (name, done.stderr)
        assert not BAR.search(done.stderr), (name, done.stderr[-500:])


# --- 6. report.html's provenance ------------------------------------------------


def provenance_rows(page: str) -> dict[str, str]:
    table = page[page.index('<table class="provenance">'):]
    table = table[: table.index("</table>")]
    return dict(re.findall(r"<tr><th>([^<]*)</th><td><code>([^<]*)</code></td></tr>", table))


def test_report_names_command_version_commit_input_and_config(compared, short_run):
    from importlib import metadata

    out, argv = compared
    rows = provenance_rows((out / "report.html").read_text())
    assert rows["command"] == command_line(["gslam", *argv])
    assert rows["gated-slam version"] == metadata.version("gated-slam")
    assert rows["git commit"] == UNKNOWN or re.fullmatch(r"[0-9a-f]{40}( \+ local changes)?", rows["git commit"])
    assert rows["input"] == str(short_run.run_dir)
    assert rows["config"] == str(TELEMAX_CONFIG)
    used = dump_config(load_config(TELEMAX_CONFIG))
    assert rows["config sha256"] == hashlib.sha256(used.encode()).hexdigest()


def test_outside_a_git_checkout_the_commit_is_unknown(tmp_path):
    (tmp_path / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    assert git_commit(tmp_path) == UNKNOWN  # no .git
    (tmp_path / ".git").mkdir()
    assert git_commit(tmp_path) == UNKNOWN  # not a repository git can read
    assert git_commit(tmp_path / "missing") == UNKNOWN


def test_the_command_line_quotes_what_a_shell_would(tmp_path):
    assert command_line(["/venv/bin/gslam", "map", "a b", "--out", "x"]) == "gslam map 'a b' --out x"
