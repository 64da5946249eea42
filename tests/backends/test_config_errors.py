"""A configured sigma that is zero, negative or NaN is a one-line error naming the key."""

from pathlib import Path

import pytest

from fusion_vo.backends import FusionConfig
from fusion_vo.cli.main import main
from fusion_vo.config.files import validate
from fusion_vo.errors import InputError


@pytest.mark.parametrize("options, message", [
    ({"imu": {"gyro_noise_density": 0.0}}, "imu: gyro_noise_density must be positive, not 0.0"),
    ({"odom": {"k": float("nan")}}, "odom: k must be a finite number, not nan"),
    ({"visual_scale_sigma": -0.01}, "visual_scale_sigma must be positive, not -0.01"),
    ({"range": {"sigma": 0.0}}, "range: sigma must be positive, not 0.0"),
    ({"imu": {"ahrs_offset_walk": -0.1}}, "imu: ahrs_offset_walk must be at least 0, not -0.1"),
    ({"visual_frame_error": -0.1}, "visual_frame_error must be at least 0, not -0.1"),
    ({"visual_frame_error": 1.0}, "visual_frame_error must be below 1, not 1.0"),
    ({"visual_frame_error": float("nan")}, "visual_frame_error must be a finite number, not nan"),
])
def test_bad_sigma_names_the_key(options, message):
    with pytest.raises(ValueError) as exc:  # (ConfigError)
        FusionConfig.from_dict(options)
    assert str(exc.value) == f"FusionConfig: {message}"
    with pytest.raises(InputError) as exc:  # read from a file: the file and the key path
        validate(FusionConfig, options, "run.yaml", ("fusion",))
    section, _, rest = message.partition(": ")
    assert str(exc.value) == (f"run.yaml: fusion.{section}: {rest}" if rest else f"run.yaml: fusion: {message}")


def test_zero_offset_walk_and_yaw_scale_are_allowed():
    cfg = FusionConfig.from_dict({"imu": {"ahrs_offset_walk": 0.0}, "wheel": {"yaw_scale": 0.0}})
    assert cfg.imu.ahrs_offset_walk == 0.0


def test_cli_exits_2_on_a_bad_sigma(tmp_path, capsys):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("fusion:\n  imu:\n    gyro_noise_density: .nan\n")
    seq = tmp_path / "seq"
    bag = Path(__file__).resolve().parents[1] / "data" / "robot_localization" / "test2.bag"
    assert main(["import-bag", str(bag), str(seq), "--imu-topic", "/imu/data",
                 "--odom-topic", "/jackal_velocity_controller/odom"]) == 0
    capsys.readouterr()
    code = main(["run", str(seq), "--out", str(tmp_path / "out"), "--config", str(cfg)])
    err = capsys.readouterr().err
    assert code == 2 and f"{cfg}: fusion.imu: gyro_noise_density must be a finite number, not nan" in err, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out" / "ekf.tum").exists()
