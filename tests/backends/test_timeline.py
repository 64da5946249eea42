"""Merging streams on the node grid: rates, jitter, order, gaps, missing sensors, configuration."""

import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, SensorStreams, build_intervals
from fusion_vo.backends.timeline import node_times, time_order
from fusion_vo.errors import InputError
from fusion_vo.measurements import VisualIncrement, WheelConfig, WheelData
from fusion_vo.sensors.visual import camera_grid
from fusion_vo.sensors.wheel import wheel_grid

CFG = WheelConfig(4096.0, 0.05, 0.05, 0.4)
PER_TICK = 2 * np.pi * 0.05 / 4096.0


def _wheel(t, speed=0.5):
    ticks = np.round(speed * t / PER_TICK).astype(np.int64)
    return WheelData(t, ticks, ticks, CFG)


def _visual(times):
    return [VisualIncrement(a, b, np.array([0.5 * (b - a), 0, 0]), np.eye(3) * 1e-6) for a, b in zip(times[:-1], times[1:])]


def test_grid_has_every_frame_and_fills_gaps_where_other_streams_have_samples():
    cam = np.r_[np.arange(0, 2, 0.05), np.arange(3, 4, 0.05)]  # one second without frames
    wheel = _wheel(np.arange(0, 4, 0.02))
    grid = node_times(SensorStreams(visual=_visual(cam), wheel=wheel), FusionConfig(step_hz=20.0))
    assert np.all(np.isin(np.round(cam, 9), np.round(grid, 9)))
    assert np.max(np.diff(grid)) <= 0.05 + 1e-9
    # the camera alone: nothing was sampled in that second, so no node is put there
    alone = node_times(SensorStreams(visual=_visual(cam)), FusionConfig(step_hz=20.0))
    np.testing.assert_allclose(np.sort(alone), np.unique(np.round(cam, 9)), atol=1e-9)


def test_grid_without_camera_is_uniform():
    grid = node_times(SensorStreams(wheel=_wheel(np.linspace(0, 2, 101))), FusionConfig(step_hz=10.0))
    np.testing.assert_allclose(np.diff(grid), 0.1, atol=1e-9)


def test_interval_travel_is_exact_for_jittered_rates():
    rng = np.random.default_rng(0)
    tw = np.sort(np.arange(0, 3, 0.02) + rng.uniform(-0.004, 0.004, 150))
    cam = np.arange(0.05, 2.9, 0.05) + rng.uniform(-0.002, 0.002, 57)
    iv = build_intervals(SensorStreams(visual=_visual(cam), wheel=_wheel(tw)), FusionConfig())
    inside = wheel_grid(iv).ok
    assert inside.sum() > 50
    np.testing.assert_allclose(wheel_grid(iv).dl[inside], 0.5 * iv.dt[inside], atol=2 * PER_TICK)


def test_out_of_order_samples_are_reordered_and_counted():
    t = np.linspace(0, 2, 101)
    w = _wheel(t)
    order = np.arange(101)
    order[[30, 31]] = order[[31, 30]]
    order[[70, 71]] = order[[71, 70]]
    shuffled = WheelData(t[order], w.left[order], w.right[order], CFG)
    a = build_intervals(SensorStreams(wheel=w), FusionConfig())
    b = build_intervals(SensorStreams(wheel=shuffled), FusionConfig())
    assert b.counts["wheel"].reordered == 2 and a.counts["wheel"].reordered == 0
    np.testing.assert_array_equal(wheel_grid(a).dl, wheel_grid(b).dl)
    idx, n_re, n_dup = time_order(np.array([0.0, 0.2, 0.1, 0.2, 0.3]))
    assert (n_re, n_dup) == (1, 1) and list(idx) == [0, 2, 1, 4]


def test_a_stream_that_stops_is_reported_missing():
    iv = build_intervals(SensorStreams(visual=_visual(np.arange(0, 4, 0.05)), wheel=_wheel(np.linspace(0, 2, 101))),
                         FusionConfig())
    assert iv.counts["wheel"].missing > 30
    assert any(n.startswith("wheel unavailable from t=2.00 (2.00 s in)") for n in iv.notes)


def test_missing_or_unknown_sensor_is_an_input_error():
    streams = SensorStreams(wheel=_wheel(np.linspace(0, 2, 101)))
    with pytest.raises(InputError, match="'imu' was asked for"):
        streams.select(["wheel", "imu"])
    with pytest.raises(InputError, match="unknown sensor 'lidar'"):
        streams.select(["lidar"])


