"""The simple baselines that fusion-vo's figures are compared with: a plain OpenCV script, dead reckoning.

The plain OpenCV script is what a robotics engineer writes in ten minutes: Shi-Tomasi corners in the previous frame,
pyramidal Lucas-Kanade into the current one, a partial affine (similarity) fitted with RANSAC. No
prediction, no undistortion, no covariance, no threads: one frame at a time, as read from disk.

    python -m fusion_vo.baseline SEQ          # prints frames measured, failures, frames/s

:func:`measure` is the per-frame step and :func:`run` the whole recording (``fusion-vo bench`` and the
benchmarks time it in the same run as fusion-vo). :func:`odometry` turns its pixel similarities into body
motion as fusion-vo does, so that its track can be scored the same way: through the same ground geometry
(:class:`~fusion_vo.geometry.ground.GroundGeometry`) with a distortion-free pinhole of the recording's
focal length (the script does not undistort), the same heights (range finder) and the same bridging of
failed frames (:class:`~fusion_vo.odometry.VisualOdometry`).

For logs without a camera, two filter-free tracks of a robot's odometry twist and IMU:

* :func:`wheel_gyro`: each odometry interval's distance along the heading of the integrated body-z gyro rate,
  less the gyro's median rate while the odometry reports standstill;
* :func:`along_orientation`: the odometry's forward speed integrated along the body's x axis as the IMU's
  3-D orientation gives it, ``p_{k+1} = p_k + v_k Δt_k R_WS(s_k) R_BSᵀ e_x`` with ``s_k`` the first IMU
  sample at or after the odometry sample ``t_k`` (a few lines of numpy, no interpolation).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from frontends.base import FrameMotion, MotionStatus
from fusion_vo.geometry import se2
from fusion_vo.geometry.ground import GroundGeometry
from fusion_vo.measurements import PoseData
from fusion_vo.odometry import VisualOdometry, heights_for
from fusion_vo.recording import Recording
from fusion_vo.sensors.imu import ImuNoise, cumulative_angle, gyro_yaw, read_imu
from fusion_vo.sensors.wheel import read_twist, twist_to_travel, wheel_track

MAX_CORNERS = 200
QUALITY = 0.01
MIN_DISTANCE = 7
LK_WIN = (15, 15)
LK_MAX_LEVEL = 2  # three pyramid levels
RANSAC_THRESHOLD = 3.0

#: the covariance a replayed similarity is given (the script states none; only ``ok`` matters for the track)
REPLAY_COVARIANCE = 1e-4


def measure(prev: np.ndarray, cur: np.ndarray) -> np.ndarray | None:
    """The 2x3 similarity mapping ``prev`` pixels to ``cur`` pixels, or None when it fails."""
    p0 = cv2.goodFeaturesToTrack(prev, MAX_CORNERS, QUALITY, MIN_DISTANCE)
    if p0 is None or len(p0) < 3:
        return None
    p1, st, _ = cv2.calcOpticalFlowPyrLK(prev, cur, p0, None, winSize=LK_WIN, maxLevel=LK_MAX_LEVEL)
    if p1 is None:
        return None
    ok = st.ravel() == 1
    if ok.sum() < 3:
        return None
    m, _ = cv2.estimateAffinePartial2D(p0[ok], p1[ok], method=cv2.RANSAC, ransacReprojThreshold=RANSAC_THRESHOLD)
    return m


def frame_paths(seq: str | Path) -> list[tuple[int, Path]]:
    """(timestamp_ns, path) of every row of ``SEQ/cam0/data.csv``."""
    seq = Path(seq)
    rows = []
    with open(seq / "cam0" / "data.csv", newline="") as fh:
        for row in csv.reader(fh):
            if not row or row[0].lstrip().startswith("#"):
                continue
            rows.append((int(row[0]), seq / "cam0" / "data" / row[1].strip()))
    return rows


def run(seq: str | Path) -> tuple[list[tuple[float, float, np.ndarray | None]], float]:
    """Measure a whole recording: ``([(t0, t1, M or None), ...], wall seconds)``, decode included."""
    start = time.perf_counter()
    out = []
    prev, t_prev = None, None
    for stamp, path in frame_paths(seq):
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        t = stamp * 1e-9
        if img is None:
            continue
        if prev is not None:
            out.append((t_prev, t, measure(prev, img)))
        prev, t_prev = img, t
    return out, time.perf_counter() - start


def similarity_parameters(m: np.ndarray) -> tuple[float, float, float, float]:
    """(tx, ty, angle [rad], scale) of a 2x3 similarity."""
    return float(m[0, 2]), float(m[1, 2]), math.atan2(m[1, 0], m[0, 0]), math.hypot(m[0, 0], m[1, 0])


class _Replay:
    """A frontend that returns the script's precomputed similarities, one per frame."""

    def __init__(self, results):
        self._results = list(results)
        self._k = -1
        self._ref_t: float | None = None

    def process(self, image, t: float) -> FrameMotion:
        self._k += 1
        if self._k == 0:
            self._ref_t = t
            return FrameMotion(t, None, status=MotionStatus.FIRST)
        _, _, m = self._results[self._k - 1]
        prev = self._ref_t
        if m is None:
            return FrameMotion(t, prev, status=MotionStatus.TOO_FEW_FEATURES)
        self._ref_t = t
        return FrameMotion(t, prev, matrix=np.asarray(m, float), covariance=np.eye(4) * REPLAY_COVARIANCE,
                           status=MotionStatus.OK)


