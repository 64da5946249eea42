"""The node's settings: a run configuration with a ros2 section, ROS parameters over it, one validation.

No DDS here: :mod:`fusion_vo.ros2.settings` and :mod:`fusion_vo.ros2.sensors` do not import ROS.
"""

import subprocess
import sys

import pytest
import yaml

from fusion_vo.errors import InputError
from fusion_vo.ros2.sensors import NO_HORIZON, sensor_setup, streaming_fusion
from fusion_vo.ros2.settings import load_settings

pytestmark = pytest.mark.ros2


def test_parameters_override_the_file_key_by_key(tmp_path):
    (tmp_path / "calib" / "imu0").mkdir(parents=True)
    (tmp_path / "calib" / "imu0" / "sensor.yaml").write_text("T_BS: {rows: 4, cols: 4, data: [1,0,0,0, 0,1,0,0, "
                                                              "0,0,1,0, 0,0,0,1]}\ngyroscope_noise_density: 0.001\n")
    (tmp_path / "calib" / "odom0").mkdir()
    cfg = tmp_path / "node.yaml"
    cfg.write_text(yaml.safe_dump({"fusion": {"reorder_window": 0.1, "ekf": {"accel_sigma": 0.7}},
                                   "ros2": {"calibration": "calib", "publish_rate": 30.0}}))
    s = load_settings(cfg, {"backend": "gtsam", "fusion.ekf.accel_sigma": 0.4, "smoothed_lag": 1.5,
                            "use_sim_time": True})
    assert s.backend == "gtsam" and s.node.publish_rate == 30.0 and s.node.smoothed_lag == 1.5
    assert s.run.fusion.ekf.accel_sigma == 0.4 and s.run.fusion.reorder_window == 0.1
    assert s.calibration == tmp_path / "calib"  # relative to the file
    setup = sensor_setup(s)
    assert setup.sensors == ["imu", "odom"]  # those the calibration folder holds, as fusion-vo run does
    assert setup.imu_noise == {"gyroscope_noise_density": 0.001}
    fusion = streaming_fusion(s, setup)
    assert fusion.backend == "gtsam" and fusion.config.reorder_window == 0.1 and fusion.horizon == NO_HORIZON
    assert load_settings(None, {"sensors": "imu,odom"}).backend == "ekf"  # the node's default backend


def test_gps_with_the_isam2_backend_is_fused(tmp_path):
    """The node's iSAM2 takes GPS as its EKF does: the fixes and the antenna's lever arm of ``gps0/sensor.yaml``."""
    (tmp_path / "gps0").mkdir()
    (tmp_path / "gps0" / "sensor.yaml").write_text("T_BS: {rows: 4, cols: 4, data: [1,0,0,-0.1, 0,1,0,0.2, "
                                                   "0,0,1,0.5, 0,0,0,1]}\nhorizontal_sigma_m: 0.5\n")
    (tmp_path / "odom0").mkdir()
    s = load_settings(None, {"backend": "gtsam", "sensors": "odom,gps", "calibration": str(tmp_path)})
    setup = sensor_setup(s)
    fusion = streaming_fusion(s, setup)
    assert fusion.backend == "gtsam" and "gps" in fusion.sensors
    assert list(fusion._gps_lever[:2]) == [-0.1, 0.2]


@pytest.mark.parametrize("params, message", [
    ({"publish_rat": 5.0}, "unknown parameter 'publish_rat'"),
    ({"fusion.ekf.accel_sigmaa": 1.0}, "fusion.ekf.accel_sigmaa: unknown key"),
    ({"fusion.ekf.accel_sigma": "fast"}, "fusion.ekf.accel_sigma: expected a number"),
    ({"publish_rate": 0.0}, "publish_rate must be at least 0.001, not 0.0"),
    ({"backend": "all"}, "the node runs one streaming backend"),
    ({"smoothed_lag": 1.0}, "smoothed_lag: odometry/smoothed comes from the iSAM2 smoother"),
    ({"sensors": ["imu", "sonar"]}, "sensors"),
    ({"calibration": "/nonexistent/calib"}, "calibration: not a folder"),
])
def test_a_bad_parameter_is_one_error_naming_it(params, message):
    with pytest.raises(InputError) as err:
        load_settings(None, params)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_configuration_the_schema_rejects_names_the_file_and_key(tmp_path):
    cfg = tmp_path / "node.yaml"
    cfg.write_text("fusion: {ekf: {accel_sigma: -1}}\n")
    with pytest.raises(InputError, match=r"node.yaml: fusion.ekf: accel_sigma must be positive, not -1"):
        load_settings(cfg)
    cfg.write_text("ros2: {queue_depth: many}\n")
    with pytest.raises(InputError, match=r"node.yaml: ros2.queue_depth: expected an integer"):
        load_settings(cfg)


def test_a_camera_without_its_calibration_is_an_error():
    with pytest.raises(InputError, match="cam0/sensor.yaml"):
        sensor_setup(load_settings(None, {"sensors": ["camera", "imu"]}))


def test_importing_the_library_and_the_command_line_needs_no_ros():
    code = ("import sys, fusion_vo, fusion_vo.ros2.settings, fusion_vo.ros2.sensors; "
            "from fusion_vo.cli.main import build_parser; build_parser(); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('rclpy', 'nav_msgs', 'sensor_msgs')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_without_the_extra_the_commands_say_what_to_install():
    code = ("import sys; sys.modules['rclpy'] = None\n"
            "from fusion_vo.cli.main import main\nsys.exit(main(['ros2-play', '.']))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 2 and out.stderr.count("\n") == 1
    assert 'the ros2 commands need the ros2 extra: pip install "fusion-vo[ros2]"' in out.stderr
