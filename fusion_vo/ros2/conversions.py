"""ROS 2 messages to the fusion's samples, and its estimates to ``nav_msgs/Odometry``.

Inputs (each function takes the message and its time [s], the header stamp on the node's clock):

* ``sensor_msgs/Imu``: gyro and accelerometer; the orientation only where ``orientation_covariance[0]`` is
  not -1 and the quaternion is finite with a norm within 0.05 of 1 (the rule of ``fusion-vo import-bag``);
* ``nav_msgs/Odometry``: the body twist ``(linear.x, linear.y, angular.z)``; its ``child_frame_id`` must be
  the base frame (or empty);
* ``std_msgs/Int64MultiArray`` on ``wheel_ticks``: ``data = [stamp_sec, stamp_nanosec, left, right]``, the
  cumulative encoder counts of the left and right wheels at that time (ROS has no stamped tick message);
* ``sensor_msgs/NavSatFix``: skipped with ``status.status < 0`` (no fix); the east-north block of
  ``position_covariance`` where ``position_covariance_type > 0``, else ``horizontal_sigma_m`` of
  ``gps0/sensor.yaml``; East-North-Up at its ``datum`` (or at the first fix), as
  :func:`~fusion_vo.recording.gps.read_gps` reads an imported bag;
* ``sensor_msgs/Range``: a reading outside ``[min_range, max_range]`` (REP 117: nothing detected) is skipped;
* ``sensor_msgs/Image``: converted to grey by the bag importer's :func:`image_to_grey` (mono8, bgr8 and the
  other encodings it lists); its size must be the calibration's.

A message the node cannot use at all (a frame, an encoding, a size or a layout) raises :class:`Unusable`;
a message with NaN or a far-future stamp is handed on and the fusion counts it (``gated``).
"""

from __future__ import annotations

import math

import numpy as np
from nav_msgs.msg import Odometry

from fusion_vo.backends.streaming import Estimate
from fusion_vo.measurements import GpsFix, ImuSample, RangeSample, TwistSample, WheelTicks
from fusion_vo.recording.gps import geodetic_to_enu
from fusion_vo.recording.rosbag.images import UnsupportedImage, image_to_grey

#: variance given to the pose and twist components a planar estimate does not have (z, roll, pitch)
UNESTIMATED_VARIANCE = 1e6
#: the wheel_ticks layout: std_msgs/Int64MultiArray data
WHEEL_TICKS_LAYOUT = ("stamp_sec", "stamp_nanosec", "left", "right")


class Unusable(ValueError):
    """A message the node cannot use (its frame, encoding, size or layout): counted, reported once per topic."""


class Skipped(ValueError):
    """A message that says it has no measurement (a GPS without a fix, a range out of range): counted."""


