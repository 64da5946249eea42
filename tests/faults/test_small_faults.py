"""Accepted without a word, once: a library call or a command option that could not be right."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from fault_tools import assert_error, cli
from fusion_vo.backends import FusionConfig, StreamingFusion
from fusion_vo.errors import InputError
from fusion_vo.measurements import ImuSample, WheelTicks
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def test_streaming_fusion_sums_up_rejected_samples_in_a_note_and_a_few_warnings(caplog):
    """Non-finite samples were counted as gated with finish().notes empty (the README promises a note), and
    each one logged its own warning."""
    s = synthetic_streams(SyntheticOptions(duration=3.0), seed=3)
    fusion = StreamingFusion("ekf", FusionConfig(), ["wheel", "imu"], wheel_config=s.wheel.config,
                             imu_noise=s.imu.noise)
    msgs = sorted([(t, 1, "wheel", WheelTicks(t, l, r)) for t, l, r in zip(s.wheel.t, s.wheel.left, s.wheel.right)]
                  + [(t, 2, "imu", ImuSample(t, g, a)) for t, g, a in zip(s.imu.t, s.imu.gyro, s.imu.accel)],
                  key=lambda m: (m[0], m[1]))
    with caplog.at_level(logging.WARNING, logger="fusion_vo.backends.streaming"):
        for i, (t, _, kind, m) in enumerate(msgs):
            fusion.feed([(t, kind, m)])
            if i % 3 == 0:
                fusion.add_imu(ImuSample(t, np.array([np.nan, 0.0, 0.0]), np.zeros(3)))
            if i % 7 == 0:
                fusion.add_wheel(WheelTicks(t + 3600.0, 0, 0))  # an hour ahead
        result = fusion.finish()
    n_nan, n_ahead = len(range(0, len(msgs), 3)), len(range(0, len(msgs), 7))
    assert n_nan > 100
    assert result.counts["ekf"]["gyro"].gated == n_nan and result.counts["ekf"]["wheel"].gated == n_ahead
    notes = [n for n in result.notes if n.startswith("samples rejected")]
    assert notes == [f"samples rejected (counted as gated): gyro {n_nan} (a non-finite or malformed value), "
                     f"wheel {n_ahead} (more than 1 s ahead of the newest sample)"]
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING and "rejected" in r.getMessage()]
    assert len(warnings) == 2, warnings  # the first of each sensor and reason (the run takes well under 10 s)
    assert "1 so far" in warnings[0] and "1 so far" in warnings[1]


def test_an_odometry_configuration_with_an_unknown_frontend_is_refused():
    from fusion_vo.odometry import OdometryConfig

    with pytest.raises(ValueError, match="frontend: expected one of 'klt', 'features' or 'direct', got 'nope'"):
        OdometryConfig(frontend="nope")


@pytest.mark.parametrize("path", ["", "  "])
def test_a_recording_with_an_empty_name_is_not_the_current_folder(path, tmp_path, monkeypatch):
    from fusion_vo.recording import Recording

    monkeypatch.chdir(tmp_path)  # (an empty folder: Recording('') read it as a recording without streams)
    with pytest.raises(InputError, match="no recording folder given"):
        Recording(path)


@pytest.mark.parametrize("second, fragment", [
    ("0 0 0.4 0 0 0 base_link imu_link", "translations [0, 0, 0.5] and [0, 0, 0.4] m"),
    ("0 0 0.5 0 0 0 imu_link base_link", "translations [0, 0, 0.5] and [0, 0, -0.5] m"),  # the same pair, inverted
    ("0 0 0.5 0 0 1.0 base_link imu_link", "disagree"),  # the same offset, another rotation
])
def test_two_static_transforms_that_disagree_are_refused(second, fragment, tmp_path, capsys):
    first = "0 0 0.5 0 0 0 base_link imu_link"
    status, _, err = cli(capsys, "import-bag", tmp_path / "missing.bag", tmp_path / "rec", "--static-tf", first,
                         "--static-tf", second)
    assert_error(status, err, "two --static-tf transforms between", fragment)
    assert not (tmp_path / "rec").exists()


def test_the_same_static_transform_twice_or_inverted_is_accepted():
    from fusion_vo.recording.rosbag.transforms import check_consistent, parse_static_tf

    check_consistent([parse_static_tf("0 0 0.5 0 0 0 base_link imu_link"),
                      parse_static_tf("0 0 0.5 0 0 0 base_link imu_link"),
                      parse_static_tf("0 0 -0.5 0 0 0 imu_link base_link")])
