"""Physical ranges of the measurements.

Beyond these a number read from a recording or a configuration is a corrupt row, a unit mix-up or a typo,
not a measurement (one ground-truth x of 1e300 scored a run "end 0.00 %"); each is an error naming it.
"""

#: a position [m] (ground truth, the initial pose): UTM northings and ECEF coordinates stay below 1e7 m
MAX_POSITION_M = 1e7
#: the camera's height above the floor [m] (``cam0/sensor.yaml``'s ``T_BS``, ``odometry.height``)
MAX_CAMERA_HEIGHT_M = 100.0
#: a gyro's angular rate or an odometry twist's yaw rate [rad/s] (gyros saturate at 35-70 rad/s)
MAX_ANGULAR_RATE = 100.0
#: an accelerometer's reading [m/s²] (about 100 g; most saturate at 16 g)
MAX_ACCELERATION = 1000.0
#: an odometry twist's forward or sideways speed [m/s]
MAX_SPEED = 100.0
#: a range finder's distance [m]
MAX_RANGE_M = 1e4