def stamp_seconds(stamp) -> float:
    """A ``builtin_interfaces/Time`` in seconds."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def set_stamp(stamp, t: float) -> None:
    """Write ``t`` [s] into a ``builtin_interfaces/Time``."""
    ns = int(round(t * 1e9))
    stamp.sec, stamp.nanosec = ns // 1_000_000_000, ns % 1_000_000_000


class FrameCheck:
    """The frame a topic's messages must name: ``expected``, or (empty) that of the topic's first message."""

    def __init__(self, expected: str = ""):
        self.expected = expected.lstrip("/")

    def check(self, frame_id: str) -> None:
        frame = str(frame_id).lstrip("/")
        if not self.expected:
            self.expected = frame
        elif frame != self.expected:
            raise Unusable(f"frame '{frame}', not '{self.expected}' (its mounting is that of '{self.expected}')")


def imu_sample(msg, t: float) -> ImuSample:
    w, a, q = msg.angular_velocity, msg.linear_acceleration, msg.orientation
    quat = np.array([q.w, q.x, q.y, q.z], dtype=np.float64)
    valid = float(msg.orientation_covariance[0]) != -1.0 and bool(np.all(np.isfinite(quat))) and \
        abs(float(np.linalg.norm(quat)) - 1.0) < 0.05
    return ImuSample(t, np.array([w.x, w.y, w.z], dtype=np.float64), np.array([a.x, a.y, a.z], dtype=np.float64),
                     quat / np.linalg.norm(quat) if valid else None)


def twist_sample(msg, t: float, base_frame: str) -> TwistSample:
    child = str(msg.child_frame_id).lstrip("/")
    if child and child != base_frame.lstrip("/"):
        raise Unusable(f"twist in child_frame_id '{child}', not the base frame '{base_frame}'")
    tw = msg.twist.twist
    return TwistSample(t, float(tw.linear.x), float(tw.linear.y), float(tw.angular.z))


def wheel_ticks(msg) -> WheelTicks:
    data = list(msg.data)
    if len(data) != len(WHEEL_TICKS_LAYOUT):
        raise Unusable(f"{len(data)} values, expected {len(WHEEL_TICKS_LAYOUT)}: {', '.join(WHEEL_TICKS_LAYOUT)}")
    sec, nanosec, left, right = (int(v) for v in data)
    if not 0 <= nanosec < 1_000_000_000:
        raise Unusable(f"stamp_nanosec {nanosec} is not in [0, 1e9)")
    return WheelTicks(sec + nanosec * 1e-9, left, right)


def range_sample(msg, t: float) -> RangeSample:
    r, low, high = float(msg.range), float(msg.min_range), float(msg.max_range)
    if math.isinf(r) or (high > low and math.isfinite(r) and not low <= r <= high):
        raise Skipped(f"range {r:g} m outside [{low:g}, {high:g}] m")
    return RangeSample(t, r)


class GpsConverter:
    """NavSatFix to :class:`GpsFix` in ENU at the datum of ``gps0/sensor.yaml`` (or at the first fix)."""

    def __init__(self, settings: dict):
        self.datum = settings["datum"]
        self.sigma = float(settings["sigma"])

    def fix(self, msg, t: float) -> GpsFix:
        if int(msg.status.status) < 0:
            raise Skipped("no fix (status < 0)")
        lat, lon, alt = float(msg.latitude), float(msg.longitude), float(msg.altitude)
        if math.isfinite(lat) and math.isfinite(lon) and (abs(lat) > 90 or abs(lon) > 180):
            raise Unusable(f"latitude {lat} / longitude {lon} out of range")
        cov = np.eye(2) * self.sigma**2
        if int(msg.position_covariance_type) > 0:
            c = msg.position_covariance
            cov = np.array([[c[0], c[1]], [c[1], c[4]]], dtype=np.float64)
        if self.datum is None:
            if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(alt)):
                return GpsFix(t, np.full(2, np.nan), cov)  # counted by the fusion (gated)
            self.datum = (lat, lon, alt)
        enu = geodetic_to_enu([lat], [lon], [alt], self.datum)[0, :2]
        return GpsFix(t, enu, cov)


def grey_image(msg, width: int, height: int) -> np.ndarray:
    try:
        img = image_to_grey(msg)
    except UnsupportedImage as exc:
        raise Unusable(str(exc)) from None
    except ValueError as exc:
        raise Unusable(f"damaged image: {exc}") from None
    if img.shape != (height, width):
        raise Unusable(f"image is {img.shape[1]}x{img.shape[0]}, the calibration's {width}x{height}")
    return img


def odometry_message(est: Estimate, frame_id: str, child_frame_id: str) -> Odometry:
    """``nav_msgs/Odometry`` of an estimate: planar pose and body twist with their covariances (ROS order x, y,
    z, roll, pitch, yaw; the components a planar estimate lacks get :data:`UNESTIMATED_VARIANCE`)."""
    msg = Odometry()
    msg.header.frame_id, msg.child_frame_id = frame_id, child_frame_id
    set_stamp(msg.header.stamp, est.t)
    x, y, yaw = (float(v) for v in est.pose)
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    msg.pose.covariance = _planar_covariance(est.covariance)
    if est.twist is not None:
        vx, vy, wz = (float(v) for v in est.twist)
        msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.angular.z = vx, vy, wz
        msg.twist.covariance = _planar_covariance(est.twist_covariance)
    else:
        msg.twist.covariance = _planar_covariance(np.eye(3) * UNESTIMATED_VARIANCE)
    return msg


def _planar_covariance(cov3: np.ndarray) -> np.ndarray:
    cov = np.eye(6) * UNESTIMATED_VARIANCE
    idx = [0, 1, 5]
    cov[np.ix_(idx, idx)] = 0.5 * (np.asarray(cov3) + np.asarray(cov3).T)
    return cov.ravel()
