"""Helpers for the backend tests: errors against the truth, visual dead reckoning."""

import numpy as np

from fusion_vo.backends import SensorStreams
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData


def position_errors(track: PoseData, truth: PoseData) -> tuple[float, float]:
    """End-point error and RMS position error of ``track`` against ``truth`` (same start, no alignment)."""
    gt = np.stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)], axis=1)
    e = np.linalg.norm(track.xyyaw[:, :2] - gt, axis=1)
    return float(e[-1]), float(np.sqrt(np.mean(e**2)))


def visual_track(visual) -> PoseData:
    ok = [v for v in visual if v.ok]
    poses = se2.integrate([v.delta for v in ok])
    return PoseData(np.array([ok[0].t0] + [v.t1 for v in ok]), poses)


def streams_of(s) -> SensorStreams:
    return SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, range=s.range, camera_height=s.camera_height)
