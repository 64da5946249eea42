"""A bad configuration is found before any work and blamed on the configuration file and the key."""

from __future__ import annotations

import re

import pytest

from fault_tools import assert_error, cli
from frontends.direct import DirectConfig
from frontends.features import FeatureConfig
from frontends.klt import KltConfig
from frontends.similarity import RobustOptions
from fusion_vo.backends.config import FusionConfig
from fusion_vo.config import validate_config
from fusion_vo.config.render import json_schema
from fusion_vo.errors import InputError
from fusion_vo.odometry import OdometryConfig

BAD = {
    "negative_height": ("odometry: {height: -0.1}", "odometry: height must be positive, not -0.1"),
    "text_height": ("odometry: {height: abc}", "odometry.height: expected a number"),
    "nan_height": ("odometry: {height: .nan}", "odometry: height must be a finite number, not nan"),
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
    "zero_lk_iterations": ("klt: {lk_iterations: 0}", "klt: lk_iterations must be at least 1, not 0"),
    # a cell of 1e-9 px made a grid that OpenCV refused ("Maximum allowed dimension exceeded"), a traceback
    "grid_cell_below_a_pixel": ("klt: {grid_cell: 1.0e-9}",
                                "klt: grid_cell must be 0 (no grid) or at least 16 px, not 1e-09"),
    # accepted, then every frame failed inside OpenCV and the run exited 0
    "max_tracks_without_bound": ("klt: {max_tracks: 100000000000}",
                                 "klt: max_tracks must be at most 10000, not 100000000000"),
    "negative_reweight_passes": ("fusion: {graph: {reweight_passes: -1}}",
                                 "fusion.graph: reweight_passes must be at least 0, not -1"),
    # PyYAML keeps the last of two equal keys: the first section's values were lost without a word
    "section_twice": ("fusion:\n  max_gap: 1.0\nfusion:\n  reorder_window: 0.1",
                      "my-config.yaml:3: not valid YAML (key 'fusion' given twice (first on line 1))"),
    "key_twice": ("fusion:\n  max_gap: 1.0\n  max_gap: 2.0", "my-config.yaml:3: not valid YAML (key 'max_gap' given twice"),
    # Python refuses to convert it ('Exceeds the limit (4300 digits)'): an internal error
    "integer_of_5001_digits": ("odometry:\n  threads: " + "9" * 5001,
                               "my-config.yaml:2: not valid YAML (an integer of 5001 characters is no setting)"),
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


#: values that cannot work, once accepted (some silently giving a wrong answer): (YAML, the start of the message)
OUT_OF_RANGE = [
    ("klt: {lk_iterations: 0}", "klt: lk_iterations must be at least 1, not 0"),
    ("klt: {min_sigma: -1}", "klt: min_sigma must be at least 0, not -1"),
    ("direct: {min_sigma: -1}", "direct: min_sigma must be at least 0, not -1"),
    ("features: {min_sigma: -1}", "features: min_sigma must be at least 0, not -1"),
    ("klt: {fb_threshold: -1}", "klt: fb_threshold must be positive, not -1"),
    ("klt: {min_inliers: 0}", "klt: min_inliers must be at least 2, not 0"),
    ("klt: {global_downsample: 0}", "klt: global_downsample must be at least 1, not 0"),
    ("klt: {min_texture: .inf}", "klt: min_texture must be a finite number, not inf"),
    ("features: {ratio: .nan}", "features: ratio must be a finite number, not nan"),
    ("odometry: {min_sigma_xy: -1}", "odometry: min_sigma_xy must be at least 0, not -1"),
    ("odometry: {max_bad_start_frames: -3}", "odometry: max_bad_start_frames must be at least 1, not -3"),
    ("fusion: {graph: {reweight_passes: -1}}", "fusion.graph: reweight_passes must be at least 0, not -1"),
    ("fusion: {graph: {max_iterations: 0}}", "fusion.graph: max_iterations must be at least 1, not 0"),
    ("fusion: {graph: {keyframe_every: 0}}", "fusion.graph: keyframe_every must be at least 1, not 0"),
    ("fusion: {imu: {spike_window: -1}}", "fusion.imu: spike_window must be at least 0, not -1"),
    ("fusion: {monitor_whole_fraction: 1.5}", "fusion: monitor_whole_fraction must be at most 1, not 1.5"),
    ("fusion: {range: {min_range: 3}}", "fusion.range: min_range must be below max_range (2), not 3"),
    ("fusion: {wheel: {k: 0}}", "fusion.wheel: k must be positive, not 0"),
    ("fusion: {ekf: {accel_sigma: 1.0e+300}}", "fusion.ekf: accel_sigma must be at most 1000, not 1e+300"),
    ("fusion: {initial_velocity_sigma: 1.0e+300}", "fusion: initial_velocity_sigma must be at most 1000, not 1e+300"),
    ("fusion: {gps: {kernel: tukey}}", "fusion.gps.kernel: expected one of 'huber', 'cauchy' or 'none', got 'tukey'"),
    ("fusion: {visual_noise: {min_intervals: 99}}", "fusion.visual_noise: min_intervals must be at least 100, not 99"),
]

_SECTIONS = {"klt": KltConfig, "features": FeatureConfig, "direct": DirectConfig, "odometry": OdometryConfig,
             "fusion": FusionConfig}


def _number_schema(cls, name):
    """The JSON schema of the number field ``name`` of ``cls`` (of its number branch when it may be null)."""
    prop = json_schema(cls)["properties"][name]
    return next((p for p in prop.get("anyOf", [prop]) if p.get("type") in ("number", "integer")), prop)


def _outside(cls, name):
    """Values of the field ``name`` of ``cls`` just outside each end of its range (as its schema states it)."""
    prop = _number_schema(cls, name)
    kind = int if prop["type"] == "integer" else float
    if "minimum" in prop:
        yield kind(prop["minimum"] - 1)
    if "exclusiveMinimum" in prop:
        yield kind(prop["exclusiveMinimum"])
    if "maximum" in prop:
        yield kind(prop["maximum"] + 1)
    if "exclusiveMaximum" in prop:
        yield kind(prop["exclusiveMaximum"])


def _ranged(cls):
    """The fields of ``cls`` whose schema states a range."""
    props = json_schema(cls)["properties"]
    return [name for name in props if {"minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"}
            & set(_number_schema(cls, name))]


#: besides, every field with a range, just outside it
EVERY_RANGE = [(section, name, value) for section, cls in _SECTIONS.items() for name in _ranged(cls)
               for value in _outside(cls, name)]


# ------------------------------------------------------------------ vectors and upper bounds of the backends' options
#: once accepted: a NaN pose made every fused pose NaN with exit status 0; the upper bounds stop a typo from making
#: a run that never ends (``step_hz: 1e9``) or exhausts the machine (``odometry.threads: 100000``)
FUSION_BAD = [
    ("fusion: {initial_pose: [.nan, 0, 0]}", "fusion: initial_pose must be three finite numbers (x, y, yaw), not [nan"),
    ("fusion: {initial_pose: [0, .inf, 0]}", "fusion: initial_pose must be three finite numbers"),
    ("fusion: {initial_pose: [0, 0]}", "fusion: initial_pose must be three finite numbers"),
    ("fusion: {initial_pose: [0, 0, 0, 0]}", "fusion: initial_pose must be three finite numbers"),
    ("fusion: {initial_pose: [a, 0, 0]}", "fusion: initial_pose must be three finite numbers"),
    ("fusion: {initial_pose: [true, 0, 0]}", "fusion: initial_pose must be three finite numbers"),
    ("fusion: {initial_pose: [0, 0, null]}", "fusion: initial_pose must be three finite numbers"),
    ("fusion: {initial_pose: [[0], 0, 0]}", "fusion: initial_pose must be three finite numbers"),
    ("fusion: {initial_pose: [1.0e+300, 0, 0]}", "fusion.initial_pose[0]: must be at most 10000000, not 1e+300"),
    ("fusion: {initial_pose: [0, 0, 7]}", "fusion.initial_pose[2]: must be at most 6.28"),
    ("fusion: {camera_height: .nan}", "fusion: camera_height must be a finite number, not nan"),
    ("fusion: {camera_height: 0}", "fusion: camera_height must be positive, not 0"),
    ("fusion: {camera_height: 1.0e+300}", "fusion: camera_height must be at most 100, not 1e+300"),
    ("fusion: {step_hz: 1.0e9}", "fusion: step_hz must be at most 1000, not '1.0e9'"),
    ("fusion: {graph: {max_iterations: 100000}}", "fusion.graph: max_iterations must be at most 1000"),
    ("fusion: {graph: {reweight_passes: 11}}", "fusion.graph: reweight_passes must be at most 10"),
    ("fusion: {max_odom_delay: 1.0e6}", "fusion: max_odom_delay must be at most 10"),
    ("fusion: {imu: {spike_window: 100000}}", "fusion.imu: spike_window must be at most 50"),
    ("odometry: {threads: 100000}", "odometry: threads must be at most 256, not 100000"),
    ("odometry: {height: 1.0e+300}", "odometry: height must be at most 100, not 1e+300"),
    ("fusion: {imu: {gyro_random_walk: 1.0e10}}", "fusion.imu: gyro_random_walk must be at most 1000"),
    ("fusion: {max_gap: 1.0e+300}", "fusion: max_gap must be at most 1000000, not 1e+300"),
    ("fusion: {range: {max_range: 1.0e+300}}", "fusion.range: max_range must be at most 1000000"),
    ("fusion: {initial_pose: [0, 0, 100]}", "fusion.initial_pose[2]: must be at most 6.28"),
    ("fusion: {consistency: {mounting_min_fit: 1.5}}", "fusion.consistency: mounting_min_fit must be at most 1"),
    ("fusion: {consistency: {mounting_tolerance_deg: 120}}",
     "fusion.consistency: mounting_tolerance_deg must be at most 90, not 120"),
]


@pytest.mark.parametrize("text, message", OUT_OF_RANGE + FUSION_BAD + [
    (f"{section}: {{{name}: {value!r}}}", f"{section}: {name} must be ") for section, name, value in EVERY_RANGE],
    ids=[t for t, _ in OUT_OF_RANGE + FUSION_BAD] + [f"{s}.{n}={v!r}" for s, n, v in EVERY_RANGE])
def test_a_value_that_cannot_work_is_one_line_naming_the_key(text, message, tmp_path):
    import yaml

    path = tmp_path / "run.yaml"
    with pytest.raises(InputError) as err:
        validate_config(yaml.safe_load(text), path)
    assert str(err.value).startswith(f"{path}: {message}")
    assert "\n" not in str(err.value)
    section, values = next(iter(yaml.safe_load(text).items()))
    if section in _SECTIONS:  # library users get the same error from the model
        expected = message.split(": ", 1)[1]
        with pytest.raises(ValueError, match=re.escape(expected.split(" must ")[0] + " must " if " must " in expected
                                                       else expected)):
            _SECTIONS[section](**values)


def test_every_default_is_in_range_and_every_range_names_a_field():
    for cls in (*_SECTIONS.values(), RobustOptions):
        cls()  # every model checks its defaults against its ranges too
    assert len(EVERY_RANGE) > 150
    validate_config({})




def test_the_upper_bounds_themselves_and_a_pose_pass():
    validate_config({"fusion": {"step_hz": 1000, "max_odom_delay": 10, "initial_pose": [1, -2.5, 3.1],
                                "graph": {"max_iterations": 1000, "reweight_passes": 10}, "imu": {"spike_window": 50}},
                     "odometry": {"threads": 256}})
    import numpy as np

    assert FusionConfig(initial_pose=np.array([1.0, 2.0, 0.5])).initial_pose == (1.0, 2.0, 0.5)  # an array will do
    with pytest.raises(ValueError, match="^FusionConfig: initial_pose must be three finite numbers"):
        FusionConfig(initial_pose=(float("nan"), 0.0, 0.0))


@pytest.mark.parametrize("text, key", [("fusion: {initial_pose: [.nan, 0, 0]}", "initial_pose"),
                                       ("odometry: {threads: 100000}", "threads"),
                                       ("fusion: {step_hz: 1.0e9}", "step_hz")])
def test_run_stops_before_any_work_on_a_nan_pose_or_a_work_setting_too_large(text, key, pristine, tmp_path, capsys,
                                                                            monkeypatch):
    """(the NaN pose ran with --no-evaluate and exited 0 with an ekf.tum of NaN)"""
    cfg = tmp_path / "my-config.yaml"
    cfg.write_text(text + "\n")

    def no_work(*args, **kwargs):
        raise AssertionError("visual odometry started with a bad configuration")

    monkeypatch.setattr("fusion_vo.pipeline.run_visual_odometry", no_work)
    status, _, err = cli(capsys, "run", pristine, "--out", tmp_path / "out", "--config", cfg, "--no-evaluate",
                         "--backend", "ekf")
    assert_error(status, err, f"{cfg}", key)
    assert not (tmp_path / "out").exists()


def test_a_configured_focal_length_out_of_range_for_the_image_names_the_key(pristine, tmp_path, capsys, monkeypatch):
    """(1e-9 px, accepted, ended a run 1.9e11 m away)"""
    cfg = tmp_path / "my-config.yaml"
    cfg.write_text("odometry: {uncalibrated: true, focal_length: 1.0e-9}\n")

    def no_work(*args, **kwargs):
        raise AssertionError("visual odometry started with a bad configuration")

    monkeypatch.setattr("fusion_vo.pipeline.run_visual_odometry", no_work)
    status, _, err = cli(capsys, "run", pristine, "--out", tmp_path / "out", "--config", cfg)
    assert_error(status, err, f"{cfg}: odometry: focal_length: focal lengths 1e-09, 1e-09 px are not a camera's "
                              "for a 160x120 image")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("leaf, value", [("initial", 1e300), ("sigma", 1e300), ("random_walk", 1e300)])
def test_a_registered_state_s_prior_has_a_range(leaf, value):
    from fusion_vo.sensors.registry import StatePrior

    with pytest.raises(ValueError, match=f"StatePrior: {leaf} must be at most 1000"):
        StatePrior(**{leaf: value})
