"""The heading-consistency monitor run causally in the streaming path.

The longer streams are named in :data:`AHEAD` and made in the session's second process (tests/ahead_job.py); each
test takes them through ``made_ahead`` and checks them here.
"""

import dataclasses

import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, SensorStreams
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams, wheels_too_long

from ahead_job import ahead_jobs
from backend_synth import position_errors, streams_of
from husky_like import husky_like


def _stream(streams, backend, config):
    fusion = streaming_for(streams, backend, config)
    fusion.feed(time_ordered_messages(streams))
    return fusion.finish()


def _lying_yaw_rate(backend: str) -> tuple:
    """Odometry whose yaw rate is 7 x the truth next to a gyro and an AHRS, fed sample by sample: (truth, result)."""
    odom, imu, truth = husky_like(duration=40.0, stop=(15.0, 25.0), yaw_scale=7.0, ahrs_drift=0.0, gyro_bias=0.002)
    return truth, _stream(SensorStreams(odom=odom, imu=imu), backend, FusionConfig())


@pytest.mark.parametrize("backend, name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_a_lying_wheel_yaw_rate_is_dropped_while_streaming(made_ahead, backend, name):
    """Odometry whose yaw rate is 7 x the truth next to a gyro and an AHRS, fed sample by sample."""
    truth, watched = made_ahead(f"lying_yaw_rate_{backend}")
    wheel = [e for e in watched.inconsistent if e["component"] == "yaw rate"]
    assert len(wheel) >= 1 and wheel[0]["sensor"] == "wheel", watched.inconsistent
    assert wheel[0]["start"] <= truth.t[0] + 3.0  # caught within the first windows
    assert all(e["component"] == "yaw rate" for e in watched.inconsistent), watched.inconsistent
    assert any(n.startswith("live monitor: wheel yaw rate inconsistent with gyro, ahrs") for n in watched.notes)
    _, rms = position_errors(watched.trajectories[name], truth)
    assert rms < 0.1, rms  # the wheels' speed is still used


def _gyro_bias_step() -> tuple:
    """A 60 s drive whose gyro's bias steps by 0.05 rad/s at 40 s, streamed by the EKF: (truth, result)."""
    odom, imu, truth = husky_like(duration=60.0, stop=(15.0, 25.0), yaw_scale=1.0, ahrs_drift=0.0, gyro_bias=0.002)
    gyro = imu.gyro.copy()
    gyro[imu.t >= 40.0, 2] += 0.05
    streams = SensorStreams(odom=odom, imu=dataclasses.replace(imu, gyro=gyro))
    return truth, _stream(streams, "ekf", FusionConfig())


def test_a_gyro_bias_step_is_dropped_from_the_step_on_while_streaming(made_ahead):
    truth, result = made_ahead("gyro_bias_step")
    gyro_eps = [e for e in result.inconsistent if e["component"] == "gyro yaw rate"]
    assert gyro_eps and 40.0 <= gyro_eps[0]["start"] <= 44.0, result.inconsistent
    assert gyro_eps[-1]["end"] >= truth.t[-1] - 1.0
    assert not [e for e in result.inconsistent if e["component"] == "AHRS heading"], result.inconsistent
    _, rms = position_errors(result.trajectories["ekf"], truth)
    assert rms < 0.1, rms


def _drifting_ahrs(backend: str = "ekf") -> tuple:
    """An AHRS heading that starts straying at 0.03 rad/s after 25 s, next to a gyro and wheels, streamed with the
    monitor and without it: (truth, watched, blind)."""
    odom, imu, truth = husky_like(duration=60.0, stop=(10.0, 15.0), yaw_scale=1.0, ahrs_drift=0.0, gyro_bias=0.002)
    q = imu.orientation
    heading = 2.0 * np.arctan2(q[:, 3], q[:, 0]) + 0.03 * np.clip(imu.t - 25.0, 0.0, None)
    q = np.stack([np.cos(heading / 2), 0 * heading, 0 * heading, np.sin(heading / 2)], axis=1)
    streams = SensorStreams(odom=odom, imu=dataclasses.replace(imu, orientation=q))
    return truth, _stream(streams, backend, FusionConfig()), _stream(streams, backend, FusionConfig(monitor=False))


def test_a_drifting_ahrs_heading_is_dropped_for_good_while_streaming(made_ahead, name="ekf"):
    """An AHRS heading that starts straying at 0.03 rad/s after 25 s, next to a gyro and wheels."""
    truth, watched, blind = made_ahead("drifting_ahrs")
    ahrs = [e for e in watched.inconsistent if e["component"] == "AHRS heading"]
    assert len(ahrs) == 1 and ahrs[0]["end"] >= truth.t[-1] - 0.1, watched.inconsistent
    assert 25.0 <= ahrs[0]["start"] <= 35.0, ahrs
    _, rms = position_errors(watched.trajectories[name], truth)
    _, rms_blind = position_errors(blind.trajectories[name], truth)
    assert rms < 0.3 * rms_blind, (rms, rms_blind)


def _with_and_without_a_wrong_match() -> list:
    """A 12 s drive streamed with a wrong visual match at 6 s and without it: [(truth, result)] in that order."""
    runs = []
    for wrong in ([6.0], []):
        s = synthetic_streams(SyntheticOptions(duration=12.0, ahrs_sigma=0.02, wrong_matches=wrong), seed=0)
        streams = SensorStreams(visual=s.visual, camera_height=s.camera_height, wheel=s.wheel, imu=s.imu)
        runs.append((s.truth, _stream(streams, "ekf", FusionConfig())))
    return runs


def test_a_wrong_visual_match_while_streaming_does_not_fail_the_run(made_ahead):
    """The live check drops the wrong increment from its own window (which keeps no per-sensor counts;
    it used to raise there), and the run matches the one without the wrong match."""
    rms = [position_errors(result.trajectories["ekf"], truth)[1]
           for truth, result in made_ahead("wrong_visual_match")]
    assert rms[0] < 1.1 * rms[1], rms


@pytest.mark.parametrize("seed", [0, 1, 6])
def test_an_honest_gyro_is_not_dropped_in_the_first_seconds_with_a_camera(seed):
    """Clean drive with camera, wheels, gyro (biased) and an AHRS of 0.02 rad, fed sample by sample: over the
    first seconds the gyro's bias is taken against the camera's summed increments, not the AHRS's two end
    readings (whose √2 σ_ψ / T is 0.028 rad/s after 1 s), so nothing honest is dropped."""
    s = synthetic_streams(SyntheticOptions(duration=15.0, ahrs_sigma=0.02, gyro_bias=0.005), seed=seed)
    streams = SensorStreams(visual=s.visual, camera_height=s.camera_height, wheel=s.wheel, imu=s.imu)
    result = _stream(streams, "ekf", FusionConfig())
    assert result.inconsistent == [], result.inconsistent


def test_the_spans_found_so_far_are_readable_while_streaming():
    """``inconsistent()`` gives, mid-stream, the spans ``finish()`` reports at the end (the open one ending at
    the last node): a live node reports them in its diagnostics."""
    odom, imu, _ = husky_like(duration=20.0, stop=(8.0, 12.0), yaw_scale=7.0, ahrs_drift=0.0, gyro_bias=0.002)
    streams = SensorStreams(odom=odom, imu=imu)
    fusion = streaming_for(streams, "ekf", FusionConfig())
    msgs = time_ordered_messages(streams)
    assert fusion.inconsistent() == []  # nothing processed yet
    fusion.feed(msgs[: len(msgs) // 2])
    midway = fusion.inconsistent()
    assert [e["component"] for e in midway] == ["yaw rate"] and midway[0]["sensor"] == "wheel", midway
    assert midway[0]["end"] == pytest.approx(fusion.processed_estimate().t)
    fusion.feed(msgs[len(msgs) // 2:])
    final = fusion.finish().inconsistent
    assert final[0]["start"] == midway[0]["start"] and final[0]["end"] > midway[0]["end"]


SPEED_LIE = (12.0, 22.0)  # [s] the wheels' counts 1.3 times too large


def _speed_drive(seed: int):
    """A generated 30 s drive with a camera, wheels and a gyro: its streams clean and with the wheels lying."""
    s = synthetic_streams(SyntheticOptions(duration=30.0), seed=seed)
    clean = streams_of(s)
    return s, clean, clean.replace(wheel=wheels_too_long(s.wheel, *SPEED_LIE, 1.3))


def _speed_lie(backend: str) -> tuple:
    """The drive of :func:`_speed_drive` (seed 2) streamed by ``backend``: (truth, the lying wheels with the monitor,
    without it, the clean drive with it)."""
    s, clean, lying = _speed_drive(seed=2)
    return (s.truth, _stream(lying, backend, FusionConfig()), _stream(lying, backend, FusionConfig(monitor=False)),
            _stream(clean, backend, FusionConfig()))


@pytest.mark.parametrize("backend, name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_a_wheel_speed_scaled_wrong_is_dropped_while_streaming(made_ahead, backend, name):
    """The live speed check: the wheels' distance against the camera's, held to their ratio over the stream so far.
    Without it the streamed EKF believed the wheels: 27.8 cm RMS from the truth, against 7.8 cm on the clean drive
    and 3.9 cm with the check."""
    truth, watched, blind, honest = made_ahead(f"speed_lie_{backend}")
    speed = [e for e in watched.inconsistent if e["component"] == "speed"]
    assert len(speed) == 1 and speed[0]["sensor"] == "wheel" and speed[0]["against"] == "camera", watched.inconsistent
    # caught within two checks of the lie's start, and trusted again within two windows of its end
    assert SPEED_LIE[0] <= speed[0]["start"] <= SPEED_LIE[0] + 2.5, speed
    assert SPEED_LIE[1] <= speed[0]["end"] <= SPEED_LIE[1] + 3.0, speed
    assert "wheel/camera distance ratio 1.0" in speed[0]["detail"] or "ratio 0.9" in speed[0]["detail"], speed
    assert [e for e in honest.inconsistent if e["component"] == "speed"] == [], honest.inconsistent
    rms = position_errors(watched.trajectories[name], truth)[1]
    rms_blind = position_errors(blind.trajectories[name], truth)[1]
    rms_clean = position_errors(honest.trajectories[name], truth)[1]
    assert rms < rms_clean and rms < 0.3 * rms_blind, (rms, rms_clean, rms_blind)


def _camera_late() -> list:
    """The lying drive of :func:`_speed_drive` (seed 0, 1 s monitor windows) streamed in time order and with every
    fifth camera increment 0.5 s late: [(rewinds, result)] in that order."""
    _, _, lying = _speed_drive(seed=0)
    config = FusionConfig(monitor_window=1.0)
    msgs = time_ordered_messages(lying)
    late = set([i for i, m in enumerate(msgs) if m[1] == "visual"][::5])
    arrival = [m for _, m in sorted(enumerate(msgs), key=lambda im: im[1][0] + (0.5 if im[0] in late else 0.0))]
    runs = []
    for order in (msgs, arrival):
        fusion = streaming_for(lying, "ekf", config)
        fusion.feed(order)
        runs.append((fusion.rewinds, fusion.finish()))
    return runs


def test_the_live_monitor_gives_the_same_track_when_the_camera_comes_late(made_ahead):
    """Every fifth camera increment 0.5 s late (beyond the 0.3 s reorder window, within the 2 s history): the EKF
    rewinds, and the monitor's state with it (its decisions, the speed ratios it holds, the window it judges), so
    the track and the spans are those of the in-order stream. The window used to be what was left after the last
    trim of its buffer, which a rewind did not undo: here (1 s windows, so that the 15 s window is trimmed within the
    drive) two of the wheels' yaw-rate spans ended 0.5 s early and the track moved 0.5 mm."""
    (_, in_order), (rewinds, delayed) = made_ahead("camera_late")
    assert rewinds > 100
    assert {e["component"] for e in in_order.inconsistent} == {"speed", "yaw rate"}, in_order.inconsistent
    assert delayed.inconsistent == in_order.inconsistent
    np.testing.assert_allclose(delayed.trajectories["ekf"].xyyaw, in_order.trajectories["ekf"].xyyaw, atol=1e-9,
                               rtol=0)


#: the streams above, made ahead in the session's second process (tests/ahead_job.py)
AHEAD = {"lying_yaw_rate_ekf": lambda: _lying_yaw_rate("ekf"), "lying_yaw_rate_gtsam": lambda: _lying_yaw_rate("gtsam"),
         "gyro_bias_step": _gyro_bias_step, "drifting_ahrs": _drifting_ahrs,
         "wrong_visual_match": _with_and_without_a_wrong_match,
         "speed_lie_ekf": lambda: _speed_lie("ekf"), "speed_lie_gtsam": lambda: _speed_lie("gtsam"),
         "camera_late": _camera_late}
BACKGROUND_COMMANDS, BACKGROUND_JOBS = ahead_jobs(__file__)
