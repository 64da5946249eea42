"""The files of a generated recording: complete layout, determinism, counter wrap-around, dropped frames."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml

from fusion_vo.config.sensor_files import read_camera
from fusion_vo.recording.reader import Recording
from fusion_vo.simulation.mount import camera_mount
from fusion_vo.simulation.sensors import wrap_int32

BASE = {"duration": 8.0, "odometry": True, "range_finder": True}

HEADERS = {
    "cam0/data.csv": "#timestamp [ns],filename",
    "imu0/data.csv": "#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                     "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]",
    "wheel0/data.csv": "#timestamp [ns],left_ticks,right_ticks",
    "odom0/data.csv": "#timestamp [ns],v_x [m s^-1],v_y [m s^-1],w_z [rad s^-1]",
    "range0/data.csv": "#timestamp [ns],distance [m]",
    "state_groundtruth_estimate0/data.csv": "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],"
                                            "q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []",
}
SENSOR_KEYS = {
    "cam0/sensor.yaml": {"sensor_type", "rate_hz", "resolution", "camera_model", "intrinsics", "distortion_model",
                         "distortion_coefficients", "T_BS"},
    "imu0/sensor.yaml": {"T_BS", "rate_hz", "gyroscope_noise_density", "gyroscope_random_walk",
                         "accelerometer_noise_density", "accelerometer_random_walk"},
    "wheel0/sensor.yaml": {"ticks_per_revolution", "wheel_radius_left", "wheel_radius_right", "wheel_base"},
}


def integer_rows(path: Path, columns) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", comments="#", dtype=np.int64, usecols=columns, ndmin=2)


def all_files(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_layout_is_complete(generate):
    root = generate("base", seed=0, **BASE)
    for name, header in HEADERS.items():
        lines = (root / name).read_text().splitlines()
        assert lines[0] == header, name
        n_cols = header.count(",") + 1
        assert len(lines) > 10 and all(len(line.split(",")) == n_cols for line in lines[1:]), name
        t = np.array([int(line.split(",")[0]) for line in lines[1:]])
        assert np.all(np.diff(t) > 0), name
    for name, keys in SENSOR_KEYS.items():
        assert keys <= set(yaml.safe_load((root / name).read_text())), name
    frames = (root / "cam0/data.csv").read_text().splitlines()[1:]
    for line in frames:
        image = cv2.imread(str(root / "cam0/data" / line.split(",")[1]), cv2.IMREAD_UNCHANGED)
        assert image.shape == (48, 80) and image.dtype == np.uint8
    assert len(list((root / "cam0/data").iterdir())) == len(frames)
    # the project's own reader sees every stream, and the camera written is the one simulated
    rec = Recording(root)
    assert rec.streams() == ["cam0", "imu0", "odom0", "range0", "state_groundtruth_estimate0", "wheel0"]
    cam = read_camera(root / "cam0/sensor.yaml")
    assert (cam.width, cam.height, cam.fu, cam.cu) == (80, 48, 60.0, 39.5)
    np.testing.assert_allclose(cam.T_BS, camera_mount(0.25, 0.10), atol=1e-12)
    summary = yaml.safe_load((root / "simulation.yaml").read_text())["summary"]
    assert summary["frames"] == len(frames) == 8 * 20 + 1
    assert not list(root.parent.glob(".*partial*"))  # no temporary folder left behind


def test_same_seed_gives_identical_files(generate):
    first = all_files(generate("base", seed=0, **BASE))
    again = all_files(generate("base_again", seed=0, **BASE))
    assert first.keys() == again.keys()
    assert all(first[k] == again[k] for k in first)


def test_other_seed_gives_other_files(generate):
    first = all_files(generate("base", seed=0, **BASE))
    other = all_files(generate("base_seed1", seed=1, **BASE))
    for name in ("imu0/data.csv", "wheel0/data.csv", "state_groundtruth_estimate0/data.csv"):
        assert first[name] != other[name], name
    pngs = [k for k in first if k.endswith(".png")]
    assert pngs and all(first[k] != other[k] for k in pngs[1:])


def test_wheel_counters_wrap_around(generate):
    start = 2**31 - 300
    plain = integer_rows(generate("base", seed=0, **BASE) / "wheel0/data.csv", (1, 2))
    wrapped = integer_rows(generate("wrap", seed=0, wheel_start_count=start, **BASE) / "wheel0/data.csv", (1, 2))
    assert wrapped.min() >= -(2**31) and wrapped.max() <= 2**31 - 1
    jumps = np.diff(wrapped, axis=0)
    assert np.any(jumps < -(2**31))  # a counter passed 2**31 - 1 and went on from -2**31
    np.testing.assert_array_equal(wrapped, wrap_int32(plain + start))
    # differences taken modulo 2**32 are the true tick increments
    np.testing.assert_array_equal(wrap_int32(jumps), np.diff(plain, axis=0))


def test_dropped_frames_leave_gaps(generate):
    root = generate("dropped", seed=2, duration=4.0, dropped_frames=0.3)
    t = integer_rows(root / "cam0/data.csv", 0)[:, 0]
    period = 50_000_000  # ns at 20 Hz
    steps = np.diff(t)
    assert np.all(steps % period == 0)
    assert np.count_nonzero(steps > period) >= 5
    truth = yaml.safe_load((root / "simulation.yaml").read_text())
    assert truth["truth"]["dropped_frames"] == 81 - len(t) > 10
    assert len(list((root / "cam0/data").iterdir())) == len(t)