def odometry(rec: Recording) -> tuple[VisualOdometry, list, list, float]:
    """The script on ``rec`` turned into body motion (module docstring).

    Returns
    -------
    vo : VisualOdometry
        Its visual odometry (``vo.track()`` the track).
    increments : list of BodyIncrement
        The body increments of the measured frame pairs.
    results : list
        The script's per-frame results, as :func:`run` returns them.
    seconds : float
        The script's wall time over the recording, decoding included.
    """
    results, seconds = run(rec.path)
    plain = dataclasses.replace(rec.camera, distortion_model="none", distortion=np.zeros(4))
    vo = VisualOdometry(_Replay(results), GroundGeometry(plain))
    times = rec.frame_times
    heights = heights_for(rec, times)
    increments = []
    for k, t in enumerate(times):
        _, inc = vo.process(None, float(t), None if heights is None else float(heights[k]))
        if inc is not None:
            increments.append(inc)
    return vo, increments, results, seconds


def raw_odometry(rec: Recording) -> PoseData:
    """The robot's own odometry twist (``odom0``) dead-reckoned from the origin."""
    return wheel_track(twist_to_travel(read_twist(rec)))


def wheel_gyro(rec: Recording) -> PoseData:
    """Wheel distance with the gyro's heading (module docstring): the odometry twist's travel per interval,
    its heading change from the integrated body-z gyro rate less the median rate at standstill."""
    odom, imu = read_twist(rec), read_imu(rec)
    gyro = gyro_yaw(imu, ImuNoise().with_sensor_keys(imu.noise))
    still = (np.abs(odom.vx) < 1e-3) & (np.abs(odom.wz) < 1e-3)
    still_at_imu = np.interp(gyro.t, odom.t, still.astype(float)) > 0.999
    bias = float(np.median(gyro.rate[still_at_imu])) if np.count_nonzero(still_at_imu) > 10 else 0.0
    angle = cumulative_angle(gyro) - bias * (gyro.t - gyro.t[0])
    travel = twist_to_travel(odom)
    dist = np.diff(0.5 * (travel.left + travel.right))
    dyaw = np.diff(np.interp(odom.t, gyro.t, angle))
    poses = np.zeros((len(odom.t), 3))
    for k in range(len(dist)):
        poses[k + 1] = se2.compose(poses[k], se2.exp((dist[k], 0.0, dyaw[k])))
    return PoseData(odom.t.copy(), poses)


def along_orientation(rec: Recording) -> PoseData:
    """The odometry's forward speed along the IMU's 3-D orientation (module docstring), in the IMU's world
    frame; the heading is that of the body's x axis on the floor plane."""
    odom, imu = read_twist(rec), read_imu(rec)
    if imu.orientation is None:
        raise ValueError(f"{rec.path}: the IMU states no orientation")
    t, v = odom.t, odom.vx
    q = np.asarray(imu.orientation, dtype=np.float64)
    sample = np.clip(np.searchsorted(imu.t, t), 0, len(imu.t) - 1)
    world_imu = Rotation.from_quat(q[sample][:, [1, 2, 3, 0]])
    axis = (world_imu * Rotation.from_matrix(np.asarray(imu.T_BS)[:3, :3]).inv()).apply([1.0, 0.0, 0.0])
    steps = (v[:-1] * np.diff(t))[:, None] * axis[:-1]
    xy = np.vstack([np.zeros((1, 3)), np.cumsum(steps, axis=0)])[:, :2]
    return PoseData(t.copy(), np.column_stack([xy, np.arctan2(axis[:, 1], axis[:, 0])]))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m fusion_vo.baseline", description=__doc__.splitlines()[0])
    ap.add_argument("seq", help="recording folder (cam0/data.csv and cam0/data/*.png)")
    args = ap.parse_args(argv)
    results, seconds = run(args.seq)
    measured = sum(m is not None for _, _, m in results)
    print(f"plain OpenCV script: {measured} of {len(results)} frame pairs measured, "
          f"{len(results) - measured} failed, {(len(results) + 1) / seconds:.1f} frames/s end to end")
    return 0


if __name__ == "__main__":
    sys.exit(main())
