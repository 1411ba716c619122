"""Further odometry sources (``input.extra_odometry``): read from a bag in
their own frame and time, validation streams and components of their own,
and configs that name them checked."""

from __future__ import annotations

import numpy as np
import pytest

from bagfactory import sensor_bag
from slam.config import InputConfig, load_config
from slam.errors import GslamError
from slam.readers.read import read_recording
from validation.streams import stream_component, validation_streams
from validation.streams.names import is_angular, is_integrated, is_stream_name, split_source_stream


@pytest.fixture(scope="module")
def vo_bag(tmp_path_factory):
    return sensor_bag(["imu", "odom", "vo"], duration_s=40.0).write(tmp_path_factory.mktemp("vo") / "vo.bag")


def _input(**extra) -> InputConfig:
    topics = {"scan": None, "gyro": "/imu/data", "compass": None, "odometry": "/odom", "gps": None,
              "groundtruth": None}
    return InputConfig.model_validate({"topics": topics, "extra_odometry": {"vo": {"topic": "/vo/odom", **extra}}})


def test_a_further_odometry_source_is_read_in_its_own_frame_and_time(vo_bag):
    rec = read_recording(vo_bag, _input())
    vo, odo = rec.extra_odometry["vo"], rec.odometry
    assert len(vo.t) == 40 * 100 // 7 + 1 and len(odo.t) == 800
    # The visual odometry starts 3 m off in a frame turned 0.7 rad.
    assert vo.x[0] == pytest.approx(3.0) and vo.y[0] == pytest.approx(-1.0) and vo.yaw[0] == pytest.approx(0.7)
    shifted = read_recording(vo_bag, _input(time_offset_s=0.25)).extra_odometry["vo"]
    np.testing.assert_allclose(shifted.t, vo.t + 0.25)
    mirrored = read_recording(vo_bag, _input(frame={"yaw_sign": -1})).extra_odometry["vo"]
    np.testing.assert_allclose(mirrored.yaw, -vo.yaw, atol=1e-12)


def test_its_streams_and_components_are_its_own(vo_bag):
    rec = read_recording(vo_bag, _input())
    streams = validation_streams(rec)
    names = {f"vo_{q}" for q in ("yaw", "distance", "forward", "lateral", "speed", "fix_speed")}
    assert names <= set(streams)
    assert stream_component("vo_yaw") == "VO_YAW" and stream_component("vo_lateral") == "VO_DIST"
    assert stream_component("odo_lateral") == "ODO_DIST" and stream_component("sm_lateral") == "SM_LAT"
    assert is_angular("vo_yaw") and not is_angular("vo_forward")
    assert is_integrated("vo_forward") and not is_integrated("vo_speed")
    # The turns of the two odometries agree to their errors (1 % and 2 %).
    turn = lambda s: s.values[-1] - s.values[0]  # noqa: E731
    assert turn(streams["vo_yaw"]) == pytest.approx(turn(streams["odo_yaw"]), rel=0.05)


def test_stream_names():
    assert is_stream_name("vo_yaw") and is_stream_name("wheels2_fix_speed") and is_stream_name("gps_speed")
    assert not is_stream_name("gps_yaw") and not is_stream_name("vo_heading") and not is_stream_name("VO_yaw")
    assert split_source_stream("vo_fix_speed") == ("vo", "fix_speed")
    assert split_source_stream("mag_strength") is None


def _config(tmp_path, extra: str, relation: str) -> str:
    path = tmp_path / "c.yaml"
    path.write_text(f"""\
input:
  topics: {{scan: null, gyro: /imu/data, compass: null, odometry: /odom, gps: null, groundtruth: null}}
{extra}
validation:
  model:
    components: [ODO_DIST, ODO_YAW, VO_DIST, VO_YAW, IMU_GYRO]
    relations: {{yaw_vo_gyro: [VO_YAW, IMU_GYRO]}}
  observers:
    magnetometer: {{enabled: false}}
    gps: {{enabled: false}}
    relations:
      - {{name: yaw_vo_gyro, stream_a: {relation}, stream_b: gyro_yaw, boundary: 0.05, window_s: 2.0, threshold: 10}}
gating:
  factors: {{odometry: [ODO_DIST], gyro: [IMU_GYRO]}}
""")
    return str(path)


def test_configs_naming_a_source_are_checked(tmp_path):
    declared = "  extra_odometry: {vo: {topic: /vo/odom}}"
    config = load_config(_config(tmp_path, declared, "vo_yaw"))
    assert config.input.extra_odometry["vo"].topic == "/vo/odom"
    with pytest.raises(GslamError, match=r"stream 'vo_yaw' is odometry source 'vo', which input.extra_odometry "
                                         r"does not declare \(declared: none\)"):
        load_config(_config(tmp_path, "", "vo_yaw"))
    with pytest.raises(GslamError, match="unknown stream 'vo_heading'"):
        load_config(_config(tmp_path, declared, "vo_heading"))
    with pytest.raises(GslamError, match="odometry source name 'gps' is taken"):
        load_config(_config(tmp_path, "  extra_odometry: {gps: {topic: /vo/odom}}", "odo_yaw"))


def test_other_formats_have_no_further_sources(tmp_path):
    log = tmp_path / "x.log"
    log.write_text("")
    with pytest.raises(GslamError, match="input.extra_odometry: a carmen recording has no topics"):
        read_recording(log, InputConfig.model_validate({"format": "carmen",
                                                        "extra_odometry": {"vo": {"topic": "/vo"}}}))
