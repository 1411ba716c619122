"""``gslam calibrate``: relation models and observer parameters learnt from
data (slam/commands/calibrate)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from conftest import TELEMAX_CONFIG
from slam.commands.calibrate import calibrate, parse_clean
from slam.commands.calibrate.fit import fit_rates
from slam.commands.calibrate.runs import CalibrationRun
from slam.commands.calibrate.select import calibrate_relation
from slam.commands.calibrate.write import _relation_comment
from slam.cli import main
from slam.config import load_config
from slam.errors import GslamError
from slam.pipeline.folder import run_map
from validation.config import ValidationConfig
from validation.observers import observe_steps
from validation.observers.config import RelationConfig
from validation.streams import Stream, fixed_rate_steps, resample_streams

RATE_HZ = 10.0


def distance_run(seed: int, faults: list[tuple[float, float]] = (), duration_s: float = 300.0,
                 clean: tuple[float, float] | None = None) -> CalibrationRun:
    """Odometry and scan-matched path lengths at 10 Hz: the scan matcher
    reads 0.9 x the odometry plus 2 mm/s, with 1 cm of noise per sample;
    inside ``faults`` it reads 1.5 x."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 0.1)
    speed = 0.5 + 0.3 * np.sin(t / 7.0) + 0.2 * np.sin(t / 2.3)
    odo = np.concatenate(([0.0], np.cumsum(speed[1:] * 0.1)))
    factor = np.full(len(t), 0.9)
    for a, b in faults:
        factor[(t >= a) & (t < b)] = 1.5
    sm = np.concatenate(([0.0], np.cumsum(factor[1:] * np.diff(odo)))) + 0.002 * t + rng.normal(0.0, 0.01, len(t))
    streams = {"odo_distance": Stream(t, odo), "sm_distance": Stream(t, sm)}
    step_t = fixed_rate_steps(t[0], t[-1], RATE_HZ)
    steps = resample_streams(streams, step_t, 0.5)
    mask = np.ones(len(step_t), dtype=bool) if clean is None else (step_t >= clean[0]) & (step_t <= clean[1])
    return CalibrationRun(f"run{seed}", streams, steps, [], mask, clean is not None)


def vcfg(relation: RelationConfig, **extra) -> ValidationConfig:
    return ValidationConfig.model_validate({"mode": "on", "rate_hz": RATE_HZ, "pass": "causal",
                                            "observers": {"relations": [relation.model_dump()]}, **extra})


RESIDUAL = RelationConfig(name="d", kind="residual", stream_a="odo_distance", stream_b="sm_distance",
                          window_s=2.0, sigma_floor=1.0, threshold=5, max_counter=25)


def test_fit_recovers_gain_offset_and_noise_through_faults():
    faults = [(40.0 + 60.0 * i, 46.0 + 60.0 * i) for i in range(4)]  # 8 % of the run faulty
    runs = [distance_run(1, faults), distance_run(2)]
    fit = fit_rates(runs, "odo_distance", "sm_distance", 2.0, "trailing", RATE_HZ)
    assert fit.gain == pytest.approx(0.9, abs=0.01)
    assert fit.rate_offset == pytest.approx(0.002, abs=0.001)
    # Two samples of 1 cm noise differ by 1.41 cm.
    assert fit.noise == pytest.approx(0.0141, rel=0.15)
    # The faulty steps, and half a window either side, are not learnt from.
    t = runs[0].steps.t
    for a, b in faults:
        assert not fit.inliers[0][(t > a + 1.0) & (t < b)].any()
    assert fit.inliers[1].mean() > 0.97


def test_calibrated_relation_meets_its_target_and_sees_a_fault_elsewhere():
    learn = [distance_run(3), distance_run(4)]
    choice = calibrate_relation(learn, RESIDUAL, vcfg(RESIDUAL), target=0.002)
    rel = choice.relation
    assert choice.met and choice.alarm <= 0.002
    # The 1 cm noise, raised to a tenth of the motion over the window (RESOLUTION).
    assert rel.gain == pytest.approx(0.9, abs=0.01) and rel.sigma_floor < 0.1 and choice.resolution
    # Another run, not learnt from, with a fault: seen there and nowhere else.
    test = distance_run(5, [(100.0, 110.0)])
    log = observe_steps(test.steps, [rel], (), "trailing", "project", False).relations[rel.name]
    t = test.steps.t
    assert log.no_match[(t > 102.0) & (t < 110.0)].all()
    assert log.no_match[(t < 99.0) | (t > 115.0)].mean() < 0.005


