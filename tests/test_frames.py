"""Frame conventions (``input.frames``, slam/readers/frames.py): a bag recorded
with NED conventions maps by config alone; large (UTM) references are
plotted relative to their start."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from slam.cli import main
from slam.config import StreamFrameConfig, load_config
from validation.base.geometry import wrap_angle
from slam.readers import frames
from slam.readers.read import read_recording
from slam.outputs.plots import relative_to_reference
from slam.recording import Trajectory
from tests.bagfactory import ned_driving_bag
from tests.conftest import CONFIGS

NED = StreamFrameConfig(world="ned")
FRD = StreamFrameConfig(body="frd")


def test_ned_poses_become_enu():
    # Driving north (NED x) then turning right (clockwise) towards east.
    x_ned, y_ned, psi = np.array([0.0, 1.0, 1.0]), np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, np.pi / 2])
    x, y, yaw = frames.planar_poses(x_ned, y_ned, psi, NED)
    assert x == pytest.approx([0, 0, 1]) and y == pytest.approx([0, 1, 1])
    assert yaw == pytest.approx([np.pi / 2, np.pi / 2, 0.0])  # north, then east: a right turn in ENU too
    # A reflection is its own inverse: ENU read as NED twice comes back.
    back = frames.planar_poses(*frames.planar_poses(x_ned, y_ned, psi, NED)[:2], np.pi / 2 - yaw, NED)
    assert back[0] == pytest.approx(x_ned) and back[1] == pytest.approx(y_ned)


def test_rates_headings_and_vectors():
    assert frames.yaw_rate(np.array([0.1]), FRD) == pytest.approx([-0.1])  # z down: a left turn is negative
    assert frames.yaw_rate(np.array([0.1]), FRD, "world") == pytest.approx([0.1])  # world z is still up
    assert frames.yaw_rate(np.array([0.1]), NED, "world") == pytest.approx([-0.1])
    assert frames.yaw_rate(np.array([0.1]), StreamFrameConfig(yaw_sign=-1)) == pytest.approx([-0.1])
    assert frames.heading(np.array([0.0, np.pi / 2]), NED) == pytest.approx([np.pi / 2, 0.0])
    assert frames.body_vector(np.array([[1.0, 2.0, 3.0]]), FRD).tolist() == [[1.0, -2.0, -3.0]]
    x, y, yaw = frames.planar_poses(np.array([1.0]), np.array([2.0]), np.array([0.3]), StreamFrameConfig(yaw_sign=-1))
    assert (x[0], y[0], yaw[0]) == pytest.approx((1.0, -2.0, -0.3))


def _config(tmp_path: Path, with_frames: bool, gyro_frd: bool = True) -> Path:
    data = yaml.safe_load((CONFIGS / "datasets" / "husky.yaml").read_text())
    data["validation"]["model"] = str(CONFIGS / "validation" / "telemax_model.yaml")
    data["input"]["topics"].update(odometry="/odom", groundtruth="/ground_truth")
    data["input"]["compass"]["mounting_yaw_deg"] = 0.0
    data["input"]["gyro"]["axis"] = "z"
    if with_frames:
        data["input"]["frames"] = {"gyro": {"body": "frd" if gyro_frd else "flu"}, "compass": {"world": "ned"},
                                   "odometry": {"world": "ned"}, "groundtruth": {"world": "ned"}}
    data["backend"]["initial_pose"] = "groundtruth"
    data["output"] = {"plots": False}
    path = tmp_path / f"frames_{with_frames}_{gyro_frd}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="module")
def ned_bag(tmp_path_factory) -> Path:
    bag, _ = ned_driving_bag()
    return bag.write(tmp_path_factory.mktemp("ned") / "ned.bag")


@pytest.mark.slow
def test_a_ned_bag_is_read_as_enu_by_config_alone(ned_bag, tmp_path):
    _, truth = ned_driving_bag()
    rec = read_recording(ned_bag, load_config(_config(tmp_path, True)).input)
    g = rec.gyro
    gyro_turn = np.sum(0.5 * (g.rate[1:] + g.rate[:-1]) * np.diff(g.t))
    odo_turn = np.unwrap(rec.odometry.yaw)[-1] - np.unwrap(rec.odometry.yaw)[0]
    true_turn = truth["yaw"][-1] - truth["yaw"][0]
    assert gyro_turn == pytest.approx(true_turn, abs=np.radians(3))
    assert odo_turn == pytest.approx(1.02 * true_turn, abs=np.radians(3))
    assert np.degrees(np.abs(wrap_angle(np.interp(rec.compass.t, truth["t"], truth["yaw"]) - rec.compass.yaw))).max() < 6
    gt = rec.groundtruth
    assert np.hypot(gt.x - np.interp(gt.t, truth["t"], truth["x"]), gt.y - np.interp(gt.t, truth["t"], truth["y"])).max() < 1e-6
    # Read as ENU (no frames), the gyro and the odometry turn opposite ways.
    plain = read_recording(ned_bag, load_config(_config(tmp_path, False)).input)
    assert np.sum(0.5 * (plain.gyro.rate[1:] + plain.gyro.rate[:-1]) * np.diff(plain.gyro.t)) == pytest.approx(-gyro_turn)


@pytest.mark.slow
def test_a_ned_bag_maps_with_gyro_compass_and_odometry_agreeing(ned_bag, tmp_path):
    metrics = {}
    for gyro_frd in (True, False):
        out = tmp_path / f"map_{gyro_frd}"
        assert main(["-q", "map", str(ned_bag), "--config", str(_config(tmp_path, True, gyro_frd)),
                     "--out", str(out), "--gating", "on"]) == 0
        metrics[gyro_frd] = json.loads((out / "metrics.json").read_text())
    framed, wrong = metrics[True], metrics[False]
    assert framed["alarm_fraction"] < 0.01
    assert min(framed["observer_coverage"].values()) > 0.8  # GPS speed: the warm-up of its 8 s windows
    assert framed["ate_rmse_m"] < 1.0
    # The gyro's z taken as up: it turns against the compass and the odometry.
    assert wrong["alarm_fraction"] > 0.1 and wrong["blamed_steps"].get("IMU_GYRO", 0) > 0


def test_frames_are_refused_for_formats_with_fixed_conventions(tmp_path):
    from slam.errors import GslamError

    cfg = load_config(None, ["input.frames.odometry.world=ned"]).input
    log = tmp_path / "x.log"
    log.write_text("FLASER 3 1 1 1 0 0 0 0 0 0 0 h 0\n")
    with pytest.raises(GslamError, match="input.frames: a carmen recording has fixed frame conventions"):
        read_recording(log, cfg)


def test_a_utm_reference_is_plotted_relative_to_its_start():
    t = np.arange(3.0)
    ref = Trajectory(t, 4.5e5 + t, 5.4e6 + t, np.zeros(3))
    anchored = Trajectory(t, 4.5e5 + t, 5.4e6 + 2 * t, np.zeros(3))
    at_origin = Trajectory(t, t, t, np.zeros(3))
    moved_ref, moved, origin = relative_to_reference(ref, {"a": anchored, "b": at_origin})
    assert origin.tolist() == [4.5e5, 5.4e6]
    assert moved_ref.x.tolist() == [0, 1, 2] and moved["a"].y.tolist() == [0, 2, 4]
    assert moved["b"] is at_origin
    assert relative_to_reference(at_origin, {"a": at_origin})[2] is None
