"""The real-fault bench's summary: each figure against its target, from the
rows the harness measured."""

from __future__ import annotations

import pytest

from scripts.bench.common import ROWS_MEASURED
from scripts.bench.real_faults import (
    BROAD_REPORT, BROAD_TUNING, HUSKY, KERNELS, METHODS, fault_specs, injected_specs, injected_stretches, log_faults,
    log_source, stretch_faults, summarise,
)


def _rows(log: str, fault: str, ates: dict[str, float], **gated) -> list[dict]:
    rows = []
    for method in METHODS:
        row = {"log": log, "fault": fault, "method": method, "ate_m": ates.get(method, 1.0)}
        if method.startswith("gated"):
            row.update(gated)
        rows.append(row)
    return rows


def test_the_summary_holds_gated_against_the_best_kernel_and_the_interval_oracle():
    rows = _rows("a", "cut3", {"gated": 0.5, "cauchy": 0.8, "interval_oracle": 0.25},
                 alarm_fraction=0.1, precision=0.9, recall=0.5, detected=3, missed=1, delay_s=1.0,
                 stretches_found=3, stretches=3)
    rows += _rows("b", "cut3", {"gated": 2.0, "huber": 1.0, "interval_oracle": 2.0},
                  alarm_fraction=0.1, precision=0.5, recall=0.5, detected=1, missed=1, delay_s=None,
                  stretches_found=0, stretches=3)
    rows += [{"log": "a", "fault": "none", "method": "ungated", "ate_m": 0.10},
             {"log": "a", "fault": "none", "method": "gated", "ate_m": 0.11, "alarm_fraction": 0.03}]
    text, f = summarise(rows)
    assert f["gated / best kernel, worst"] == pytest.approx(2.0)
    assert f["gated / best kernel, worst set"] == pytest.approx(2.0)  # one set: the worst row's
    assert f["gated / best kernel, geometric mean"] == pytest.approx((0.5 / 0.8 * 2.0) ** 0.5)
    assert f["gated / interval oracle, geometric mean"] == pytest.approx((2.0 * 1.0) ** 0.5)
    assert f["labelled intervals detected"] == pytest.approx(4 / 6)
    assert f["injected stretches found"] == pytest.approx(3 / 6)
    assert "| 3/3 | 3/4 | 1.0 |" in text and "| 0/3 | 1/2 |" in text
    assert f["uninjected gated / ungated, worst"] == pytest.approx(1.1)
    assert f["uninjected alarm fraction, worst"] == pytest.approx(0.03)
    assert "| a | cut3 |" in text and "cauchy 0.800" in text and "missed" in text and "met" in text
    assert set(KERNELS) < set(METHODS)


def test_faults_are_placed_as_shares_of_the_log():
    assert fault_specs("cut2", 100.0, [0.2, 0.5], 0.1) == ["laser_cut@20.0:30.0,range_m=2", "laser_cut@50.0:60.0,range_m=2"]
    assert fault_specs("yaw_slip", 10.0, [0.0], 0.5) == ["slip@0.0:5.0,scale=1.0,yaw_scale=1.5"]


def test_the_husky_bag_takes_its_own_sensors_faults_after_what_its_config_learnt_from():
    assert "cut3" not in log_faults(HUSKY) and {"gyro_bias", "dipole", "slip"} <= set(log_faults(HUSKY))
    assert "gyro_bias" not in log_faults("intel")
    specs = injected_specs(HUSKY, "gyro_bias", 395.0, None)
    starts = [float(s.split("@")[1].split(":")[0]) for s in specs]
    assert len(specs) == 3 and min(starts) > 215.0 and all(s.endswith("bias_deg_s=2") for s in specs)


def test_a_log_without_ground_truth_has_no_tight_oracle_and_its_own_summary_column():
    rows = _rows("intel", "cut3", {"gated": 0.5, "cauchy": 1.0, "interval_oracle": 0.5}, detected=1, missed=0)
    husky = _rows(HUSKY, "slip", {"gated": 2.0, **{k: 5.0 for k in KERNELS}, "gnc_gm": 4.0, "interval_oracle": 1.0},
                  detected=0, missed=1)
    rows += [r for r in husky if r["method"] != "oracle"]
    text, f = summarise(rows)
    assert f["gated / best kernel, geometric mean"] == pytest.approx((0.5 * 0.5) ** 0.5)
    assert f["labelled intervals detected"] == pytest.approx(0.5)
    assert f["injected stretches found"] is None  # no row counted them
    assert "| husky | slip | 1.000 | 2.000 | 1.000 | gnc_gm 4.000 | – |" in text
    assert "| figure | measured, every log | CARMEN | Husky | target |  |" in text