def test_a_window_of_travel_is_calibrated_in_travel():
    """A relation over windows of travel keeps them: its window is chosen
    among lengths of travel (not seconds, which would cut every 2 m window
    short), its gain is the scan matcher's 0.9 of the odometry, and a fault
    on a run not learnt from is seen there and nowhere else."""
    travel = RESIDUAL.model_copy(update={"name": "t", "window_s": 30.0, "window_travel": 2.0})
    choice = calibrate_relation([distance_run(3), distance_run(4)], travel, vcfg(travel), target=0.002)
    rel = choice.relation
    assert choice.met and rel.window_travel in (1.0, 2.0, 4.0) and rel.window_s == 30.0
    assert rel.gain == pytest.approx(0.9, abs=0.01) and rel.rate_offset == 0.0
    test = distance_run(5, [(100.0, 130.0)])
    log = observe_steps(test.steps, [rel], (), "trailing", "project", False).relations[rel.name]
    t = test.steps.t
    assert log.no_match[(t > 110.0) & (t < 130.0)].all()
    assert log.no_match[(t < 95.0) | (t > 150.0)].mean() < 0.005


def test_cusum_relation_is_calibrated_like_a_residual_one():
    cus = RESIDUAL.model_copy(update={"name": "c", "kind": "cusum"})
    choice = calibrate_relation([distance_run(3), distance_run(4)], cus, vcfg(cus), target=0.002)
    assert choice.met and choice.relation.kind == "cusum" and choice.relation.k_sigma >= 5.0


@pytest.mark.slow
def test_held_offset_relation_is_learnt_about_its_held_level():
    """An offset relation held to a drift rate keeps it; its noise is the
    spread about the held level, and the relation then sees a standing
    error on a run not learnt from, for as long as it stands."""
    off = RelationConfig(name="o", kind="offset", stream_a="odo_distance", stream_b="sm_distance", window_s=2.0,
                         sigma_floor=1.0, level_window_s=60.0, level_max_rate=0.01, threshold=5, max_counter=25)
    choice = calibrate_relation([distance_run(3), distance_run(4)], off, vcfg(off), target=0.002)
    rel = choice.relation
    assert choice.met and rel.level_max_rate == 0.01 and rel.gain == pytest.approx(0.9, abs=0.01)
    assert rel.sigma_floor < 0.05  # the 1 cm noise, not the drift of the level
    test = distance_run(5, [(100.0, 103.0)])  # 1.5 x for 3 s: the scan matcher 0.9 m ahead from then on
    log = observe_steps(test.steps, [rel], (), "trailing", "project", False).relations[rel.name]
    t = test.steps.t
    assert log.no_match[t > 105.0].mean() > 0.95
    assert log.no_match[t < 99.0].mean() < 0.005


def test_trend_relation_keeps_its_mismatch_margin():
    """The margin is the user's; the search counts mismatches as the
    observer does (with it), and the config says so."""
    trend = RelationConfig(name="d", stream_a="odo_distance", stream_b="sm_distance", boundary=0.1, window_s=2.0,
                           boundary_b=0.09, mismatch_margin=1.0, threshold=5, max_counter=25)
    runs = [distance_run(3), distance_run(4)]
    choice = calibrate_relation(runs, trend, vcfg(trend), target=0.002)
    rel = choice.relation
    assert choice.met and rel.mismatch_margin == 1.0
    for run in runs:
        log = observe_steps(run.steps, [rel], (), "trailing", "project", False).relations[rel.name]
        assert log.no_match[log.valid].mean() <= 0.002
    text = "\n".join(_relation_comment(choice, 0.002, 2))
    assert "a mismatch counts where the slopes part by more than 1 b" in text


def test_parse_clean():
    assert parse_clean(None) is None
    assert parse_clean("0:120") == (0.0, 120.0)
    assert parse_clean("30:end") == (30.0, float("inf"))
    for bad in ("120", "5:2", "a:b", "-1:3", "nan:4"):
        with pytest.raises(GslamError, match="--clean"):
            parse_clean(bad)


