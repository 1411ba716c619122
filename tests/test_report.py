"""report.html (slam.outputs.report) of gslam compare: one file that holds the
table and every figure, checked as text and in a real headless browser."""

from __future__ import annotations

import base64
import csv
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from slam.commands.compare import run_compare
from slam.outputs.report import Figure, Section, Table, render
from tests.conftest import TELEMAX_CONFIG

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
IMAGE = re.compile(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)" alt="([^"]*)">')


@pytest.fixture(scope="module")
def compared(short_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("compare") / "cmp"
    return run_compare(short_run.run_dir, TELEMAX_CONFIG, out, only=["ungated", "gated"])


def test_render_embeds_figures_and_escapes_text(tmp_path):
    png = tmp_path / "a.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    page = render("x < y", [
        Section("s & t", "a <note>", tables=[Table(["h"], [["<b>"]])], figures=[Figure(png, "fig")]),
        Section("only missing figures", figures=[Figure(tmp_path / "none.png", "gone")]),
    ])
    assert "<title>x &lt; y</title>" in page and "<td>&lt;b&gt;</td>" in page and "a &lt;note&gt;" in page
    (data, alt), = IMAGE.findall(page)
    assert base64.b64decode(data) == png.read_bytes() and alt == "fig"
    assert "only missing figures" not in page
    assert "<script" not in page and "http" not in page  # nothing to fetch, nothing to run


@pytest.mark.slow
def test_compare_report_holds_the_table_and_every_figure(compared):
    folder = compared.out_dir
    page = (folder / "report.html").read_text()
    rows = list(csv.DictReader((folder / "comparison.csv").open()))
    for row in rows:
        ate = f"{float(row['ate_rmse_m']):.3f}"
        assert f"<tr><td>{row['variant']}</td><td>{ate}</td>" in page
    images = dict((alt, base64.b64decode(data)) for data, alt in IMAGE.findall(page))
    expected = {
        "every variant over the reference, around it": folder / "trajectories.png",
        "every variant over the reference, whole": folder / "trajectories_full.png",
        "yaw streams and trends": folder / "compass_trends.png",
        "observers": folder / "observer_alarms.png",
        "gating timeline": folder / "gating_timeline.png",
        "ungated": folder / "ungated" / "map.png",
        "gated": folder / "gated" / "map.png",
    }
    assert set(images) == set(expected)
    for alt, path in expected.items():
        assert images[alt] == path.read_bytes(), alt
    assert compared.report_s > 0


def _section(page: str, heading: str) -> str:
    """The HTML from ``heading``'s h2 to the next h2 (or the end)."""
    start = page.index(f"<h2>{heading}</h2>")
    end = page.find("<h2>", start + 1)
    return page[start:end if end > 0 else len(page)]


def _csv_spans(path: Path) -> list[tuple[str, str, str, float, float]]:
    """(factor, dof, action, from, to) of each run of exclude or inflate in
    validation.csv's gate columns, a run lasting to the next step's time."""
    rows = list(csv.DictReader(path.open()))
    t = [float(r["t"]) for r in rows]
    spans = []
    for column in (c for c in rows[0] if c.startswith("gate.") and c != "gate.loop"):
        _, factor, dof = column.split(".")
        k = 0
        while k < len(rows):
            action = rows[k][column]
            j = k
            while j + 1 < len(rows) and rows[j + 1][column] == action:
                j += 1
            if action != "include":
                spans.append((factor, dof, action, t[k], t[j + 1] if j + 1 < len(t) else t[j] + t[1] - t[0]))
            k = j + 1
    return spans


@pytest.mark.slow
def test_compare_report_has_the_gating_timeline(compared, short_run):
    folder = compared.out_dir
    timeline = _section((folder / "report.html").read_text(), "Gating timeline")
    spans = _csv_spans(folder / "gated" / "validation.csv")
    assert spans, "the short run's compass fault should be gated"
    for factor, dof, action, a, b in spans:
        assert f"<tr><td>gated</td><td>{factor}</td><td>{dof}</td><td>{action}</td><td>{a:.1f}</td><td>{b:.1f}</td></tr>" \
            in timeline
    assert "<td>ungated</td>" not in timeline  # nothing validated there
    # The true faults, each detected or missed, and metrics.json's figures.
    metrics = compared.results["gated"].metrics
    for comp, intervals in short_run.faults.items():
        for a, b in intervals:
            assert re.search(rf"<tr><td>gated</td><td>{comp}</td><td>{a:.1f}</td><td>{b:.1f}</td>"
                             r"<td>(detected|missed)</td>", timeline)
    assert (f"<tr><td>gated</td><td>{metrics['faults_missed']}</td><td>{metrics['faults_detected']}</td>"
            f"<td>{metrics['false_alarm_fraction']:.3f}</td>") in timeline
    assert "true fault" in timeline
    (data, alt), = IMAGE.findall(timeline)
    assert alt == "gating timeline" and base64.b64decode(data) == (folder / "gating_timeline.png").read_bytes()


@pytest.fixture(scope="module")
def compared_without_truth(short_run, tmp_path_factory):
    """The run folder's bag alone: the same data, no truth.json."""
    res = run_compare(short_run.run_dir / "bag", TELEMAX_CONFIG, tmp_path_factory.mktemp("c") / "c", only=["gated"])
    assert res.results["gated"].recording is None or res.results["gated"].recording.fault_truth is None
    return res


@pytest.mark.slow
def test_gating_timeline_without_truth_has_no_true_fault(compared_without_truth):
    res = compared_without_truth
    timeline = _section((res.out_dir / "report.html").read_text(), "Gating timeline")
    spans = _csv_spans(res.out_dir / "gated" / "validation.csv")
    assert spans
    for factor, dof, action, a, b in spans:
        assert f"<td>{factor}</td><td>{dof}</td><td>{action}</td><td>{a:.1f}</td>" in timeline
    assert "true fault" not in timeline.lower() and "missed" not in timeline and "false alarm" not in timeline
    assert len(IMAGE.findall(timeline)) == 1


@pytest.mark.slow
def test_observer_timelines_name_true_faults_only_with_truth(compared, compared_without_truth):
    heading = "Observer timelines (the paper&#x27;s Fig. 3)"
    with_truth = _section((compared.out_dir / "report.html").read_text(), heading)
    assert "over the true faults" in with_truth
    without = _section((compared_without_truth.out_dir / "report.html").read_text(), heading)
    assert "true fault" not in without.lower() and "no fault truth" in without
    assert len(IMAGE.findall(without)) == 1


@pytest.mark.slow
def test_report_can_be_turned_off(short_run, tmp_path):
    res = run_compare(short_run.run_dir, TELEMAX_CONFIG, tmp_path / "c", only=["ungated"],
                      overrides=["output.report=false", "output.mcap=false", "output.plots=false"])
    assert not (res.out_dir / "report.html").exists() and res.report_s == 0.0


@pytest.mark.skipif(CHROMIUM is None, reason="no chromium on this machine (Debian: apt-get install chromium)")
def test_compare_report_renders_in_headless_chromium(compared, tmp_path):
    # The page with a probe added: once loaded, it writes how many images
    # the browser decoded (complete, with a width) into the page.
    probe = ("<script>addEventListener('load', () => { const i = [...document.images];"
             " document.body.insertAdjacentHTML('beforeend', '<pre id=probe>' +"
             " i.filter(x => x.complete && x.naturalWidth > 0).length + '/' + i.length + '</pre>'); });</script>")
    page = tmp_path / "report.html"
    page.write_text((compared.out_dir / "report.html").read_text().replace("</body>", probe + "</body>"))
    args = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=10000"]
    dom = subprocess.run([*args, "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120).stdout
    decoded = re.search(r'<pre id="probe">(\d+)/(\d+)</pre>', dom)
    assert decoded is not None, dom[-2000:]
    assert decoded.group(1) == decoded.group(2) == str(len(IMAGE.findall(page.read_text())))
