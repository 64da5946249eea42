"""The camera's heading noise estimated from the gyro's (``fusion: {visual_noise: {estimate: true}}``)."""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "backends"))
from backend_synth import streams_of  # noqa: E402

from fusion_vo.backends import FusionConfig, StreamingFusion, fuse  # noqa: E402
from fusion_vo.backends.timeline import build_intervals  # noqa: E402
from fusion_vo.config.files import validate  # noqa: E402
from fusion_vo.errors import InputError  # noqa: E402
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams  # noqa: E402
from fusion_vo.sensors.visual import camera_grid  # noqa: E402

ESTIMATE = {"visual_noise": {"estimate": True}}


def _drive(frame_error: float, stated: float, duration: float = 60.0, seed: int = 2):
    """A drive whose camera heading errors have the moving-average share ``frame_error`` and whose increments
    state ``stated`` times their true heading variance (their heading covariances ``√stated`` times)."""
    s = synthetic_streams(SyntheticOptions(duration=duration, visual_frame_error=frame_error,
                                           visual_sigma_yaw=0.001), seed=seed)
    root = np.sqrt(stated)
    factor = np.array([[1.0, 1.0, root], [1.0, 1.0, root], [root, root, stated]])
    visual = [dataclasses.replace(v, covariance=np.asarray(v.covariance) * factor) for v in s.visual]
    return s, streams_of(s).replace(visual=visual)


def test_recovers_the_scale_and_the_frame_error_of_a_known_camera():
    """Truth: variance 1/4 of the stated one, lag-1 correlation -0.25 (f = 0.5; realised on this drive -0.27).
    Measured: scale 0.285 ± 0.021, correlation -0.319 ± 0.048; the bounds are about two standard errors.
    Independent increments would give a correlation near 0."""
    _, streams = _drive(0.5, 4.0)
    stated = np.array([v.covariance[2, 2] for v in streams.visual if v.ok])
    iv = build_intervals(streams.select(["camera", "imu", "wheel"]), FusionConfig.from_dict(ESTIMATE))
    e = camera_grid(iv).noise
    assert e.intervals > 1100
    assert e.scale == pytest.approx(0.25, rel=0.2) and e.scale_se < 0.04
    assert e.correlation == pytest.approx(-0.25, abs=0.1) and e.correlation_se < 0.075
    assert e.scale_applied and e.frame_error_applied
    assert camera_grid(iv).frame_error == pytest.approx(0.5, abs=0.2)
    # the increments' heading variance is the estimate times the stated one; their translation as stated
    assert np.median(camera_grid(iv).cov[:, 2, 2]) == pytest.approx(e.scale * np.median(stated), rel=0.05)
    assert np.median(camera_grid(iv).cov[:, 0, 0]) == pytest.approx(0.0015**2, rel=0.05)
    assert any("lag-1 correlation" in n and "used: scale and frame error" in n for n in iv.notes), iv.notes


def test_independent_honest_increments_keep_their_noise():
    """Truth: scale 1, no correlation. Measured: 1.103 ± 0.089, correlation +0.013 ± 0.054 (f = 0)."""
    _, streams = _drive(0.0, 1.0)
    iv = build_intervals(streams.select(["camera", "imu"]), FusionConfig.from_dict(ESTIMATE))
    e = camera_grid(iv).noise
    assert e.scale == pytest.approx(1.0, rel=0.2)
    assert abs(e.correlation) < 0.1 and e.frame_error < 0.2
    assert camera_grid(iv).frame_error < 0.2


def test_without_a_gyro_or_with_too_few_intervals_it_does_nothing_and_says_so():
    _, streams = _drive(0.5, 4.0, duration=6.0)
    config = FusionConfig.from_dict(ESTIMATE)
    for sensors, words in ((["camera", "wheel"], "needs the camera and the gyro"),
                           (["camera", "imu"], "fewer than visual_noise.min_intervals (200)")):
        iv = build_intervals(streams.select(sensors), config)
        assert not camera_grid(iv).noise.scale_applied and camera_grid(iv).frame_error == 0.0
        assert any(words in n for n in iv.notes), iv.notes
        reference = build_intervals(streams.select(sensors), FusionConfig())
        assert np.array_equal(camera_grid(iv).cov, camera_grid(reference).cov)
        assert camera_grid(reference).noise is None


def test_every_backend_fuses_the_estimate_as_if_configured():
    """The estimate reaches both backends through the grid: a run with it gives the tracks of a run configured
    with its f and with the increments' heading variance scaled by it by hand."""
    _, streams = _drive(0.5, 4.0, duration=14.0)
    streams = streams.select(["camera", "imu", "wheel"])
    forced = {"visual_noise": {"estimate": True, "scale_tolerance": 1e6, "frame_error_tolerance": 1e6}}
    estimated = fuse(streams, "all", FusionConfig.from_dict(forced))
    e = estimated.visual_noise
    assert e["scale_applied"] and e["frame_error_applied"] and 0 < e["frame_error"] < 0.9
    root = np.sqrt(e["scale"])
    factor = np.array([[1.0, 1.0, root], [1.0, 1.0, root], [root, root, e["scale"]]])
    by_hand = streams.replace(visual=[dataclasses.replace(v, covariance=np.asarray(v.covariance) * factor)
                                                   for v in streams.visual])
    configured = fuse(by_hand, "all", FusionConfig.from_dict({"visual_frame_error": e["frame_error"]}))
    for name in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online"):
        a, b = estimated.trajectories[name].xyyaw, configured.trajectories[name].xyyaw
        assert np.max(np.abs(a - b)) < 1e-9, name
    assert any("camera heading noise from camera minus gyro" in n for n in estimated.notes)
    assert estimated.summary()["visual_noise"]["intervals"] == e["intervals"]
    # streaming keeps the stated noise and says so
    fusion = StreamingFusion("ekf", FusionConfig.from_dict(ESTIMATE), ["camera"])
    for v in streams.visual[:40]:
        fusion.add_visual(v)
    assert any("not estimated in streaming use" in n for n in fusion.finish().notes)


@pytest.mark.parametrize("options, message", [
    ({"visual_noise": {"estimate": "maybe"}}, "fusion.visual_noise.estimate: expected true or false, got 'maybe'"),
    ({"visual_noise": {"scale_tolerance": 0.0}}, "fusion.visual_noise: scale_tolerance must be positive, not 0.0"),
    ({"visual_noise": {"frame_error_tolerance": float("nan")}},
     "fusion.visual_noise: frame_error_tolerance must be a finite number, not nan"),
    ({"visual_noise": {"min_intervals": 10}}, "fusion.visual_noise: min_intervals must be at least 100, not 10"),
    ({"visual_noise": {"estimat": True}}, "fusion.visual_noise.estimat: unknown key"),
])
def test_bad_settings_are_one_line_errors_naming_the_key(options, message):
    with pytest.raises(InputError) as err:
        validate(FusionConfig, options, prefix=("fusion",))
    assert message in str(err.value) and "\n" not in str(err.value)
