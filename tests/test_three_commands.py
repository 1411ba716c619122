"""inspect -> calibrate -> map --gating on, with no hand edit, on recordings
of sensor sets the project ships no config for (tests/bagfactory.py's
sensor_bag): a visual odometry beside wheels and an IMU, a second wheel
odometry, a magnetometer instead of an orientation, an IMU mounted upside
down; and what calibration drops, learns and says on the way."""

from __future__ import annotations

import numpy as np
import pytest

from bagfactory import sensor_bag
from slam.commands.calibrate import calibrate
from slam.commands.calibrate.runs import CalibrationRun
from slam.commands.calibrate.select import held_out
from slam.cli import main
from slam.config import load_config, validation_sections
from slam.commands.inspect.inspection import inspect_recording
from slam.pipeline.folder import run_map

pytestmark = pytest.mark.slow  # end to end: pytest -m 'not slow' leaves it out

FAULT = (60.0, 80.0)


def _three_commands(tmp_path, sensors, faulty: str, **bag):
    """Inspect and calibrate on a clean recording, map another with
    ``faulty`` going wrong over FAULT; the validation outcome and the
    learnt config."""
    clean = sensor_bag(sensors, seed=1, **bag).write(tmp_path / "clean.bag")
    run = sensor_bag(sensors, seed=2, faults={faulty: FAULT}, **bag).write(tmp_path / "faulty.bag")
    starter = tmp_path / "starter.yaml"
    learnt = tmp_path / "learnt.yaml"
    assert main(["-q", "inspect", str(clean), "--config-out", str(starter)]) == 0
    assert main(["-q", "calibrate", str(clean), "--config", str(starter), "--out", str(learnt)]) == 0
    result = run_map(run, load_config(learnt, ["validation.mode=on", "output.plots=false"]), tmp_path / "map",
                     concurrent=False)
    return result.validation, load_config(learnt)


def _blamed(v, component: str) -> np.ndarray:
    return np.array([r.consistent and bool(r.diagnoses) and component in r.diagnoses[0] for r in v.results])


def _check(v, component: str, parts: tuple[str, ...] = ()) -> None:
    """The faulty sensor blamed over most of its fault, no sensor blamed
    far from it."""
    t = v.step_t
    inside = (t >= FAULT[0] + 3.0) & (t <= FAULT[1])
    blamed = np.zeros(len(t), bool)
    for c in (component, *parts):
        blamed |= _blamed(v, c)
    assert blamed[inside].mean() > 0.6
    any_alarm = np.array([not r.consistent or bool(r.diagnoses and r.diagnoses[0]) for r in v.results])
    far = (t < FAULT[0] - 5.0) | (t > FAULT[1] + 15.0)
    assert any_alarm[far].mean() < 0.03


def test_wheels_a_visual_odometry_and_an_imu_no_laser(tmp_path):
    v, config = _three_commands(tmp_path, ["imu", "odom", "vo"], "vo")
    _check(v, "VO_YAW", ("VO",))
    assert "yaw_vo_gyro" in validation_sections(config)[0].model.relations


def test_a_second_wheel_odometry(tmp_path):
    v, _ = _three_commands(tmp_path, ["imu_no_orientation", "odom", "odom2"], "odom2")
    _check(v, "WHEELS2_YAW", ("WHEELS2",))


def test_a_magnetometer_instead_of_an_orientation_learns_its_reference(tmp_path):
    v, config = _three_commands(tmp_path, ["imu_no_orientation", "mag", "odom"], "mag")
    _check(v, "IMU_YAW")
    mag = validation_sections(config)[0].observers.magnetometer
    assert mag.strength_T == pytest.approx(np.hypot(20e-6, 40e-6), rel=0.02)
    assert mag.dip_deg == pytest.approx(np.degrees(np.arctan2(40, 20)), abs=1.0)


def test_an_imu_mounted_upside_down(tmp_path):
    v, _ = _three_commands(tmp_path, ["imu_down", "odom", "vo"], "odom")
    _check(v, "ODO_YAW", ("ODO",))


