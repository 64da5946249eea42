"""The division-model lens of an uncalibrated camera, estimated from tracked points alone."""

from __future__ import annotations

import numpy as np
import pytest

from fusion_vo.calibration.lens_from_motion import estimate_division, lens_from_motion
from fusion_vo.config.sensor_files import camera_model
from fusion_vo.geometry.camera import CameraModel


def _pinhole() -> CameraModel:
    return CameraModel(640, 360, 420.0, 420.0, 319.5, 179.5)


def test_division_model_round_trips_and_reads_from_sensor_yaml():
    cam = camera_model({"resolution": [640, 360], "intrinsics": [420.0, 420.0, 319.5, 179.5],
                                 "distortion_model": "division", "distortion_coefficients": [-0.3]})
    assert cam.has_distortion
    pix = np.array([[0.0, 0.0], [639.0, 359.0], [319.5, 179.5], [100.0, 300.0]])
    assert np.allclose(cam.denormalize(cam.normalize(pix)), pix, atol=1e-9)
    # barrel: the corner's ray lies farther out than the pinhole's
    assert np.linalg.norm(cam.normalize(pix[:1])) > np.linalg.norm((pix[0] - [319.5, 179.5]) / 420.0) * 1.2
    assert cam.to_dict()["distortion_model"] == "division"


def _tracks(lam: float, pairs: int = 12, seed: int = 0, noise: float = 0.2):
    """Points of a flat floor seen through a division-model lens, moved by a similarity per pair."""
    rng = np.random.default_rng(seed)
    lens = CameraModel(640, 360, 420.0, 420.0, 319.5, 179.5, "division", np.array([lam]))
    out = []
    for _ in range(pairs):
        p0 = np.column_stack([rng.uniform(10, 630, 150), rng.uniform(10, 350, 150)])
        u0 = lens.normalize(p0)
        theta, s = rng.normal(0, 0.03), 1.0 + rng.normal(0, 0.005)
        R = s * np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
        u1 = u0 @ R.T + rng.normal(0, 0.05, 2)  # up to ~20 px of flow
        p1 = lens.denormalize(u1) + rng.normal(0, noise, p0.shape)
        inside = np.all((p1 >= 0) & (p1 <= [639, 359]), axis=1)
        p1[rng.random(len(p1)) < 0.1] += rng.uniform(-15, 15, (1, 2))  # mismatches
        out.append((p0[inside], p1[inside]))
    return out


@pytest.mark.parametrize("lam", [-0.35, -0.1, 0.0, 0.1])
def test_the_lens_is_recovered_from_tracks(lam):
    est = estimate_division(_pinhole(), _tracks(lam))
    assert est is not None
    assert abs(est.lam - lam) < 0.02
    if lam != 0.0:  # the right lens explains the tracks better than none
        assert est.rms_px < est.rms_px_without


def test_too_little_motion_gives_no_estimate():
    still = [(p0, p0 + 0.1) for p0, _ in _tracks(-0.3)]
    assert estimate_division(_pinhole(), still) is None
    assert estimate_division(_pinhole(), _tracks(-0.3, pairs=3)) is None


class _Frames:
    """A stand-in recording whose frames are flat grey: nothing to track."""

    path = "flat"

    def __len__(self):
        return 10

    def frames(self, start, stop):
        from fusion_vo.recording.reader import Frame

        for k in range(start, stop):
            yield Frame(k, 0.05 * k, np.full((360, 640), 128, np.uint8), "flat")


def test_a_recording_without_texture_keeps_the_pinhole():
    cam, est = lens_from_motion(_Frames(), _pinhole())
    assert est is None and not cam.has_distortion
