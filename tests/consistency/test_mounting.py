"""The IMU's mounting and the wheels' signs from the data, on synthetic streams in memory."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from fusion_vo.backends import FusionConfig, fuse
from fusion_vo.consistency.mounting import rotation, static_tf, yaml_rows
from fusion_vo.consistency.stage import check_streams
from fusion_vo.recording.rosbag import parse_static_tf
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

sys.path.insert(0, str(Path(__file__).parents[1] / "backends"))
from backend_synth import streams_of  # noqa: E402

ON_ITS_SIDE = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
UPSIDE_DOWN = np.diag([1.0, -1.0, -1.0])


@pytest.fixture(scope="module")
def streams():
    """30 s of camera, wheels and an IMU whose accelerometer reads gravity, as stated."""
    return streams_of(synthetic_streams(SyntheticOptions(duration=30.0), seed=3)).select(["camera", "wheel", "imu"])


def mounted(streams, R_BS: np.ndarray, accel: bool = True):
    """The same streams from an IMU mounted with ``R_BS`` (its samples ``R_BSᵀ`` the body's), still stated as
    the identity."""
    imu = streams.imu
    return streams.replace(imu=dataclasses.replace(
        imu, gyro=imu.gyro @ R_BS, accel=imu.accel @ R_BS if accel else imu.accel))


def findings(checked) -> dict:
    return {f.check: f for f in checked.findings}


def test_transform_sentences_read_back_as_the_mounting():
    T = np.eye(4)
    T[:3, :3] = ON_ITS_SIDE
    T[:3, 3] = [0.0, -0.3, 0.52]
    np.testing.assert_allclose(parse_static_tf(static_tf(T)).T, T, atol=1e-4)
    np.testing.assert_allclose(np.array(yaml.safe_load(yaml_rows(T))).reshape(4, 4), T, atol=1e-4)
    assert static_tf(T) == "0.0 -0.3 0.52 -1.5708 0.0 1.5708 base_link imu_link"


def test_estimated_axes_snap_to_the_mounting_within_five_degrees():
    up = np.array([0.02, 0.999, 0.03])
    forward = np.array([0.05, -0.02, -0.998])
    np.testing.assert_array_equal(rotation(up / np.linalg.norm(up), forward / np.linalg.norm(forward), np.eye(3)),
                                  ON_ITS_SIDE)
    tilted = np.array([0.0, np.sin(0.2), np.cos(0.2)])  # 11.5°: a real tilt, kept
    R = rotation(tilted, None, np.eye(3))
    np.testing.assert_allclose(R[2], tilted, atol=1e-12)


@pytest.mark.parametrize("R_BS", [ON_ITS_SIDE, UPSIDE_DOWN], ids=["on its side", "upside down"])
def test_mounting_other_than_stated_is_corrected(streams, R_BS):
    checked = check_streams(mounted(streams, R_BS), FusionConfig())
    found = findings(checked)["mounting"]
    assert found.decision == "corrected", found
    np.testing.assert_allclose(checked.streams.imu.T_BS[2, :3], R_BS[2], atol=1e-12)
    assert "imu0/sensor.yaml: T_BS contradicts the data" in found.sentence and "--static-tf" in found.sentence


def test_mounting_without_gravity_is_corrected_from_the_gyro_alone(streams):
    broken = mounted(streams, ON_ITS_SIDE)
    broken = broken.replace(imu=dataclasses.replace(broken.imu, accel=np.zeros_like(broken.imu.accel)))
    found = findings(check_streams(broken, FusionConfig()))["mounting"]
    assert found.decision == "corrected" and found.estimate["gravity_z"] is None, found
    assert "heading about the vertical is kept as stated" in found.sentence


def test_gyro_and_gravity_that_disagree_leave_the_imu_out(streams):
    broken = mounted(streams, ON_ITS_SIDE, accel=False)
    checked = check_streams(broken, FusionConfig())
    assert findings(checked)["mounting"].decision == "refused" and checked.streams.imu is None
    result = fuse(broken, "ekf", FusionConfig())
    assert "gyro" not in result.counts["ekf"] and any("the IMU is left out" in n for n in result.notes)


def test_wheels_turning_the_other_way_are_the_liars_not_the_imu(streams):
    """Both encoders counting backwards: the wheels turn against the gyro, whose axis gravity confirms; the IMU is
    kept and the encoders are negated."""
    wheel = streams.wheel
    backwards = streams.replace(wheel=dataclasses.replace(wheel, left=-wheel.left, right=-wheel.right))
    checked = check_streams(backwards.replace(visual=None), FusionConfig())
    found = findings(checked)
    assert found["mounting"].decision == "kept" and found["mounting"].estimate["reference_reversed"]
    assert found["wheel sign"].decision == "corrected"
    assert "both encoders count backwards" in found["wheel sign"].sentence
    np.testing.assert_array_equal(checked.streams.wheel.left, wheel.left)


def test_valid_streams_are_fused_as_without_the_checks(streams):
    off = FusionConfig(consistency={"check": False})
    on = fuse(streams, "ekf", FusionConfig())
    assert {f["decision"] for f in on.consistency} == {"kept"}, on.consistency
    np.testing.assert_array_equal(on.trajectories["ekf"].xyyaw, fuse(streams, "ekf", off).trajectories["ekf"].xyyaw)


def test_gravity_alone_disagreeing_leaves_the_imu_as_stated_with_a_warning(streams):
    """The gyro turns about the stated axis (what the backends read); only the accelerometer's axes differ."""
    broken = streams.replace(imu=dataclasses.replace(streams.imu, accel=streams.imu.accel @ ON_ITS_SIDE))
    checked = check_streams(broken, FusionConfig())
    found = findings(checked)["mounting"]
    assert found.decision == "undecided" and "gravity lies 90° from it" in found.sentence, found
    assert checked.streams.imu is broken.imu
