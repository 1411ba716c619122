"""gslam ablate: spec validation, job expansion, resumable runs, failures,
the summary against the run folders, and Ray against the local pool.

Runs use the short compass scenario of conftest (about 24 s of robot time,
well under a second per job)."""

from __future__ import annotations

import base64
import csv
import json
import shutil
from pathlib import Path

import pytest
import yaml

from slam.commands.ablate import expand_jobs, load_spec, run_ablation
from slam.commands.ablate.jobs import config_overrides, set_path, sweep_points
from slam.commands.ablate.runner import dispatch_order
from slam.cli import main
from slam.config import load_config
from validation.base.yamlio import load_yaml
from slam.errors import GslamError

from conftest import TELEMAX_CONFIG

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

TIMING = ("runtime_s", "realtime_factor", "validation_time_s", "timings_s.", "input_path")


def write_spec(path: Path, scenario: Path, **changes) -> Path:
    spec = {
        "name": "tiny",
        "config": str(TELEMAX_CONFIG),
        "inputs": {"scenarios": [{"path": str(scenario), "seeds": [1]}]},
        "variants": {"ungated": {"validation.mode": "off"}, "gated": {"validation.mode": "on"}},
        "sweep": {"grid": {"gating.inflation": [5.0, 20.0]}},
    }
    spec.update(changes)
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return path


def read_csv(path: Path) -> list[dict[str, str]]:
    with path.open() as f:
        return list(csv.DictReader(f))


# --- spec validation -----------------------------------------------------------


@pytest.mark.parametrize(
    "changes, key",
    [
        ({"variant": {"a": {}}}, "variant"),
        ({"variants": {"a": {"backend.optimiser": "batch"}}}, "backend.optimiser"),
        ({"sweep": {"grid": {"scenario.sensors.gyro.noise": [0.1]}}}, "scenario.sensors.gyro.noise"),
        ({"sweep": {"grid": {"validation.observers.relations.yaw_*.treshold": [5]}}}, "treshold"),
        ({"sweep": {"grid": {"validation.observers.relations.compass_*.threshold": [5]}}}, "compass_*"),
        ({"sweep": {"random": {"samples": 2, "params": {"gating.inflation": {"uniformm": [1, 2]}}}}}, "uniformm"),
    ],
)
def test_a_typo_fails_before_any_job_naming_the_key(tmp_path, short_scenario_yaml, changes, key):
    spec_path = write_spec(tmp_path / "spec.yaml", short_scenario_yaml, **changes)
    with pytest.raises(GslamError, match=key.replace("*", r"\*")) as err:
        run_ablation(load_spec(spec_path), tmp_path / "out", workers=1, progress=False)
    assert "\n" not in str(err.value)
    assert not (tmp_path / "out").exists()