def test_a_broad_trial_takes_an_imus_faults_and_is_judged_by_its_heading():
    assert set(log_faults("broad-02")) == {"gyro_bias", "dipole"}
    args = type("Args", (), {"placements": [0.2, 0.5], "length": 0.1})()
    assert injected_specs("broad-02", "dipole", 100.0, args) == [
        "dipole@20.0:30.0,target=magnetometer", "dipole@50.0:60.0,target=magnetometer"]
    assert not set(BROAD_REPORT) & set(BROAD_TUNING)
    rows = _rows("intel", "cut3", {"gated": 0.5, "cauchy": 1.0, "interval_oracle": 0.5}, detected=1, missed=0)
    broad = _rows("broad-02", "dipole", {}, detected=1, missed=0)
    for r in broad:  # its ATE is of positions it does not estimate: 1.0 for every method here
        r["yaw_rmse_deg"] = {"gated": 8.0, "cauchy": 2.0, "interval_oracle": 4.0}.get(r["method"], 10.0)
    text, f = summarise(rows + broad)
    assert f["gated / best kernel, worst"] == pytest.approx(4.0)
    assert "| broad-02 | dipole | 10.000 | 8.000 |" in text and "heading RMSE in deg" in text
    assert "| CARMEN | BROAD | target |" in text


def test_a_broad_trial_is_found_by_its_number(tmp_path):
    (tmp_path / "broad").mkdir()
    (tmp_path / "broad" / "02_undisturbed_slow_rotation_B.mat").write_bytes(b"")
    assert log_source("broad-02", tmp_path).name == "02_undisturbed_slow_rotation_B.mat"
    assert log_source("intel", tmp_path) == tmp_path / "carmen" / "intel-corrected.log.gz"


def test_the_stretch_oracle_gates_each_injected_sensor_over_its_whole_stretch():
    got = stretch_faults(["laser_cut@10.0:20.0,range_m=3", "slip@30.0:40.0,scale=1.5",
                          "slip@50.0:60.0,scale=1.0,yaw_scale=1.5", "gyro_bias@1.0:2.0,bias_deg_s=2",
                          "dipole@3.0:4.0,target=heading"])
    assert got == {"SM_DIST": [(10.0, 20.0)], "SM_LAT": [(10.0, 20.0)], "SM_YAW": [(10.0, 20.0)],
                   "ODO_DIST": [(30.0, 40.0)], "ODO_YAW": [(50.0, 60.0)], "IMU_GYRO": [(1.0, 2.0)],
                   "IMU_YAW": [(3.0, 4.0)]}
    rows = _rows("a", "cut3", {"gated": 1.0, **{k: 3.0 for k in KERNELS}, "cauchy": 2.0, "interval_oracle": 0.5,
                               "stretch_oracle": 4.0},
                 detected=1, missed=0)
    text, f = summarise(rows)
    assert f["gated / stretch oracle, geometric mean"] == pytest.approx(0.25)
    assert "| a | cut3 | 1.000 | 1.000 | 1.000 | cauchy 2.000 | 1.000 | 0.500 | 4.000 | 0.50 | 2.00 | 0.25 |" in text


def test_an_injected_stretch_is_found_where_one_of_its_components_is_blamed():
    from types import SimpleNamespace

    from validation.metrics import stretches_found

    specs = ["laser_cut@10.0:20.0,range_m=3", "slip@30.0:40.0,scale=1.5", "slip@50.0:60.0,scale=1.5"]
    stretches = injected_stretches(specs)
    assert stretches == [(["SM_DIST", "SM_LAT", "SM_YAW"], 10.0, 20.0), (["ODO_DIST"], 30.0, 40.0),
                         (["ODO_DIST"], 50.0, 60.0)]
    t = [15.0, 35.0, 45.0, 55.0]

    def result(*diagnoses):
        return SimpleNamespace(consistent=True, diagnoses=tuple(frozenset(d) for d in diagnoses))

    # The whole matcher blamed in the cut (a sensor stands for its modalities);
    # the odometry blamed between the slips, and only suspected (second in
    # the ranking) within the second.
    results = [result({"SM"}), result({"ODO_DIST"}), result({"ODO_DIST"}), result({"LOOP"}, {"ODO_DIST"})]
    expand = {"SM": ["SM_DIST", "SM_LAT", "SM_YAW"]}
    assert stretches_found(t, results, [], stretches, expand) == 2
    assert stretches_found(t, results, [], stretches) == 1


