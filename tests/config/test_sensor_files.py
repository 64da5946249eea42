"""The models of the ``sensor.yaml`` files (:mod:`fusion_vo.config.sensor_files`)."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import yaml

from fusion_vo.config.sensor_files import CameraFile, ImuFile, WheelFile, uncalibrated_camera
from fusion_vo.errors import InputError

CAMERA = {"sensor_type": "camera", "comment": "EuRoC's own keys are left alone", "rate_hz": 20,
          "resolution": [640, 480], "camera_model": "pinhole", "intrinsics": [400.0, 401.0, 319.5, 239.5],
          "distortion_model": "radtan", "distortion_coefficients": [-0.1, 0.01, 0.0, 0.0]}


def _write(tmp_path, data) -> object:
    path = tmp_path / "sensor.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_a_camera_file_becomes_its_camera_model_with_the_lens_alias_resolved(tmp_path):
    cam = CameraFile.read(_write(tmp_path, CAMERA)).camera()
    assert (cam.width, cam.height, cam.fu, cam.fv, cam.cu, cam.cv) == (640, 480, 400.0, 401.0, 319.5, 239.5)
    assert cam.distortion_model == "radial-tangential" and list(cam.distortion) == [-0.1, 0.01, 0.0, 0.0]
    assert cam.T_BS[2, 3] == pytest.approx(0.1)  # the default mount: 0.1 m above the floor


def test_a_misspelt_optional_key_is_warned_about_naming_the_key_meant(tmp_path, caplog):
    path = _write(tmp_path, {**CAMERA, "hieght_sigma": 0.001})
    with caplog.at_level(logging.WARNING):
        assert CameraFile.read(path).height_sigma is None
    assert [r.getMessage() for r in caplog.records] == [f"{path}: unknown key 'hieght_sigma' (did you mean "
                                                        "'height_sigma'?)"]


def test_the_wheel_file_needs_its_four_keys_and_the_imu_file_none(tmp_path):
    with pytest.raises(InputError, match="missing key 'wheel_base'") as info:
        WheelFile.read(_write(tmp_path, {"ticks_per_revolution": 4096, "wheel_radius_left": 0.05,
                                         "wheel_radius_right": 0.05}))
    assert info.value.path == tmp_path / "sensor.yaml"
    imu = ImuFile.read(_write(tmp_path, {"gyroscope_noise_density": 1.7e-4, "accelerometer_random_walk": 0}))
    assert imu.noise() == {"gyroscope_noise_density": 1.7e-4, "accelerometer_random_walk": 0.0}
    assert np.array_equal(imu.pose(np.eye(4)), np.eye(4))


def test_a_configured_focal_length_replaces_the_file_s_intrinsics_unchecked(tmp_path):
    path = _write(tmp_path, {**CAMERA, "intrinsics": [1e-9, 1e-9, 0.0, 0.0]})
    with pytest.raises(InputError, match="intrinsics: focal lengths 1e-09, 1e-09 px"):
        uncalibrated_camera(path)
    cam = uncalibrated_camera(path, focal_length=500.0)
    assert (cam.fu, cam.fv, cam.cu, cam.cv, cam.distortion_model) == (500.0, 500.0, 319.5, 239.5, "none")
