"""A bad configuration is found before any work and blamed on the configuration file and the key."""

from __future__ import annotations

import pytest

from fault_tools import assert_error, cli

BAD = {
    "negative_height": ("odometry: {height: -0.1}", "odometry.height"),
    "text_height": ("odometry: {height: abc}", "odometry.height: expected a number"),
    "nan_height": ("odometry: {height: .nan}", "odometry.height"),
    "text_window": ("klt: {window: thirteen}", "klt.window: expected"),
    "even_window": ("klt: {window: 4}", "klt"),
    "unknown_feature_key_of_the_frontend_not_used": ("features: {bogus: 1}", "features"),
    "unknown_fusion_key": ("fusion: {bogus: 1}", "fusion"),
    "fusion_text_number": ("fusion: {ekf: {accel_sigma: fast}}", "accel_sigma"),
    "backend": ("backend: kalman", "backend"),
    "sensor": ("sensors: [camera, lidar]", "lidar"),
    "section": ("odometri: {}", "odometri"),
    "not_a_mapping": ("- a\n- list", "mapping"),
    "invalid_yaml": ("klt: {window: [5\n", "not valid YAML"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_config_error_names_the_config_file_before_any_work(name, pristine, tmp_path, capsys, monkeypatch):
    text, fragment = BAD[name]
    cfg = tmp_path / "my-config.yaml"
    cfg.write_text(text + "\n")

    def no_work(*args, **kwargs):
        raise AssertionError("visual odometry started with a bad configuration")

    monkeypatch.setattr("fusion_vo.pipeline.run_visual_odometry", no_work)
    status, _, err = cli(capsys, "run", pristine, "--out", tmp_path / "out", "--config", cfg)
    assert_error(status, err, f"{cfg}", fragment)
    assert "cam0/sensor.yaml" not in err
    assert not (tmp_path / "out").exists()


def test_a_sensor_the_recording_lacks_names_the_folder(recording, tmp_path, capsys):
    import shutil

    shutil.rmtree(recording / "imu0")
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--sensors", "camera,imu")
    assert_error(status, err, "imu0/", "sensors to use include 'imu'")
    assert "was asked for" not in err
