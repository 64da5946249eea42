"""Sensor models: wheel encoders and odometry twist, IMU (gyro, AHRS), downward range finder, GPS.

Each module turns a recorded stream (arrays from :mod:`fusion_vo.measurements`) into gated samples with
a documented noise model; the backends integrate them between their nodes. Each module also registers its sensor with
:mod:`fusion_vo.sensors.registry` (reader, configuration section, timeline, EKF and graph parts), which
is how the rest of the library finds it. :mod:`fusion_vo.sensors.instances` declares the further instances
of the odometry-twist and IMU kinds (``odom1`` ... ``odom9``, ``imu1`` ... ``imu9``), made when a name asks for one.
"""

from fusion_vo.sensors.gps import GpsModel, GpsNoise, align_to_fixes
from fusion_vo.sensors.imu import ImuNoise, ahrs_heading, gyro_yaw
from fusion_vo.sensors.range import RangeNoise, camera_height
from fusion_vo.sensors.wheel import (
    WheelNoise, arc_covariance, arc_increment, ticks_to_travel, unwrap_ticks, wheel_track,
)

__all__ = [
    "GpsModel", "GpsNoise", "ImuNoise", "align_to_fixes", "RangeNoise", "WheelNoise", "ahrs_heading", "arc_covariance", "arc_increment",
    "camera_height", "gyro_yaw", "ticks_to_travel", "unwrap_ticks", "wheel_track",
]
