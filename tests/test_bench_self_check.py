"""The self-check bench's rows and page, from fake metrics.json files (no
mapping)."""

from __future__ import annotations

import json
from pathlib import Path

from scripts.bench.self_check import (
    DEMO_VARIANTS, HEADER, Row, Unit, cells, findings, page, rows_of, units_of,
)


def _figure(value, bound, side, samples, unit=""):
    passed = None if value is None else (value >= bound if side == "at_least" else value <= bound)
    return {"value": value, "bound": bound, "side": side, "unit": unit, "samples": samples, "passed": passed}


def metrics(scan, loop, odo, ate=0.1, stamps=None, blame=None, seconds=0.5, n_poses=500, free=(0.2, 1000)):
    """A metrics.json as gslam map writes it: figures as (value, samples)."""
    figures = {"scan_agreement": _figure(*scan[:1], 0.85, "at_least", scan[1]),
               "free_space_returns": _figure(*free[:1], 0.5, "at_most", free[1]),
               "loop_residual_m": _figure(*loop[:1], 0.2, "at_most", loop[1], "m"),
               "odometry_disagreement": _figure(*odo[:1], 0.35, "at_most", odo[1])}
    failed = [n for n, f in figures.items() if f["passed"] is False]
    m = {"n_poses": n_poses, "timings_s": {"read": 1.0, "self_check": seconds},
         "self_check": {"verdict": "fail" if failed else "pass", "failed": failed, "figures": figures,
                        "stamps_synthesised": stamps, "blame_share": blame}}
    if ate is not None:
        m["ate_rmse_m"] = ate
    return m


def test_a_row_holds_each_figure_with_its_samples_the_verdict_and_the_seconds():
    row = Row("intel", "carmen", metrics((0.9868, 455), (0.02, 524), (0.0077, 909), ate=0.0854, seconds=0.918))
    assert cells(row) == ["intel", "0.085", "0.9868 (455)", "0.2 (1000)", "0.02 (524)", "0.0077 (909)", "no", "pass",
                          "0.92"]
    assert len(cells(row)) == len(HEADER)


def test_a_figure_that_does_not_apply_is_a_dash_and_a_failed_check_names_its_figure():
    row = Row("orebro", "carmen", metrics((0.6793, 237), (None, 0), (None, 0), ate=18.441, stamps="all zero",
                                          free=(0.9622, 41921)))
    assert cells(row) == ["orebro", "18.441", "0.6793 (237)", "0.9622 (41921)", None, None, "yes", "fail", "0.50"]
    text = " ".join(findings([row]))
    assert "orebro fails on scan_agreement 0.6793 (bound ≥ 0.85), free_space_returns 0.9622 (bound ≤ 0.5)" in text
    assert "loop_residual_m and odometry_disagreement do not apply" in text


def test_the_bag_has_no_ate_and_a_result_without_a_check_is_marked():
    assert cells(Row("Husky bag (husky.yaml)", "husky", metrics((None, 0), (None, 0), (0.0, 718), ate=None)))[1] is None
    assert cells(Row("old", "carmen", {"ate_rmse_m": 1.0}))[HEADER.index("verdict")] == "no self-check"


def test_the_findings_are_drawn_from_the_rows():
    rows = [Row("intel", "carmen", metrics((0.99, 455), (0.02, 524), (0.0077, 909), ate=0.085)),
            Row("csail", "carmen", metrics((0.968, 406), (0.0187, 44), (0.1753, 405), ate=0.141, stamps="x")),
            Row("corridor", "carmen", metrics((0.9856, 486), (0.0231, 590), (0.001, 1940), ate=0.781)),
            Row("orebro", "carmen", metrics((0.6793, 237), (None, 0), (None, 0), ate=18.441)),
            Row("demo, ungated", "demo", metrics((0.9486, 370), (0.015, 3), (0.1927, 441), ate=4.627, n_poses=442)),
            Row("demo, gated", "demo", metrics((1.0, 370), (0.0153, 89), (0.0, 441), ate=0.034, blame=0.29601,
                                               seconds=3.2, n_poses=4791))]
    text = "\n".join(findings(rows))
    assert "Of the 4 CARMEN logs mapped, 2 map within 0.2 m ATE of their corrected reference; all of them pass" in text
    assert "corridor (0.781 m) passes; orebro (18.441 m) fails" in text
    assert "scan_agreement 0.968 (csail) to 0.99 (intel)" in text
    assert "odometry_disagreement 0.001 (corridor) to 0.1753 (csail)" in text
    assert "corridor passes at 0.781 m ATE: scan_agreement 0.9856, free_space_returns 0.2, loop_residual_m 0.0231 m" in text
    assert "The demo ungated against gated (4.627 m against 0.034 m ATE)" in text
    assert "odometry_disagreement 0.1927 against 0" in text
    assert "the 370 of its 442 keyframes whose scans hold points (72 see nothing" in text
    assert "demo, gated 0.29601" in text
    assert "3.20 s (demo, gated: 4791 keyframes, 370 of them checked" in text
    body = page(rows, ["seattle: /x not found"], 1, 1)
    assert "`gslam demo` (telemax_lab, seed 1)" in body and "- seattle: /x not found" in body
    assert "- csail: x" in body  # why its stamps were made


def test_the_units_skip_absent_data_and_read_the_demo_variants(tmp_path: Path):
    (tmp_path / "carmen").mkdir()
    (tmp_path / "carmen" / "intel-corrected.log.gz").write_bytes(b"")
    units, skipped = units_of(["intel", "aces", "husky", "demo"], tmp_path, tmp_path / "work")
    assert [u.name for u in units] == ["intel", "demo"]
    assert [s.split(":")[0] for s in skipped] == ["aces", "husky"]
    assert units[0].args[:2] == ["map", str(tmp_path / "carmen" / "intel-corrected.log.gz")]
    assert units[0].args[-2:] == ["--out", str(tmp_path / "work" / "carmen" / "intel")]
    demo = Unit("demo", Path("telemax_lab"), [], tmp_path / "demo")
    for v in DEMO_VARIANTS:
        (demo.out / "compare" / v).mkdir(parents=True)
        (demo.out / "compare" / v / "metrics.json").write_text(json.dumps(metrics((1.0, 3), (None, 0), (0.0, 2))))
    assert [r.label for r in rows_of(demo)] == ["demo, ungated", "demo, gated", "demo, oracle"]