def test_streams_that_do_not_move_together_are_dropped_with_the_reason(tmp_path):
    bag = sensor_bag(["imu", "odom", "vo"], seed=1, unrelated=["vo"]).write(tmp_path / "run.bag")
    starter = tmp_path / "starter.yaml"
    starter.write_text(inspect_recording(bag, starter=True).starter)
    res = calibrate([bag], starter, tmp_path / "learnt.yaml")
    dropped = {name for name in res.dropped}
    assert {"yaw_vo_gyro", "yaw_odo_vo", "yaw_compass_vo"} <= dropped
    assert "yaw_odo_gyro" not in dropped and "yaw_compass_gyro" not in dropped
    assert "do not move together (correlation" in res.dropped["yaw_vo_gyro"].reason
    text = res.out.read_text()
    assert "# yaw_vo_gyro (trend, vo_yaw against gyro_yaw): dropped, the data do not support it" in text
    vcfg, _ = validation_sections(load_config(res.out))
    assert "yaw_vo_gyro" not in vcfg.model.relations and "yaw_vo_gyro" not in {r.name for r in vcfg.observers.relations}


def test_a_config_whose_every_relation_is_dropped_still_loads(tmp_path):
    """A magnetometer and an unrelated odometry: the relation goes, the field check stays."""
    bag = sensor_bag(["mag", "vo"], seed=1, unrelated=["vo"]).write(tmp_path / "run.bag")
    starter = tmp_path / "starter.yaml"
    starter.write_text(inspect_recording(bag, starter=True).starter)
    res = calibrate([bag], starter, tmp_path / "learnt.yaml")
    assert res.dropped
    vcfg, _ = validation_sections(load_config(res.out))
    assert vcfg.observers.relations == () and vcfg.observers.magnetometer.enabled


def test_the_compass_mounting_is_learnt_from_the_gps_course(tmp_path):
    bag = sensor_bag(["imu", "odom", "gps"], seed=1, heading_offset=np.radians(30.0)).write(tmp_path / "run.bag")
    starter = tmp_path / "starter.yaml"
    starter.write_text(inspect_recording(bag, starter=True).starter)
    res = calibrate([bag], starter, tmp_path / "learnt.yaml")
    assert res.applied_heading is not None
    assert load_config(res.out).input.compass.mounting_yaw_deg == pytest.approx(30.0, abs=2.0)
    assert "yaw_compass_gps" in {r.name for r in validation_sections(load_config(res.out))[0].observers.relations}


def test_held_out_folds():
    t = np.arange(0.0, 10.0, 0.1)

    def run(clean) -> CalibrationRun:
        from slam.commands.calibrate.runs import StepStreams

        return CalibrationRun("r", {}, StepStreams(t, {}, {}, {}), [], clean, False)

    one = run(np.ones(len(t), bool))
    (learn_a, _, judged_a), (learn_b, _, judged_b) = held_out([one])
    assert judged_a.sum() == judged_b.sum() == 50 and not (judged_a & judged_b).any()
    assert (learn_a[0].clean == judged_b).all() and (learn_b[0].clean == judged_a).all()
    three = [run(np.ones(len(t), bool)) for _ in range(3)]
    folds = held_out(three)
    assert [judged for _, judged, _ in folds] == [0, 1, 2]
    assert all(len(learning) == 2 and all(r is not three[i] for r in learning) for i, (learning, _, _) in enumerate(folds))


def test_a_simulated_run_with_a_laser_no_base_config(short_run, tmp_path, capsys):
    """The three commands on a run folder (ROS 2 bag: laser, IMU, magnetometer,
    odometry, and a GPS topic without a fix indoors), topics guessed, every
    stream with data validated."""
    run = str(short_run.run_dir)
    starter, learnt = tmp_path / "s.yaml", tmp_path / "l.yaml"
    assert main(["-q", "inspect", run, "--config-out", str(starter)]) == 0
    assert "proposed system model: 10 components" in capsys.readouterr().out
    assert main(["-q", "calibrate", run, "--config", str(starter), "--out", str(learnt)]) == 0
    assert main(["-q", "map", run, "--config", str(learnt), "--out", str(tmp_path / "m"), "--gating", "on"]) == 0
    vcfg, gating = validation_sections(load_config(learnt))
    assert {"SM_DIST", "SM_LAT", "SM_YAW", "IMU_GYRO", "IMU_YAW", "ODO_DIST"} <= set(vcfg.model.components)
    assert "GPS" not in vcfg.model.components
    assert vcfg.observers.scan.enabled and vcfg.observers.magnetometer.enabled
    assert (tmp_path / "m" / "validation.csv").exists()
