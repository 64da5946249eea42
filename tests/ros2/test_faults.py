"""Bad input to the node over DDS: counted in diagnostics, reported once per topic, never stopping it.

The node runs iSAM2 with a smoothed pose 1 s behind. The peer publishes IMU and odometry at 100 Hz on the
wall clock, then NaN values, far-future, late
(older than the history) and out-of-order stamps, messages in a frame the node cannot use, images of an
unsupported encoding and of the wrong size, then good data again; it stops the node with SIGTERM. Start-up
mistakes (an unknown parameter, a configuration the schema rejects, malformed ROS arguments) are one line
and exit status 2.
"""

import numpy as np
import pytest


pytestmark = pytest.mark.ros2

CAM0 = """sensor_type: camera
rate_hz: 20.0
resolution: [640, 360]
camera_model: pinhole
intrinsics: [420.0, 420.0, 319.5, 179.5]
distortion_model: radial-tangential
distortion_coefficients: [0.0, 0.0, 0.0, 0.0]
T_BS: {cols: 4, rows: 4, data: [0.0, -1.0, 0.0, 0.25, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.1, 0.0, 0.0, 0.0, 1.0]}
"""


@pytest.fixture(scope="module")
def faults(tmp_path_factory, peer):
    tmp = tmp_path_factory.mktemp("faults")
    (tmp / "calib" / "cam0").mkdir(parents=True)
    (tmp / "calib" / "cam0" / "sensor.yaml").write_text(CAM0)
    spec = {"node": ["ros2", "--ros-args", "-p", f"calibration:={tmp / 'calib'}", "-p", "sensors:=[camera,imu,odom]",
                     "-p", "diagnostics_period:=0.25", "-p", "backend:=gtsam", "-p", "smoothed_lag:=1.0"],
            "inject": True, "signal": "SIGTERM"}
    return peer(tmp, spec)


def test_bad_messages_are_counted_and_the_node_goes_on(faults):
    diag = faults["diagnostics"]
    imu, odom, cam = diag["fusion_vo: imu"], diag["fusion_vo: odom"], diag["fusion_vo: camera"]
    assert int(imu["gyro.gated"]) >= 5  # NaN gyro
    assert int(odom["future"]) == 3  # stamped 1000 s ahead of the clock
    # five stamped 30 s back and one 50 ms back, each counted as it arrived: the five older than the 2 s history
    # are dropped (late), the other is fused in time order (by the fusion, ``wheel.reordered``, or, when a busy
    # node took both messages at once, by the intake's sort)
    assert int(odom["out_of_order"]) == 6 and int(imu["out_of_order"]) == 0, (odom, imu)
    assert int(odom["wheel.late"]) == 5, odom
    assert int(imu["unusable"]) == 10 and "frame 'elsewhere'" in imu["unusable_reason"], imu
    assert int(odom["unusable"]) == 10 and "child_frame_id 'wheel_frame'" in odom["unusable_reason"], odom
    assert int(cam["unusable"]) == 5 and "'32FC1' is not supported" in cam["unusable_reason"], cam
    assert imu["level"] == 1 and odom["level"] == 1 and cam["level"] == 1  # WARN
    after = [p for p in faults["poses"] if p["t"] > faults["bad_end"] + 0.5]
    assert len(after) > 20  # still publishing (50 Hz) after the bad messages


def test_the_smoother_pose_a_lag_behind_is_published(faults):
    """iSAM2 (``backend:=gtsam``) with ``smoothed_lag:=1.0``: odometry/smoothed trails the filtered pose."""
    smoothed, filtered = faults["smoothed"], faults["poses"]
    assert len(smoothed) > 5 and smoothed[-1]["frame"] == "odom"
    arrival = np.array([p["received"] for p in filtered])
    # against the filtered pose that arrived with it: the lag plus the 0.3 s reorder window
    behind = [filtered[int(np.argmin(abs(arrival - s["received"])))]["t"] - s["t"] for s in smoothed]
    assert 1.0 <= np.median(behind) <= 1.6, behind
    assert all(v > 0 for v in smoothed[-1]["var"])


def test_an_unusable_topic_is_reported_once_not_per_message(faults):
    reports = [line for line in faults["stderr"] if "messages cannot be used" in line]
    assert len(reports) == 3, reports  # /imu/data, /odom, /image: once each for 10, 10 and 5 messages
    assert {r.split(": messages")[0].split()[-1] for r in reports} == {"/imu/data", "/odom", "/image"}


def test_sigterm_stops_the_node_cleanly_within_two_seconds(faults):
    assert faults["code"] == 0, faults["stderr"][-5:]
    assert faults["exited"] - faults["signal_sent"] < 2.0
    assert faults["stderr"][-1] == "fusion-vo ros2: stopped"
    assert not [line for line in faults["stderr"] if "Traceback" in line]


@pytest.mark.parametrize("args, config, message", [
    (["-p", "publish_rat:=5.0"], None, "fusion-vo: error: unknown parameter 'publish_rat'"),
    ([], "fusion: {ekf: {accel_sigma: fast}}\n", "node.yaml: fusion.ekf.accel_sigma: expected a number, got 'fast'"),
    (["-p"], None, "fusion-vo: error: --ros-args:"),
])
def test_a_start_up_mistake_is_one_line_and_exit_2(tmp_path, args, config, message, peer):
    node = ["ros2"]
    if config is not None:
        (tmp_path / "node.yaml").write_text(config)
        node += ["--config", str(tmp_path / "node.yaml")]
    out = peer(tmp_path, {"node": node + ["--ros-args", "-p", "sensors:=[imu,odom]"] + args})
    assert not out["ready"] and out["code"] == 2, out
    errors = [line for line in out["stderr"] if line.startswith("fusion-vo: error:")]
    assert len(errors) == 1 and message in errors[0], out["stderr"]
    assert not [line for line in out["stderr"] if "Traceback" in line]
