"""The consistency monitor on speeds: the wheels' distance against the camera's, per window."""

import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, fuse
from fusion_vo.sensors.synthetic import SyntheticOptions, camera_too_long, synthetic_streams, wheels_too_long

from backend_synth import position_errors, streams_of

FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
LIE = (20.0, 35.0)  # [s] span in which one stream's speed is scaled by 1.3


def _speed_episodes(result):
    return [e for e in result.inconsistent if e["component"] == "speed"]


@pytest.fixture(scope="module")
def drive():
    return synthetic_streams(SyntheticOptions(duration=60.0), seed=0)


def test_wheel_speed_scaled_wrong_is_dropped_for_its_span(drive):
    streams = streams_of(drive).replace(wheel=wheels_too_long(drive.wheel, *LIE, 1.3))
    result = fuse(streams, "all", FusionConfig())
    eps = _speed_episodes(result)
    assert len(eps) == 1, result.inconsistent
    ep = eps[0]
    assert ep["sensor"] == "wheel" and ep["against"] == "camera"
    # found within a monitor window (2 s) of where the lie starts and ends, not over the whole drive
    assert LIE[0] - 2.5 <= ep["start"] <= LIE[0] + 0.5 and LIE[1] - 0.5 <= ep["end"] <= LIE[1] + 2.5, ep
    assert ep["max_nis"] > 15.1
    assert "ratio 1.2" in ep["detail"] or "ratio 1.3" in ep["detail"], ep["detail"]
    assert any(n.startswith("wheel speed inconsistent with camera from t=") and "20." in n for n in result.notes)
    # what summary.json's fusion.inconsistent gets: JSON-friendly, with the times
    import json

    entry = next(e for e in json.loads(json.dumps(result.summary()["inconsistent"])) if e["component"] == "speed")
    assert entry["component"] == "speed" and entry["start"] == ep["start"] and entry["end"] == ep["end"]
    clean = fuse(streams_of(drive), "all", FusionConfig())
    unchecked = fuse(streams, "all", FusionConfig(monitor=False))
    for name in FUSED:
        _, rms = position_errors(result.trajectories[name], drive.truth)
        _, rms_clean = position_errors(clean.trajectories[name], drive.truth)
        _, rms_unchecked = position_errors(unchecked.trajectories[name], drive.truth)
        # the camera carries the translation there: close to the clean drive, far better than believing the wheels
        assert rms < 1.5 * rms_clean + 0.02 and rms < 0.5 * rms_unchecked, (name, rms, rms_clean, rms_unchecked)


def test_camera_scale_gone_wrong_is_reported_with_its_span(drive):
    streams = streams_of(drive).replace(visual=camera_too_long(drive.visual, *LIE, 1.3))
    result = fuse(streams, "ekf", FusionConfig())
    eps = _speed_episodes(result)
    assert len(eps) == 1, result.inconsistent
    ep = eps[0]
    assert LIE[0] - 2.5 <= ep["start"] <= LIE[0] + 0.5 and LIE[1] - 0.5 <= ep["end"] <= LIE[1] + 2.5, ep
    # the wheel/camera ratio there is about 1/1.3 of the recording's: the reader sees which stream moved
    there, overall = (float(x) for x in
                      ep["detail"].split("ratio ")[1].split(" over")[0].replace(" there,", "").split())
    assert 0.7 < there / overall < 0.85, ep["detail"]
    assert np.isfinite(result.trajectories["ekf"].xyyaw).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_no_speed_disagreement_on_clean_drives(seed):
    s = synthetic_streams(SyntheticOptions(duration=60.0), seed=seed)
    result = fuse(streams_of(s), "ekf", FusionConfig())
    assert _speed_episodes(result) == [], result.inconsistent


def test_a_constant_scale_ratio_is_calibration_not_a_lie():
    """A camera height 8 % off for the whole drive: the backends estimate it; the monitor stays quiet."""
    s = synthetic_streams(SyntheticOptions(duration=60.0, visual_scale=1.08), seed=1)
    result = fuse(streams_of(s), "ekf", FusionConfig())
    assert _speed_episodes(result) == [], result.inconsistent


def test_monitor_scale_sigma_is_checked():
    with pytest.raises(ValueError, match="monitor_scale_sigma must be positive"):
        FusionConfig.from_dict({"monitor_scale_sigma": 0.0})


def test_the_wheels_are_checked_against_a_registered_distance_source(drive):
    """A sensor registered outside the library that declares a DistanceSource (an odometer reading the distance
    travelled from ground truth, 1 mm per interval) takes the camera's place: the wheels scaled 1.3 in the same
    span are dropped against it. Fails if the speed check names the camera instead of taking the registered
    sources (no camera here: nothing would be checked)."""
    from fusion_vo.backends import SensorStreams
    from fusion_vo.measurements import SensorCount
    from fusion_vo.sensors.registry import DistanceSource, Sensor, Step, registered

    def on_grid(iv, streams, config, counts):
        truth = streams["odometer"]  # (its samples: the true poses)
        xy = np.column_stack([np.interp(iv.t, truth.t, truth.xyyaw[:, i]) for i in range(2)])
        iv.sensors["odometer"] = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        counts.setdefault("odometer", SensorCount()).used += len(iv.dt)

    def change(iv, config):
        d = iv.sensors.get("odometer")
        return None if d is None else (np.ones(len(d), bool), d, np.full(len(d), 1e-6))

    odometer = Sensor(name="odometer", intervals=Step(100, on_grid),
                      distance=(DistanceSource("odometer", "distance", rank=50, change=change),))
    with registered(odometer):
        streams = SensorStreams(wheel=wheels_too_long(drive.wheel, *LIE, 1.3), imu=drive.imu, odometer=drive.truth)
        result = fuse(streams.select(["wheel", "imu"]), "ekf", FusionConfig())
        assert _speed_episodes(result) == []  # without the odometer: the wheels' distance has nothing to meet
        result = fuse(streams.select(["wheel", "imu", "odometer"]), "ekf", FusionConfig())
    eps = _speed_episodes(result)
    assert len(eps) == 1 and eps[0]["sensor"] == "wheel" and eps[0]["against"] == "odometer", result.inconsistent
    assert LIE[0] - 2.5 <= eps[0]["start"] <= LIE[0] + 0.5 and LIE[1] - 0.5 <= eps[0]["end"] <= LIE[1] + 2.5, eps
    assert "wheel/odometer distance ratio 1.2" in eps[0]["detail"] or "ratio 1.3" in eps[0]["detail"], eps[0]