def test_a_blame_is_right_within_an_injected_stretch_of_its_sensor_whether_or_not_that_step_was_harmed():
    from types import SimpleNamespace

    from validation.metrics import stretch_precision

    stretches = injected_stretches(["laser_cut@10.0:20.0,range_m=3", "slip@30.0:40.0,scale=1.5"])
    t = [5.0, 12.0, 15.0, 18.0, 25.0, 35.0, 36.0]

    def result(*blamed):
        return SimpleNamespace(consistent=True, diagnoses=(frozenset(blamed),))

    # Right: the whole matcher within the cut, one of its modalities within
    # it, the odometry within the slip. Wrong: the matcher before the cut
    # and after it, the odometry within the cut with the matcher (a blame
    # must lie wholly within what was injected). Not counted: no blame.
    results = [result("SM"), result("SM"), result("SM_DIST"), result("SM", "ODO_DIST"), result("SM_YAW"),
               result("ODO_DIST"), result()]
    expand = {"SM": ["SM_DIST", "SM_LAT", "SM_YAW"]}
    assert stretch_precision(t, results, [], stretches, expand) == (3, 6)


def test_a_floor_is_met_from_above_and_the_rows_read_back_summarise_as_they_were(tmp_path):
    from scripts.bench.common import csv_text
    from scripts.bench.real_faults import read_rows

    rows = _rows("a", "cut3", {"gated": 0.5, "cauchy": 0.8, "interval_oracle": 0.25},
                 alarm_fraction=0.1, precision=0.9, recall=0.5, detected=3, missed=1, delay_s=1.0,
                 stretches_found=1, stretches=3)
    text, f = summarise(rows)
    assert f["injected stretches found"] == pytest.approx(1 / 3)
    assert "| injected stretches found | 0.33 | ≥ 0.8 | missed |" in text
    assert "| step precision | 0.90 | ≥ 0.7 | met |" in text
    path = tmp_path / "real_faults.csv"
    path.write_text(csv_text(rows, sorted({k for r in rows for k in r})))
    assert summarise(read_rows(path)) == (text, f)


