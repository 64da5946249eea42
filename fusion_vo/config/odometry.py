"""Visual odometry's configuration: :class:`OdometrySettings` (the ``odometry`` section of a run configuration) and
:class:`OdometryConfig` (those settings with the frontend and its options, what
:func:`fusion_vo.odometry.run_visual_odometry` takes)."""

from __future__ import annotations

import math
import os
from typing import Annotated, Any, Literal

from pydantic import Field

from fusion_vo.choices import FRONTENDS
from fusion_vo.config.base import INTEGER, NUMBER, Float, Int, Section
from fusion_vo.measurements import MAX_CAMERA_HEIGHT_M

__all__ = ["OdometryConfig", "OdometrySettings", "available_cores"]


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the system reports it)."""
    try:
        return max(len(os.sched_getaffinity(0)), 1)
    except AttributeError:  # not Linux
        return max(os.cpu_count() or 1, 1)


class OdometrySettings(Section):
    """Visual odometry settings besides the frontend's: the ``odometry`` section of a run configuration (the run's
    ``frontend`` chooses the frontend and its own section configures it, :class:`OdometryConfig`)."""

    height: Annotated[float, Field(gt=0, le=MAX_CAMERA_HEIGHT_M), NUMBER] | None = Field(None, description=(
        "Camera height above the floor [m]; null takes it from ``T_BS`` of ``cam0/sensor.yaml``."))
    use_range: bool = Field(True, description=(
        "Use the downward range finder (``range0``), when the recording has one, as the camera height."))
    range_smoothing: bool = Field(True, description=(
        "With ``use_range``: estimate the height at every frame from all the readings together with the frames' "
        "own change of scale (:mod:`fusion_vo.geometry.height`), instead of from the one or two readings around "
        "the frame."))
    min_sigma_xy: Float = Field(2e-5, ge=0, le=10, description=(
        "Floor on the standard deviation of a visual increment's translation [m] (0: no floor)."))
    min_sigma_yaw: Float = Field(1.4e-5, ge=0, le=math.pi, description=(
        "Floor on the standard deviation of a visual increment's heading [rad] (0: no floor)."))
    max_bad_start_frames: Int = Field(5, ge=1, le=1_000_000, description=(
        "If this many frames in a row fail to load at the start (wrong size, unreadable), stop with an error "
        "instead of skipping them one by one."))
    gyro_derotation: bool = Field(True, description=(
        "When the recording has an IMU, remove the image motion of the camera's roll and pitch from every "
        "similarity before it becomes body motion (:mod:`fusion_vo.geometry.derotation`)."))
    uncalibrated: bool = Field(False, description=(
        "Run without the intrinsics of ``cam0/sensor.yaml``: a pinhole without distortion, principal point at the "
        "image centre, focal length ``focal_length`` (or the file's, or a 60 degree horizontal field of view). "
        "With ``lens_from_motion`` the lens distortion is then estimated from the frames themselves "
        "(:mod:`fusion_vo.calibration.lens_from_motion`); when the frames do not allow it, or without "
        "``lens_from_motion``, the frontends use only the central half of the width and height "
        "(``UNCALIBRATED_CENTRAL_REGION``, unless the frontend's options set ``central_region``), where the "
        "distortion left out is smallest. Without ``uncalibrated``, a ``sensor.yaml`` without intrinsics is an "
        "error."))
    focal_length: Annotated[float, Field(gt=0, le=1e6), NUMBER] | None = Field(None, description=(
        "Approximate focal length [px] for ``uncalibrated`` (checked against the image size when it is used)."))
    lens_from_motion: bool = Field(True, description=(
        "With ``uncalibrated``: estimate a one-parameter (division-model) lens distortion from tracks in 40 frame "
        "pairs spread over the recording before the run."))
    check_lens: bool = Field(True, description=(
        "Without ``uncalibrated``, when ``cam0/sensor.yaml`` states no lens distortion: check that against the "
        "frames (about 1.5 s of CPU) and, where a lens explains their tracks clearly better, use that lens with a "
        "warning naming the file (:func:`fusion_vo.calibration.lens_from_motion.check_stated_lens`)."))
    max_bridge: Float = Field(1.0, ge=0, le=3600, description=(
        "Longest gap [s] between the last measured frame and a restart of the frontend that the visual track "
        "bridges at constant velocity; across a longer gap it holds its last pose."))
    threads: Annotated[int, Field(ge=1, le=256), INTEGER] | None = Field(None, description=(
        "Threads the run may use: ``1`` decodes and tracks in the calling thread with OpenCV single-threaded; "
        "``N >= 2`` decodes and prepares frames ahead of the tracker in other threads (:func:`prepared_frames`) and "
        "lets OpenCV use ``N`` threads. Null uses the cores available to the process; at most 256, so that a "
        "mistyped value cannot start threads up to the process limit. The results do not depend on it."))
    handoff: bool = Field(False, description=(
        "With ``threads >= 2``, give a frontend that can hand work off (KLT, features) one more thread for it (off "
        "by default: it shortens the tracking thread, not the wall time, where the other threads already fill the "
        "cores; docs/decisions/0002-hand-off-thread-off-by-default.md). The results do not depend on it."))
    camera_noise: bool = Field(True, description=(
        "Use the heading noise model that ``cam0/sensor.yaml`` states under ``camera_noise`` for this frontend "
        "(``fusion-vo calibrate camera-noise``, :mod:`fusion_vo.calibration.camera_noise`): each increment's "
        "heading variance by its turn and each frame's own error, in place of the frontend's heading variance and "
        "the ``min_sigma_yaw`` floor (without the key nothing changes)."))

    def thread_count(self) -> int:
        """The number of threads to use (``threads``, or the cores available when it is ``None``)."""
        return self.threads if self.threads is not None else available_cores()


class OdometryConfig(OdometrySettings):
    """Visual odometry settings with the frontend and its options (what :func:`run_visual_odometry` takes)."""

    frontend: Literal[FRONTENDS] = Field("klt", description=(
        "``klt`` (pyramidal Lucas-Kanade tracking), ``features`` (corners, descriptors, matching) or ``direct`` "
        "(photometric alignment)."))
    frontend_options: dict[str, Any] = Field(default_factory=dict, description=(
        "Options of the chosen frontend (``frontends.klt.KltConfig``, ``frontends.features.FeatureConfig``, "
        "``frontends.direct.DirectConfig``), checked when the frontend is made."))
