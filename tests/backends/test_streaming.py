"""Streaming use: measurements arriving shuffled within the window, late ones counted, same answer as batch."""

import numpy as np
import pytest
from backend_synth import position_errors, streams_of

from fusion_vo.backends import FusionConfig, StreamingFusion, fuse
from fusion_vo.errors import InputError
from fusion_vo.measurements import ImuSample, RangeSample, WheelTicks
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


def _messages(s, rng, delay):
    msgs = [(v.t1, "visual", v) for v in s.visual]
    msgs += [(t, "wheel", WheelTicks(t, l, r)) for t, l, r in zip(s.wheel.t, s.wheel.left, s.wheel.right)]
    msgs += [(t, "imu", ImuSample(t, g, a)) for t, g, a in zip(s.imu.t, s.imu.gyro, s.imu.accel)]
    arrival = np.array([m[0] for m in msgs]) + rng.uniform(0.0, delay, len(msgs))
    return [msgs[i] for i in np.argsort(arrival)]


@pytest.fixture(scope="module")
def drive():
    s = synthetic_streams(SyntheticOptions(duration=10.0, visual_scale=1.02), seed=11)
    return s, fuse(streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"]), "all")


@pytest.mark.parametrize("backend, batch_name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_shuffled_arrivals_give_the_batch_online_estimate(drive, backend, batch_name):
    s, batch = drive
    stated = streams_of(s, stated_scale=1.02)  # the calibrations' uncertainties, as the batch run has them
    fusion = StreamingFusion(backend, FusionConfig(reorder_window=0.2), ["camera", "wheel", "imu"],
                             wheel_config=stated.wheel.config, imu_noise=s.imu.noise,
                             camera_height=s.camera_height, camera_height_sigma=stated.camera_height_sigma)
    assert fusion.current_estimate() is None
    for _, kind, m in _messages(s, np.random.default_rng(1), 0.1):
        getattr(fusion, f"add_{kind}")(m)
    now = fusion.current_estimate()
    assert now is not None and now.t > 9.0 and now.covariance.shape == (3, 3)
    result = fusion.finish()
    track = result.trajectories[batch_name]
    counts = result.counts[batch_name]
    assert counts["wheel"].reordered > 0 and counts["camera"].late == 0 and counts["wheel"].late == 0
    ref = batch.trajectories[batch_name]
    common = np.isin(np.round(ref.t, 9), np.round(track.t, 9))
    assert common.sum() > 0.95 * len(ref)
    ours = track.xyyaw[np.isin(np.round(track.t, 9), np.round(ref.t, 9))]
    assert np.max(np.abs(ours[:, :2] - ref.xyyaw[common, :2])) < 0.01
    assert position_errors(track, s.truth)[0] < 0.05


def test_measurements_later_than_the_window_are_counted_not_applied(drive):
    s, _ = drive
    fusion = StreamingFusion("ekf", FusionConfig(reorder_window=0.05), ["camera", "wheel", "imu"],
                             wheel_config=s.wheel.config, imu_noise=s.imu.noise)
    msgs = _messages(s, np.random.default_rng(2), 0.0)
    held = [m for m in msgs if m[1] == "wheel" and 4.0 < m[0] < 4.5]
    for m in msgs:
        if m not in held:
            getattr(fusion, f"add_{m[1]}")(m[2])
    for _, kind, m in held:  # arrive seconds late
        getattr(fusion, f"add_{kind}")(m)
    result = fusion.finish()
    assert result.counts["ekf"]["wheel"].late == len(held)
    assert any("late measurements not applied: wheel" in n for n in result.notes)


def test_undeclared_or_unconfigured_sensors_are_input_errors():
    with pytest.raises(InputError, match="wheel_config"):
        StreamingFusion("ekf", sensors=["wheel"])
    fusion = StreamingFusion("ekf", sensors=["imu"])
    with pytest.raises(InputError, match="not declared"):
        fusion.add_range(RangeSample(0.0, 0.1))