def test_cli_typo_is_one_line_and_exit_code_1(tmp_path, short_scenario_yaml, capsys):
    spec_path = write_spec(tmp_path / "spec.yaml", short_scenario_yaml, variants={"a": {"gating.singel": "exclude"}})
    assert main(["-q", "ablate", str(spec_path), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert "singel" in err and "gating" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("config", ["spec.yaml", "./spec.yaml", "link.yaml", "other_spec.yaml"])
def test_a_spec_whose_config_is_a_spec_says_so_in_one_line(tmp_path, short_scenario_yaml, capsys, config):
    """config naming the spec itself (or through a link, or another spec) is
    named for what it is, not reported as a variant's unknown key 'name'."""
    spec_path = write_spec(tmp_path / "spec.yaml", short_scenario_yaml, config=config)
    (tmp_path / "link.yaml").symlink_to(spec_path)
    write_spec(tmp_path / "other_spec.yaml", short_scenario_yaml)
    said = "is an ablation spec, not a pipeline config" if config == "other_spec.yaml" else \
        "config names this spec file itself"
    with pytest.raises(GslamError, match=said):
        load_spec(spec_path)
    assert main(["-q", "ablate", str(spec_path), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and said in err and err.startswith(f"gslam: error: {spec_path}: "), err
    assert "unknown config key" not in err and not (tmp_path / "out").exists()


# --- expansion -----------------------------------------------------------------


def test_recorded_inputs_resolve_the_data_root_and_globs(tmp_path, monkeypatch):
    data = tmp_path / "data"
    (data / "logs").mkdir(parents=True)
    for name in ("b.log", "a.log", "notes.txt"):
        (data / "logs" / name).write_text("")
    monkeypatch.setenv("GSLAM_DATA", str(data))
    spec_path = tmp_path / "spec.yaml"
    spec_path.write_text(yaml.safe_dump({
        "name": "recorded",
        "config": str(TELEMAX_CONFIG),
        "inputs": {"recorded": [{"path": "{data}/logs/*.log"}, {"path": "{data}/logs/notes.txt", "name": "notes"}]},
    }))
    spec = load_spec(spec_path)
    assert [(r.path, r.label()) for r in spec.inputs.recorded] == [
        (data / "logs" / "a.log", "a"), (data / "logs" / "b.log", "b"), (data / "logs" / "notes.txt", "notes"),
    ]
    spec_path.write_text(yaml.safe_dump({
        "name": "recorded", "config": str(TELEMAX_CONFIG), "inputs": {"recorded": [{"path": "{data}/logs/*.bag"}]},
    }))
    with pytest.raises(GslamError, match=r"spec\.yaml: recorded input \{data\}/logs/\*\.bag: no file matches"):
        load_spec(spec_path)


def test_set_path_selects_list_elements_by_index_name_and_glob():
    tree = {"r": [{"name": "yaw_a", "t": 1}, {"name": "yaw_b", "t": 1}, {"name": "dist", "t": 1}]}
    set_path(tree, "r.yaw_*.t", 5)
    assert [e["t"] for e in tree["r"]] == [5, 5, 1]
    set_path(tree, "r.dist.t", 7)
    set_path(tree, "r.0.t", 2)
    assert [e["t"] for e in tree["r"]] == [2, 5, 7]
    with pytest.raises(GslamError, match="index 3"):
        set_path(tree, "r.3.t", 0)


def test_list_overrides_reach_load_config():
    base = load_yaml(TELEMAX_CONFIG)
    strings = config_overrides(base, [("validation.observers.relations.yaw_*.threshold", 4), ("gating.inflation", 3.5)])
    cfg = load_config(TELEMAX_CONFIG, strings)
    rel = {r["name"]: r["threshold"] for r in cfg.validation["observers"]["relations"]}
    assert rel["yaw_compass_gyro"] == rel["yaw_odo_gyro"] == 4
    assert rel["speed_gps_odo"] == 10 and rel["distance_odo_sm_res"] == 5
    assert cfg.gating["inflation"] == 3.5


def test_grid_union_and_seeded_random_are_deterministic(tmp_path, short_scenario_yaml):
    random = {"samples": 3, "seed": 7, "params": {"gating.inflation": {"log_uniform": [2, 50]},
                                                  "validation.observers.relations.*.threshold": {"integer": [5, 15]}}}
    grid = [{"gating.single": ["exclude", "inflate"]}, {"gating.holdoff_s": [2.0, 5.0, 8.0]}]
    path = write_spec(tmp_path / "s.yaml", short_scenario_yaml, sweep={"grid": grid, "random": random})
    spec = load_spec(path)
    points = sweep_points(spec.sweep)
    assert len(points) == (2 + 3) * 3
    assert points == sweep_points(load_spec(path).sweep)
    infl = [p["gating.inflation"] for p in points[:3]]
    assert all(2 <= v <= 50 for v in infl) and len(set(infl)) == 3
    other = write_spec(tmp_path / "o.yaml", short_scenario_yaml, sweep={"grid": grid, "random": {**random, "seed": 8}})
    assert sweep_points(load_spec(other).sweep) != points
    jobs = expand_jobs(spec)
    assert len(jobs) == 2 * len(points)
    assert [j.id for j in jobs] == [j.id for j in expand_jobs(load_spec(path))]
    assert len({j.id for j in jobs}) == len(jobs)


def test_scenario_sweeps_give_distinct_inputs(tmp_path, short_scenario_yaml):
    path = write_spec(tmp_path / "s.yaml", short_scenario_yaml, variants={"base": {}},
                      sweep={"grid": {"scenario.world.disturbers.*.moment_A_m2": [10.0, 100.0]}})
    jobs = expand_jobs(load_spec(path))
    assert len({j.simulated.key for j in jobs}) == 2
    assert [d["moment_A_m2"] for d in jobs[1].simulated.scenario["world"]["disturbers"]] == [100.0, 100.0]


def test_dispatch_interleaves_inputs(tmp_path, short_scenario_yaml):
    path = write_spec(tmp_path / "s.yaml", short_scenario_yaml,
                      inputs={"scenarios": [{"path": str(short_scenario_yaml), "seeds": [1, 2, 3]}]})
    jobs = expand_jobs(load_spec(path))
    assert [j.seed for j in jobs[:4]] == [1, 1, 1, 1]
    order = dispatch_order(jobs)
    assert sorted(j.id for j in order) == sorted(j.id for j in jobs)
    assert [j.seed for j in order[:6]] == [1, 2, 3, 1, 2, 3]


# --- running, resuming, failing ------------------------------------------------


@pytest.fixture(scope="module")
def finished(tmp_path_factory, short_scenario_yaml):
    """The 4-job tiny spec run once on 2 local workers."""
    root = tmp_path_factory.mktemp("ablate")
    spec_path = write_spec(root / "spec.yaml", short_scenario_yaml)
    result = run_ablation(load_spec(spec_path), root / "out", workers=2, progress=False)
    return spec_path, result


def test_summary_has_one_row_per_job_equal_to_metrics_json(finished):
    _, res = finished
    assert len(res.ran) == 4 and not res.failed and not res.skipped
    rows = read_csv(res.out_dir / "summary.csv")
    assert [r["job_id"] for r in rows] == [j.id for j in res.jobs]
    for row in rows:
        metrics = json.loads((res.out_dir / "jobs" / row["job_id"] / "metrics.json").read_text())
        assert float(row["ate_rmse_m"]) == metrics["ate_rmse_m"]
        assert float(row["runtime_s"]) == metrics["runtime_s"]
        assert float(row["timings_s.optimise"]) == metrics["timings_s"]["optimise"]
        if row["variant"] == "gated":
            assert float(row["alarm_fraction"]) == metrics["alarm_fraction"]
            assert float(row["detection_delay_s.IMU_YAW"]) == metrics["detection_delay_s"]["IMU_YAW"]
        assert row["gating.inflation"] in ("5.0", "20.0")
    md = (res.out_dir / "summary.md").read_text()
    assert "| gated | 20 | 1/1 |" in md
    assert (res.out_dir / "plots" / "gating.inflation.png").exists()
    # report.html: the same table and the plots, embedded.
    page = (res.out_dir / "report.html").read_text()
    assert "<tr><td>gated</td><td>20</td><td>1/1</td>" in page
    plot = base64.b64encode((res.out_dir / "plots" / "gating.inflation.png").read_bytes()).decode()
    assert f'<img src="data:image/png;base64,{plot}" alt="against gating.inflation">' in page
    assert res.summary.report_s > 0
    # A sweep's jobs write no grid and no bag unless the spec asks (as for plots).
    job = res.out_dir / "jobs" / rows[0]["job_id"]
    assert not (job / "run.mcap").exists() and not (job / "map.pgm").exists()


def test_killed_sweep_resumes_only_missing_jobs(finished, tmp_path):
    spec_path, res = finished
    out = tmp_path / "out"
    shutil.copytree(res.out_dir, out)
    gone = [j.id for j in res.jobs[1:3]]
    for job_id in gone:
        shutil.rmtree(out / "jobs" / job_id)
    # what kill -9 leaves: a half-written temp folder beside a job's place
    leftover = out / "jobs" / f".{gone[0]}.gslam-tmp-abc12345"
    leftover.mkdir()
    (leftover / ".gslam-tmp.json").write_text('{"host": "elsewhere", "pid": 1}')
    (leftover / "trajectory.tum").write_text("1 2 3")
    # and a hidden file that is not ours
    (out / "jobs" / ".notes").write_text("mine")
    again = run_ablation(load_spec(spec_path), out, workers=2, progress=False)
    assert sorted(again.ran) == sorted(gone)
    assert len(again.skipped) == 2
    assert [p.name for p in (out / "jobs").iterdir() if p.name.startswith(".")] == [".notes"]
    assert len(read_csv(out / "summary.csv")) == 4
    third = run_ablation(load_spec(spec_path), out, workers=1, progress=False)
    assert third.ran == [] and len(third.skipped) == 4


def test_a_failing_job_is_recorded_and_others_continue(tmp_path, short_scenario_yaml):
    variants = {"ungated": {"validation.mode": "off"}, "broken": {"keyframes.period_s": 1000.0}}
    spec_path = write_spec(tmp_path / "s.yaml", short_scenario_yaml, variants=variants, sweep={})
    res = run_ablation(load_spec(spec_path), tmp_path / "out", workers=2, progress=False)
    assert len(res.ran) == 1 and len(res.failed) == 1
    (failed_id, error), = res.failed.items()
    assert "fewer than 2 keyframes" in error
    record = json.loads((tmp_path / "out" / "failed" / f"{failed_id}.json").read_text())
    assert record["error"] == error
    rows = {r["variant"]: r for r in read_csv(tmp_path / "out" / "summary.csv")}
    assert rows["broken"]["status"] == "failed" and rows["ungated"]["status"] == "ok"
    retry = run_ablation(load_spec(spec_path), tmp_path / "out", workers=1, progress=False)
    assert retry.ran == [] and list(retry.failed) == [failed_id]


def test_ray_gives_the_same_summary_as_local(finished, tmp_path):
    ray = pytest.importorskip("ray", reason='the Ray backend needs ray (pip install ".[ray]")')
    assert ray is not None
    spec_path, res = finished
    out = run_ablation(load_spec(spec_path), tmp_path / "ray", workers=2, backend="ray", progress=False)
    assert len(out.ran) == 4 and not out.failed
    local, remote = read_csv(res.out_dir / "summary.csv"), read_csv(tmp_path / "ray" / "summary.csv")

    def strip(rows):
        return [{k: v for k, v in r.items() if not k.startswith(TIMING)} for r in rows]

    assert strip(local) == strip(remote)


# --- jobs sharing reading and scan matching -------------------------------------


def test_jobs_sharing_reading_and_scan_matching_are_grouped(tmp_path, short_scenario_yaml):
    from slam.commands.ablate.sharing import share_groups

    variants = {"ungated": {"validation.mode": "off"}, "gated": {"validation.mode": "on"},
                "coarse": {"frontend.voxel_size_m": 0.2}}
    spec_path = write_spec(tmp_path / "s.yaml", short_scenario_yaml, variants=variants,
                           inputs={"scenarios": [{"path": str(short_scenario_yaml), "seeds": [1, 2]}]})
    jobs = expand_jobs(load_spec(spec_path))  # 2 seeds x 3 variants x 2 inflations
    groups = share_groups(jobs, workers=1)
    assert sorted(j.id for g in groups for j in g) == sorted(j.id for j in jobs)
    for g in groups:  # one input, one front-end per group
        assert len({j.seed for j in g}) == 1 and len({j.variant == "coarse" for j in g}) == 1
    assert len(groups) == 4  # (seed 1, seed 2) x (voxel 0.1, voxel 0.2): 4 jobs, 2 jobs, 4, 2
    assert len(share_groups(jobs, workers=4)) > len(groups)  # split further to keep 4 workers busy


def test_shared_jobs_write_what_jobs_on_their_own_write(finished, tmp_path):
    from slam.commands.ablate.worker import run_job
    from slam.commands.ablate.sharing import run_jobs

    spec_path, res = finished
    out = tmp_path / "out"
    shutil.copytree(res.out_dir / "inputs", out / "inputs")
    jobs = res.jobs
    outcomes = run_jobs(jobs, out)
    assert [o.error for o in outcomes] == [None] * len(jobs)
    alone = tmp_path / "alone"
    shutil.copytree(res.out_dir / "inputs", alone / "inputs")
    for job in jobs:
        assert run_job(job, alone).error is None
        a, b = out / "jobs" / job.id, alone / "jobs" / job.id
        names = sorted(p.name for p in a.iterdir() if p.name != ".gslam-result.json")
        assert names == sorted(p.name for p in b.iterdir() if p.name != ".gslam-result.json")
        for name in names:
            if name == "metrics.json":
                ma, mb = (json.loads((d / name).read_text()) for d in (a, b))
                drop = ("runtime_s", "realtime_factor", "timings_s", "validation_time_s", "input")
                assert {k: v for k, v in ma.items() if k not in drop} == {k: v for k, v in mb.items() if k not in drop}
            else:
                assert (a / name).read_bytes() == (b / name).read_bytes(), (job.id, name)
