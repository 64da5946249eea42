"""Helpers for the backend tests: errors against the truth, visual dead reckoning, GPS fixes of a track."""

import dataclasses

import numpy as np

from fusion_vo.backends import SensorStreams
from fusion_vo.geometry import se2
from fusion_vo.measurements import GpsData, PoseData


def position_errors(track: PoseData, truth: PoseData) -> tuple[float, float]:
    """End-point error and RMS position error of ``track`` against ``truth`` (same start, no alignment)."""
    gt = np.stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)], axis=1)
    e = np.linalg.norm(track.xyyaw[:, :2] - gt, axis=1)
    return float(e[-1]), float(np.sqrt(np.mean(e**2)))


def visual_track(visual) -> PoseData:
    ok = [v for v in visual if v.ok]
    poses = se2.integrate([v.delta for v in ok])
    return PoseData(np.array([ok[0].t0] + [v.t1 for v in ok]), poses)


def streams_of(s, stated_scale: float | None = None) -> SensorStreams:
    """The synthetic drive's streams. With ``stated_scale`` (the drive's ``visual_scale``), the calibration
    uncertainties stated as the simulator writes them into the sensors' files: the camera height's
    (:func:`stated_height_sigma`) and the wheels' radius error (0 on these drives, so 0.1 mm)."""
    if stated_scale is None:
        return SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, range=s.range, camera_height=s.camera_height)
    wheel = dataclasses.replace(s.wheel, config=dataclasses.replace(s.wheel.config, radius_sigma=1e-4))
    return SensorStreams(visual=s.visual, wheel=wheel, imu=s.imu, range=s.range, camera_height=s.camera_height,
                         camera_height_sigma=stated_height_sigma(s, stated_scale))


def stated_height_sigma(s, visual_scale: float) -> float:
    """``height_sigma`` [m] the simulator states for a camera height it wrote wrong by ``visual_scale``: the size
    of the error (the true height is ``camera_height / visual_scale``), at least 0.1 mm. A drive whose camera
    scale is wrong on purpose states it, as ``fusion-vo simulate`` does, or the default prior (the height known
    to 0.2 %) keeps the wrong scale."""
    return max(abs(s.camera_height - s.camera_height / visual_scale), 1e-4)


def gps_along(truth, t: np.ndarray, sigma: float, rng) -> GpsData:
    """Fixes of the ``truth`` track at the times ``t``, in ENU at the datum (the antenna at the body's origin)."""
    enu = np.column_stack([np.interp(t, truth.t, truth.xyyaw[:, 0]), np.interp(t, truth.t, truth.xyyaw[:, 1]),
                           np.zeros(len(t))]) + np.column_stack([rng.normal(0.0, sigma, (len(t), 2)), np.zeros(len(t))])
    return GpsData(t=t, enu=enu, covariance=np.tile(np.eye(2) * sigma**2, (len(t), 1, 1)),
                   geodetic=np.zeros((len(t), 3)), status=np.zeros(len(t), int), datum=(0.0, 0.0, 0.0),
                   lever_arm=np.zeros(3), horizontal_sigma=sigma)