@pytest.mark.slow
def test_calibrate_writes_a_config_that_maps_other_runs(short_run, tmp_path, capsys):
    out = tmp_path / "calibrated.yaml"
    # The compass is disturbed from 10.85 s: learn from the first 10 s.
    assert main(["-q", "calibrate", str(short_run.run_dir), "--config", str(TELEMAX_CONFIG), "--clean", "0:10",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "yaw_gyro_sm_res (residual): gain" in printed and f"wrote {out}" in printed
    text = out.read_text()
    assert text.startswith("# gslam calibrate result")
    assert "# yaw_compass_gyro_res (residual): compass_yaw against gyro_yaw" in text
    config = load_config(out)
    given = {r["name"]: r for r in load_config(TELEMAX_CONFIG).validation["observers"]["relations"]}
    learnt = {r["name"]: r for r in config.validation["observers"]["relations"]}
    assert learnt.keys() == given.keys()
    assert learnt["yaw_gyro_sm_res"]["sigma_floor"] != given["yaw_gyro_sm_res"]["sigma_floor"]
    assert learnt["speed_gps_odo"] == given["speed_gps_odo"]  # no GPS in the run: kept, and said so
    assert "speed_gps_odo: not calibrated" in text
    # 10 s is too short to measure how long the compass's error lasts: its factor is kept.
    assert config.backend.factors.compass == load_config(TELEMAX_CONFIG).backend.factors.compass
    # An earlier result is replaced; the config it maps with is the one written.
    assert main(["-q", "calibrate", str(short_run.run_dir), "--config", str(TELEMAX_CONFIG), "--clean", "0:10",
                 "--out", str(out)]) == 0
    assert out.read_text() == text  # deterministic
    res = run_map(short_run.run_dir, load_config(out, ["validation.mode=on", "output.plots=false"]), tmp_path / "m")
    assert res.metrics["validation_steps"] > 0 and "IMU_YAW" in res.metrics["blamed_steps"]


def test_calibrate_refuses_what_it_cannot_learn_from(short_run, tmp_path):
    with pytest.raises(GslamError, match="holds no validation step"):
        calibrate([short_run.run_dir], TELEMAX_CONFIG, tmp_path / "a.yaml", clean="500:600")
    with pytest.raises(GslamError, match="--false-alarm"):
        calibrate([short_run.run_dir], TELEMAX_CONFIG, tmp_path / "a.yaml", false_alarm=1.5)
    assert not (tmp_path / "a.yaml").exists()
    no_model = tmp_path / "c.yaml"
    tree = yaml.safe_load(TELEMAX_CONFIG.read_text())
    tree["validation"]["model"] = None
    no_model.write_text(yaml.safe_dump(tree))
    with pytest.raises(GslamError, match="validation.model"):
        calibrate([short_run.run_dir], no_model, tmp_path / "a.yaml")


def heading_run(tau_s: float, sd_rad: float, seed: int = 0, duration_s: float = 600.0,
                clean: tuple[float, float] | None = None,
                disturbed: tuple[float, float] | None = None) -> CalibrationRun:
    """A turning robot's integrated gyro heading (with a bias: a line) and a
    compass that reads it plus an error with correlation time ``tau_s``
    (first-order Gauss-Markov, sd ``sd_rad``), and 1 rad more while ``disturbed``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 0.1)
    heading = 0.8 * np.sin(t / 13.0) + 0.3 * np.sin(t / 3.1)
    a = np.exp(-0.1 / tau_s)
    err = np.zeros(len(t))
    err[0] = rng.normal(0.0, sd_rad)
    for k in range(1, len(t)):
        err[k] = a * err[k - 1] + rng.normal(0.0, sd_rad * np.sqrt(1.0 - a * a))
    if disturbed is not None:
        err[(t >= disturbed[0]) & (t < disturbed[1])] += 1.0
    streams = {"gyro_yaw": Stream(t, heading + 0.001 * t), "compass_yaw": Stream(t, heading + err, angular=True)}
    step_t = fixed_rate_steps(t[0], t[-1], RATE_HZ)
    steps = resample_streams(streams, step_t, 0.5)
    mask = np.ones(len(step_t), dtype=bool) if clean is None else (step_t >= clean[0]) & (step_t <= clean[1])
    return CalibrationRun("heading", streams, steps, [], mask, clean is not None)


@pytest.mark.parametrize("tau_s", [2.0, 10.0])
def test_compass_noise_is_its_error_against_the_gyro_and_how_long_that_lasts(tau_s):
    from slam.commands.calibrate.noise import learn_compass_noise

    runs = [heading_run(tau_s, 0.07, seed) for seed in range(3)]
    noise = learn_compass_noise(runs, RATE_HZ)
    assert noise.correlation_s == pytest.approx(tau_s, rel=0.25)
    assert noise.sd_rad == pytest.approx(0.07, rel=0.2)
    # Learnt whole: a rare 4-sd excursion is left out as a fault, and splits its stretch.
    assert noise.stretches >= 3 and noise.steps > 0.99 * sum(len(r.steps.t) for r in runs)
    # A lower bound: over 4 correlation times the line takes in most of the slow error.
    short = learn_compass_noise([heading_run(10.0, 0.07, clean=(0.0, 40.0))], RATE_HZ)
    assert 0.0 < short.correlation_s < 5.0 and short.sd_rad < 0.07
    # Learnt whole, a disturbance is a fault, not noise: the figures stay those of the compass.
    disturbed = learn_compass_noise([heading_run(tau_s, 0.07, seed, disturbed=(200.0, 230.0)) for seed in range(3)],
                                    RATE_HZ)
    assert disturbed.correlation_s == pytest.approx(tau_s, rel=0.25)
    assert disturbed.sd_rad == pytest.approx(0.07, rel=0.2)
    # Under 30 s clean: nothing measured, the factor kept as configured.
    assert learn_compass_noise([heading_run(10.0, 0.07, clean=(0.0, 25.0))], RATE_HZ) is None


@pytest.mark.slow
def test_calibrate_writes_the_compass_noise_into_the_factor(tmp_path):
    from slam.commands.calibrate import learn

    tree = yaml.safe_load(TELEMAX_CONFIG.read_text())
    tree["validation"]["model"] = str((TELEMAX_CONFIG.parent / tree["validation"]["model"]).resolve())
    tree["validation"]["observers"]["relations"] = [
        r for r in tree["validation"]["observers"]["relations"] if r["name"] == "yaw_compass_gyro"]
    start = tmp_path / "start.yaml"
    start.write_text(yaml.safe_dump(tree))
    res = learn([heading_run(10.0, 0.07)], load_config(start))
    out = tmp_path / "learnt.yaml"
    out.write_text(res.text)
    compass = load_config(out).backend.factors.compass
    assert compass.correlation_s == pytest.approx(res.compass_noise.correlation_s, rel=1e-2)
    assert compass.correlation_s == pytest.approx(10.0, rel=0.25)
    assert compass.sigma_yaw_deg == pytest.approx(np.degrees(0.07), rel=0.2)
    assert "# Compass heading minus the integrated gyro's" in res.text


# --- relations the data do not support -----------------------------------------------


def speed_run(seed: int, follows: bool, duration_s: float = 300.0) -> CalibrationRun:
    """A GPS speed and an odometry speed at 10 Hz, all declared clean. With
    ``follows`` the robot speeds up and slows down and both see it (the
    GPS with 5 cm/s of noise); without, it drives at a steady 1 m/s that
    the odometry reads to 5 mm/s while the GPS speed jumps by 0.15 m/s a
    sample: level with the odometry, its changes noise the odometry never
    sees (the Husky bag's speed_gps_odo)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 0.1)
    true = 1.0 + (0.4 * np.sin(t / 6.0) + 0.2 * np.sin(t / 2.1) if follows else 0.0)
    odo = true + rng.normal(0.0, 0.005, len(t))
    gps = true + rng.normal(0.0, 0.05 if follows else 0.15, len(t))
    streams = {"gps_speed": Stream(t, gps), "odo_fix_speed": Stream(t, odo)}
    step_t = fixed_rate_steps(t[0], t[-1], RATE_HZ)
    return CalibrationRun(f"speed{seed}", streams, resample_streams(streams, step_t, 0.5), [],
                          np.ones(len(step_t), dtype=bool), True)


SPEED = RelationConfig(name="speed_gps_odo", stream_a="gps_speed", stream_b="odo_fix_speed", boundary=0.1,
                       window_s=2.0, threshold=5, max_counter=25)


@pytest.mark.parametrize("follows", [True, False])
def test_a_relation_whose_gain_is_near_zero_is_dropped(follows):
    """Speeds level with each other but whose changes do not follow: the
    level alone kept them before; the gain of the changes now drops them,
    with the reason in words."""
    from slam.commands.calibrate.support import judge

    runs = [speed_run(1, follows), speed_run(2, follows)]
    choice = calibrate_relation(runs, SPEED, vcfg(SPEED), target=0.002)
    verdict = judge(runs, choice, vcfg(SPEED))
    if follows:
        assert choice.fit.gain == pytest.approx(1.0, abs=0.1) and verdict.kept, verdict
        return
    assert choice.fit.gain_fitted and abs(choice.fit.gain) < 0.1
    assert not verdict.kept and verdict.measure == "gain"
    assert verdict.reason.startswith("odo_fix_speed does not follow gps_speed's changes over")
    assert "at least 0.25 needed" in verdict.reason


def test_the_changes_carry_evidence_only_with_a_gain_and_a_correlation():
    """Step 3 of slam/commands/calibrate/support.py on fits built by hand:
    a gain against the motion, near zero, and a good gain with changes that
    hardly correlate."""
    from slam.commands.calibrate.fit import RateFit
    from slam.commands.calibrate.support import changes_evidence

    def fit(gain: float, corr: float) -> RateFit:
        return RateFit("gyro_yaw", "odo_yaw", 1.0, gain, 0.0, 0.01, 0.0, corr, 1000, 0.1)

    assert changes_evidence(fit(1.0, 0.95), 1.0) is None
    assert changes_evidence(fit(0.55, 0.9), 1.0) is None  # a skid-steer's odometry against its gyro
    against = changes_evidence(fit(-0.9, 0.9), 1.0)
    assert not against.kept and "turns against" in against.reason and "input.frames" in against.reason
    assert changes_evidence(fit(0.1, 0.9), 1.0).measure == "gain"
    weak = changes_evidence(fit(0.8, 0.3), 1.0)
    assert not weak.kept and weak.measure == "correlation of the changes" and "explains 9 %" in weak.reason


def heading_pair_run(seed: int) -> CalibrationRun:
    """A compass and a GPS course: the same heading 0.3 rad apart, the
    course with 0.3 rad of noise a sample (a course from fixes at walking
    speed), the robot turning slowly."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 600.0, 0.1)
    heading = np.unwrap(np.angle(np.exp(1j * 0.6 * np.sin(t / 40.0))))
    streams = {"compass_yaw": Stream(t, heading + rng.normal(0.0, 0.01, len(t))),
               "gps_course": Stream(t, heading - 0.3 + rng.normal(0.0, 0.3, len(t)))}
    step_t = fixed_rate_steps(t[0], t[-1], RATE_HZ)
    return CalibrationRun(f"heading{seed}", streams, resample_streams(streams, step_t, 0.5), [],
                          np.ones(len(step_t), dtype=bool), True)


def test_an_offset_observer_of_two_absolute_headings_is_judged_by_their_steady_difference():
    """Its observer keeps the configured gain (1) and compares levels, so
    the gain fitted to the changes (noise of the course) is no verdict on
    it: the mean resultant length of the difference is."""
    from slam.commands.calibrate.support import judge, uses_fitted_gain

    rel = RelationConfig(name="yaw_compass_gps", kind="offset", stream_a="gps_course", stream_b="compass_yaw",
                         window_s=4.0, sigma_floor=0.3, level_window_s=None, threshold=1, max_counter=21)
    runs = [heading_pair_run(1), heading_pair_run(2)]
    choice = calibrate_relation(runs, rel, vcfg(rel), target=0.002)
    verdict = judge(runs, choice, vcfg(rel))
    assert not uses_fitted_gain(choice.relation) and choice.relation.gain == 1.0
    assert verdict.kept and verdict.measure == "mean resultant length" and verdict.value > 0.9, verdict