def test_config_rejects_unknown_keys_and_bad_values():
    cfg = FusionConfig.from_dict({"gate_probability": 0.99, "graph": {"robust": "cauchy"}, "wheel": {"k": 0.02}})
    assert cfg.gate_probability == 0.99 and cfg.graph.robust == "cauchy" and cfg.wheel.k == 0.02
    with pytest.raises(ValueError, match=r"graph\.robustness: unknown key"):
        FusionConfig.from_dict({"graph": {"robustness": "huber"}})
    with pytest.raises(ValueError, match="step_hz: expected a number, got 'fast'"):
        FusionConfig.from_dict({"step_hz": "fast"})
    with pytest.raises(ValueError, match=r"graph\.robust: expected one of 'huber', 'cauchy' or 'none'"):
        FusionConfig.from_dict({"graph": {"robust": "tukey"}})


def test_a_pitched_body_projects_wheel_travel_onto_the_floor_plan():
    from fusion_vo.backends import fuse
    from fusion_vo.measurements import ImuData

    t = np.linspace(0, 4, 201)
    pitch = 0.3
    q = np.tile([np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0], (len(t), 1))  # nose down/up by 0.3 rad
    imu = ImuData(t, np.zeros((len(t), 3)), np.tile([0, 0, 9.81], (len(t), 1)), q)
    streams = SensorStreams(wheel=_wheel(t), imu=imu)
    iv = build_intervals(streams, FusionConfig())
    np.testing.assert_allclose(iv.cx, np.cos(pitch), atol=1e-9)
    result = fuse(streams, "all")
    for name in ("ekf", "gtsam"):
        end = result.trajectories[name].xyyaw[-1]
        np.testing.assert_allclose(end[:2], [0.5 * 4 * np.cos(pitch), 0.0], atol=5e-3)
    # the wheel dead reckoning knows nothing of the slope
    assert abs(result.trajectories["wheel"].xyyaw[-1, 0] - 2.0) < 2 * PER_TICK


def test_odometry_twist_stands_in_for_encoder_ticks():
    from fusion_vo.backends import fuse
    from fusion_vo.measurements import TwistData

    t = np.linspace(0, 3, 151)
    odom = TwistData(t, np.full(151, 0.4), np.zeros(151), np.full(151, 0.2))
    streams = SensorStreams(odom=odom).select(["odom"])
    result = fuse(streams, "ekf")
    end = result.trajectories["ekf"].xyyaw[-1]
    R = 0.4 / 0.2
    np.testing.assert_allclose(end, [R * np.sin(0.6), R * (1 - np.cos(0.6)), 0.6], atol=5e-3)
    assert set(fuse(streams, "none").trajectories) == {"wheel"}


def test_camera_increments_are_checked_counted_and_put_in_time_order():
    cam = np.arange(0, 2.0, 0.05)
    wheel = _wheel(np.arange(0, 2.0, 0.02))
    clean = _visual(cam)
    for i, inc in enumerate(clean):
        inc.delta[2] = 0.001 * i  # tells the increments apart
    nodes = node_times(SensorStreams(visual=clean, wheel=wheel), FusionConfig())
    vis = list(clean)
    bad = {3: "lost", 5: "nan", 7: "not positive definite", 9: "off the grid"}
    vis[3] = VisualIncrement(vis[3].t0, vis[3].t1, vis[3].delta, vis[3].covariance, status="lost")
    vis[5] = VisualIncrement(vis[5].t0, vis[5].t1, np.array([np.nan, 0.0, 0.0]), vis[5].covariance)
    vis[7] = VisualIncrement(vis[7].t0, vis[7].t1, vis[7].delta, -np.eye(3))
    vis[9] = VisualIncrement(vis[9].t0 + 0.003, vis[9].t1, vis[9].delta, vis[9].covariance)
    vis[11], vis[12] = vis[12], vis[11]  # one increment arrives after the next one
    iv = build_intervals(SensorStreams(visual=vis, wheel=wheel), FusionConfig(), nodes=nodes)
    count = iv.counts["camera"]
    assert (count.missing, count.gated, count.reordered, count.used) == (1, 3, 1, len(vis) - len(bad))
    kept = [inc for i, inc in enumerate(clean) if i not in bad]  # in time order, the swap undone
    np.testing.assert_array_equal(camera_grid(iv).delta[:, 2], [inc.delta[2] for inc in kept])
    np.testing.assert_allclose(iv.t[camera_grid(iv).i0], [inc.t0 for inc in kept], atol=1e-9)
    np.testing.assert_allclose(iv.t[camera_grid(iv).i1], [inc.t1 for inc in kept], atol=1e-9)
    # the intervals of the dropped increments are not covered by the camera: a note says so only when long
    assert not any("camera lost" in note for note in iv.notes)