def test_the_readme_table_of_a_page_summarised_from_earlier_rows_says_where_they_were_measured(tmp_path, monkeypatch):
    import scripts.bench.common as common

    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "real_faults.md").write_text(
        "# Title\n\nWritten by `python -m scripts.bench real_faults --rows r.csv` at commit abc, 2026-01-01 00:00 UTC, "
        f"on a machine.\n\n{common.ROWS_MEASURED} an earlier run of this bench at commit 123 and read back.\n\n| a |\n|---|\n| 1 |\n\nmore\n")
    (tmp_path / "README.md").write_text("before\n<!-- results/real_faults -->\nold\n<!-- /results/real_faults -->\nafter\n")
    monkeypatch.setattr(common, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(common, "REPO", tmp_path)
    common.include_in_readme("real_faults")
    readme = (tmp_path / "README.md").read_text()
    assert "| 1 |\n\nWritten by `python -m scripts.bench real_faults --rows r.csv` at commit abc, 2026-01-01 00:00 UTC.\n" \
           f"{common.ROWS_MEASURED} an earlier run of this bench at commit 123 and read back.\n<!-- /results/real_faults -->" in readme
    assert "old" not in readme and readme.startswith("before\n") and readme.endswith("after\n")


def test_rows_read_back_say_at_which_commit_each_log_was_measured():
    from scripts.bench.real_faults import measured_where

    rows = [{"log": "intel", "commit": "aaa"}, {"log": "husky", "commit": "bbb"}, {"log": "intel", "commit": "aaa"},
            {"log": "aces", "commit": "aaa"}]
    assert measured_where(rows) == " at commits aaa (intel, aces); bbb (husky), one run per commit, their rows put together,"
    assert measured_where(rows[:1]) == " at commit aaa"
    assert measured_where([{"log": "intel"}]) == ""


def test_runs_of_some_logs_each_make_one_page_and_a_row_in_two_runs_is_refused(tmp_path):
    from scripts.bench.common import csv_text
    from scripts.bench.real_faults import read_back

    a = _rows("intel", "cut3", {"gated": 0.5, "cauchy": 0.8})
    b = _rows("aces", "cut3", {"gated": 2.0, "huber": 1.0})
    for name, rows in (("a.csv", a), ("b.csv", b)):
        rows = [{**r, "commit": "abc", "placements": "0.2 0.5 0.8"} for r in rows]
        (tmp_path / name).write_text(csv_text(rows, sorted({k for r in rows for k in r})))
    rows, said = read_back([tmp_path / "a.csv", tmp_path / "b.csv"])
    assert summarise(rows) == summarise([{**r, "commit": "abc", "placements": "0.2 0.5 0.8"} for r in a + b])
    assert said.startswith(f"{ROWS_MEASURED} 2 earlier runs of this bench, their rows put together: "
                           f"intel at commit abc (`{tmp_path / 'a.csv'}`); aces at commit abc (`{tmp_path / 'b.csv'}`)")
    with pytest.raises(SystemExit, match="a.csv: given twice"):
        read_back([tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "a.csv"])
    rows, said = read_back([tmp_path / "a.csv"])
    assert said == f"{ROWS_MEASURED} an earlier run of this bench at commit abc and read back from its `a.csv`; " \
                   "this command summarised them."


def test_a_row_two_runs_both_mapped_counts_once_with_the_same_figures_and_is_refused_with_others(tmp_path):
    from scripts.bench.common import csv_text
    from scripts.bench.real_faults import read_back

    def write(name: str, ate: float, seconds: float, commit: str) -> None:
        rows = [{"log": "aces", "fault": "none", "method": m, "ate_m": ate, "seconds": seconds, "commit": commit}
                for m in ("ungated", "gated")]
        rows += [{**r, "fault": "cut3", "placements": name} for r in _rows("aces", "cut3", {"gated": 2.0})]
        (tmp_path / f"{name}.csv").write_text(csv_text(rows, sorted({k for r in rows for k in r})))

    write("first", 0.09, 12.0, "abc")
    write("again", 0.09, 15.5, "def")
    rows, said = read_back([tmp_path / "first.csv", tmp_path / "again.csv"])
    recorded = [r for r in rows if r["fault"] == "none"]
    assert [(r["method"], r["seconds"]) for r in recorded] == [("ungated", 12.0), ("gated", 12.0)]
    assert len(rows) == 2 + 2 * len(METHODS)
    assert said.endswith(" 2 rows mapped again by a later run, with the same figures (the time aside), are counted once.")
    write("other", 0.10, 12.0, "abc")
    with pytest.raises(SystemExit, match="other.csv: aces none ungated at placements None is also in .*first.csv "
                                         "with other figures"):
        read_back([tmp_path / "first.csv", tmp_path / "other.csv"])


def test_a_blame_of_the_husky_bags_own_compass_fault_is_right_but_not_an_injected_stretch_found():
    from scripts.bench.real_faults import own_faults

    (comps, start, end), = own_faults(HUSKY)
    assert comps == ["IMU_YAW"] and 180.0 < start < 230.0 and end == float("inf")
    assert own_faults("intel") == []


def test_placement_sets_are_summarised_by_medians_of_the_ratios_set_by_set():
    first = _rows("a", "cut3", {"gated": 1.0, "cauchy": 2.0, "huber": 4.0, "interval_oracle": 1.0},
                  detected=2, missed=1, stretches_found=3, stretches=3, alarm_fraction=0.1)
    second = _rows("a", "cut3", {"gated": 3.0, "cauchy": 6.0, "huber": 1.0, "interval_oracle": 2.0},
                   detected=1, missed=2, stretches_found=1, stretches=3, alarm_fraction=0.3)
    third = _rows("a", "cut3", {"gated": 2.0, "cauchy": 1.0, "huber": 8.0, "interval_oracle": 4.0},
                  detected=3, missed=0, stretches_found=2, stretches=3, alarm_fraction=0.2)
    for rows, sets in ((first, "0.2 0.5 0.8"), (second, "0.1 0.4 0.7"), (third, "0.3 0.6 0.9")):
        for r in rows:
            r["placements"] = sets
    text, f = summarise(first + second + third)
    # gated against each set's best kernel: 1/1 (a kernel at 1.0 by default), 3/1, 2/1; the median is 2
    assert f["gated / best kernel, worst"] == pytest.approx(2.0)
    assert f["gated / best kernel, worst set"] == pytest.approx(3.0)  # the second set's, beside the median
    # against the interval oracle set by set: 1, 1.5, 0.5
    assert f["gated / interval oracle, geometric mean"] == pytest.approx(1.0)
    assert f["labelled intervals detected"] == pytest.approx(6 / 9)
    assert f["injected stretches found"] == pytest.approx(6 / 9)
    assert "| a | cut3 (3 sets) | 1.000 | 2.000 |" in text  # ungated and gated: the medians over the sets
    assert "| 0.200 |" in text and "| 6/9 | 6/9 |" in text and "3 sets of placements" in text


def test_every_default_placement_set_ends_its_last_stretch_inside_the_log():
    from scripts.bench.real_faults import PLACEMENT_SETS

    assert len(PLACEMENT_SETS) == 3 and len(set(PLACEMENT_SETS)) == 3
    assert all(0.0 <= p and p + 0.1 < 1.0 for ps in PLACEMENT_SETS for p in ps)
