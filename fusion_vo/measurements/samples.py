"""Measurements that flow from the recording and the ground geometry into the backends.

Two shapes of the same data:

* per-sample dataclasses (:class:`VisualIncrement`, :class:`WheelTicks`, :class:`ImuSample`,
  :class:`TwistSample`, :class:`RangeSample`, :class:`GpsFix`) for the streaming API, one object per measurement;
* per-stream arrays (:class:`ImuData`, :class:`WheelData`, :class:`TwistData`, :class:`RangeData`,
  :class:`PoseData`, :class:`GpsData`) as read from a recording, for batch use without millions of small objects.

All times are seconds on the recording's clock (``float``). Poses and increments are ``(x, y, yaw)`` of
the body frame B (REP-103: x forward, y left, z up; origin on the floor under the drive axle).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# --------------------------------------------------------------------------- per-sample
@dataclass(frozen=True)
class VisualIncrement:
    """Body motion between two camera frames, from the ground geometry.

    Attributes
    ----------
    t0, t1 : float
        Times of the previous and the current frame [s].
    delta : ndarray, shape (3,)
        Pose of B(t1) in B(t0): ``(dx [m], dy [m], dyaw [rad])``.
    covariance : ndarray, shape (3, 3)
        Covariance of ``delta`` (from the frontend's inlier residuals).
    height_ratio : float
        ``h(t1) / h(t0)`` of the camera height above the floor, from the similarity's scale.
    status : str
        The frontend's status (``"ok"`` when usable; anything else contributes nothing).
    n_inliers : int
        Inlier correspondences behind the estimate.
    frame_covariance : ndarray, shape (3, 3), optional
        The part of ``covariance`` that is the error of each of the two frames' own measurements, in the
        units of ``delta`` (:mod:`fusion_vo.sensors.visual`): an increment's error is ``e_t1 - e_t0 + w``
        with ``e ~ N(0, frame_covariance)`` shared with the neighbouring increments and
        ``w ~ N(0, covariance - 2 frame_covariance)`` its own. None (the default): the backends use
        ``fusion.visual_frame_error``.
    """

    t0: float
    t1: float
    delta: np.ndarray
    covariance: np.ndarray
    height_ratio: float = 1.0
    status: str = "ok"
    n_inliers: int = 0
    frame_covariance: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def dt(self) -> float:
        return self.t1 - self.t0


@dataclass(frozen=True)
class WheelTicks:
    """Cumulative encoder counts at time ``t`` (signed 32-bit, may wrap)."""

    t: float
    left: int
    right: int


@dataclass(frozen=True)
class TwistSample:
    """Body-frame twist from a robot's own odometry: ``vx, vy`` [m/s], ``wz`` [rad/s]."""

    t: float
    vx: float
    vy: float
    wz: float


@dataclass(frozen=True)
class ImuSample:
    """One IMU sample in the IMU frame.

    ``gyro`` [rad/s] and ``accel`` [m/s^2] are 3-vectors; ``orientation`` is an optional AHRS
    quaternion ``(w, x, y, z)`` of the IMU in the world.
    """

    t: float
    gyro: np.ndarray
    accel: np.ndarray
    orientation: np.ndarray | None = None


@dataclass(frozen=True)
class RangeSample:
    """Downward range finder: distance to the floor [m] (camera height)."""

    t: float
    distance: float


@dataclass(frozen=True)
class GpsFix:
    """One GNSS fix: antenna ``east, north`` [m] in ENU at the datum and its 2x2 covariance [m²]."""

    t: float
    enu: np.ndarray
    covariance: np.ndarray


# --------------------------------------------------------------------------- per-stream arrays
@dataclass
class WheelConfig:
    """Differential-drive calibration (``wheel0/sensor.yaml``).

    ``radius_sigma`` is the standard deviation [m] of each wheel's radius error (from tyre pressure,
    wear and load), or None when the file does not state it: the prior of the wheels' common distance
    scale and, as independent left and right errors, of their curvature bias.
    """

    ticks_per_revolution: float
    wheel_radius_left: float
    wheel_radius_right: float
    wheel_base: float
    radius_sigma: float | None = None

    def relative_radius_sigma(self, default: float) -> float:
        """``radius_sigma / radius`` (the mean of the two radii), or ``default`` when it is not stated."""
        if self.radius_sigma is None:
            return float(default)
        return float(2.0 * self.radius_sigma / (self.wheel_radius_left + self.wheel_radius_right))


@dataclass
class WheelData:
    """Encoder stream: times ``t`` (N,), cumulative counts ``left``, ``right`` (N,) int64 as recorded."""

    t: np.ndarray
    left: np.ndarray
    right: np.ndarray
    config: WheelConfig

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class ImuData:
    """IMU stream: ``t`` (N,), ``gyro`` (N, 3), ``accel`` (N, 3), optional ``orientation`` (N, 4) w,x,y,z.

    ``T_BS`` is the IMU's pose in the body frame; ``noise`` holds the EuRoC noise keys of
    ``imu0/sensor.yaml`` (gyroscope_noise_density, gyroscope_random_walk, accelerometer_noise_density,
    accelerometer_random_walk) when given.
    """

    t: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    orientation: np.ndarray | None = None
    T_BS: np.ndarray = field(default_factory=lambda: np.eye(4))
    rate_hz: float | None = None
    noise: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class TwistData:
    """Odometry twist stream: ``t``, ``vx``, ``vy``, ``wz`` (N,)."""

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    wz: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class RangeData:
    """Range-finder stream: ``t``, ``distance`` (N,)."""

    t: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class PoseData:
    """Planar poses over time: ``t`` (N,), ``xyyaw`` (N, 3); ``z`` and full quaternions kept when known."""

    t: np.ndarray
    xyyaw: np.ndarray
    z: np.ndarray | None = None
    quat_wxyz: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class GpsData:
    """GNSS fixes in local East-North-Up at the datum (``gps0``), after skipping unusable fixes.

    Attributes
    ----------
    t : ndarray (N,)
        Times [s].
    enu : ndarray (N, 3)
        East, north, up of the antenna [m] relative to ``datum``.
    covariance : ndarray (N, 2, 2)
        Horizontal (east, north) covariance of each fix [m²]; the default sigma where a fix had none.
    geodetic : ndarray (N, 3)
        Latitude, longitude [deg] and ellipsoidal altitude [m] as recorded.
    status : ndarray (N,) int
        NavSatFix status (0 fix, 1 SBAS, 2 GBAS); 0 when the file has no status column.
    datum : tuple of float
        Latitude, longitude [deg], altitude [m] of the ENU origin.
    lever_arm : ndarray (3,)
        Antenna position in the body frame [m] (translation of ``T_BS``).
    horizontal_sigma : float
        Default standard deviation [m] used for fixes without a covariance.
    skipped : dict
        Reason -> number of fixes skipped (``no fix``, ``NaN``, ``zero covariance``: any covariance that is not
        positive definite).
    notes : list of str
        What was assumed or skipped, for the run's notes.
    """

    t: np.ndarray
    enu: np.ndarray
    covariance: np.ndarray
    geodetic: np.ndarray
    status: np.ndarray
    datum: tuple
    lever_arm: np.ndarray
    horizontal_sigma: float
    skipped: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t)

    def samples(self) -> list[GpsFix]:
        """The fixes one at a time (east, north and covariance), for the streaming API."""
        return [GpsFix(float(t), self.enu[i, :2].copy(), self.covariance[i].copy()) for i, t in enumerate(self.t)]
