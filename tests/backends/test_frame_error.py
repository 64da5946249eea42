"""The camera's frame errors (``visual_frame_error``): consecutive increments sharing a frame's error."""

import dataclasses

import numpy as np
import pytest
from backend_synth import position_errors, streams_of

from fusion_vo.backends import FusionConfig, StreamingFusion, fuse
from fusion_vo.backends.ekf import DIM, FRAME_ERRORS, filter_for
from fusion_vo.backends.ekf_adapter import EkfReadings
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.sensors.readings import Readings
from fusion_vo.sensors.visual import VISUAL
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

TRACKS = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


@pytest.fixture(scope="module")
def camera_only():
    """A drive whose camera increments share half their variance with their neighbours, fused by the camera
    alone without and with the frame errors modelled."""
    s = synthetic_streams(SyntheticOptions(duration=8.0, visual_frame_error=0.5, visual_sigma_yaw=0.003), seed=3)
    streams = streams_of(s).select(["camera"])
    return s, {f: fuse(streams, "all", FusionConfig(visual_frame_error=f)) for f in (0.0, 0.5)}


def test_every_backend_gives_the_long_run_heading_variance_of_the_frame_errors(camera_only):
    """Over N increments the heading's variance is N σ² for independent ones, and (N (1 - f) + f) σ² when the
    fraction f of each increment's variance is its two frames' errors (the sum telescopes): about half."""
    s, runs = camera_only
    n = len(s.visual)
    expected = (n * 0.5 + 0.5) / n
    for name in TRACKS:
        independent = runs[0.0].covariances[name][-1, 2, 2]
        modelled = runs[0.5].covariances[name][-1, 2, 2]
        assert modelled / independent == pytest.approx(expected, rel=0.1), name


def test_frame_errors_leave_the_common_scale_of_camera_and_wheels_to_the_priors():
    """Camera and wheels measure only the ratio of their scales; a frame's tie in metres would shrink with the
    whole track and pull both scales (2.7 % here), so the graph ties a frame in the increments' units."""
    s = synthetic_streams(SyntheticOptions(duration=20.0, visual_frame_error=0.5, visual_sigma_yaw=0.003), seed=1)
    streams = streams_of(s).select(["camera", "wheel"])
    config = {"graph": {"online": False}}
    before, after = (fuse(streams, "gtsam", FusionConfig.from_dict({"visual_frame_error": f, **config}))
                     for f in (0.0, 0.5))
    for key in ("visual_scale", "wheel_scale"):
        assert after.calibration["gtsam"][key] == pytest.approx(before.calibration["gtsam"][key], abs=2e-3), key


@pytest.mark.parametrize("backend, batch_name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_streaming_models_the_frame_errors_as_the_batch_run(camera_only, backend, batch_name):
    s, runs = camera_only
    fusion = StreamingFusion(backend, FusionConfig(visual_frame_error=0.5), ["camera"])
    for v in s.visual:
        fusion.add_visual(v)
    _assert_same_track(fusion.finish().trajectories[batch_name], runs[0.5].trajectories[batch_name])


def _stating(visual, share: float):
    """The increments with ``share`` of their covariance stated as each frame's own error."""
    import dataclasses

    return [dataclasses.replace(v, frame_covariance=share * np.asarray(v.covariance)) for v in visual]


def test_frame_errors_stated_by_the_increments_are_the_same_model(camera_only):
    """An increment's own ``frame_covariance`` of f/2 of its covariance is ``visual_frame_error = f``: every
    backend gives the same track and covariances to rounding."""
    import dataclasses

    s, runs = camera_only
    stated = streams_of(s).select(["camera"]).replace(visual=_stating(s.visual, 0.25))
    result = fuse(stated, "all", FusionConfig())
    for name in TRACKS:
        np.testing.assert_allclose(result.trajectories[name].xyyaw, runs[0.5].trajectories[name].xyyaw,
                                   rtol=0, atol=1e-9, err_msg=name)
        np.testing.assert_allclose(result.covariances[name], runs[0.5].covariances[name], rtol=1e-6, atol=1e-15,
                                   err_msg=name)


@pytest.mark.parametrize("backend, batch_name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_streaming_takes_the_frame_errors_the_increments_state(camera_only, backend, batch_name):
    from fusion_vo.backends.streaming import streaming_for

    import dataclasses

    s, runs = camera_only
    stated = streams_of(s).select(["camera"]).replace(visual=_stating(s.visual, 0.25))
    fusion = streaming_for(stated, backend, FusionConfig())
    for v in stated.visual:
        fusion.add_visual(v)
    _assert_same_track(fusion.finish().trajectories[batch_name], runs[0.5].trajectories[batch_name])


def _assert_same_track(track, ref) -> None:
    """A streamed ``track`` has nearly all of the batch ``ref``'s poses, each within 1 µm (1 µrad)."""
    common = np.isin(np.round(ref.t, 9), np.round(track.t, 9))
    ours = track.xyyaw[np.isin(np.round(track.t, 9), np.round(ref.t, 9))]
    assert common.sum() > 0.95 * len(ref)
    assert np.max(np.abs(ours - ref.xyyaw[common])) < 1e-6



def test_the_filter_carries_the_frame_errors_of_whichever_sensor_states_them():
    """The EKF's frame-error states follow the readings, not a sensor's name: a registered sensor's readings
    that state their frames' errors (``Readings.frame_cov``) get them, as the camera's do; the same readings
    without them do not, nor does a run without such readings."""
    s = synthetic_streams(SyntheticOptions(duration=4.0), seed=0)
    config = FusionConfig()
    iv = build_intervals(streams_of(s).select(["wheel"]), config)
    k = np.arange(iv.n_steps)
    cov = np.tile(np.eye(3) * 1e-4, (len(k), 1, 1))
    framed = Readings("vo", VISUAL, k, k + 1, np.zeros((len(k), 3)), cov, frame_cov=0.25 * cov)
    for readings, carried in (([framed], True), ([dataclasses.replace(framed, frame_cov=None)], False), ([], False)):
        ekf = filter_for(iv, config, EkfReadings(readings, iv.t))
        assert (ekf.frame_errors is not None) == carried
        assert ekf.dim == DIM + len(iv.states) + (2 * FRAME_ERRORS if carried else 0)
