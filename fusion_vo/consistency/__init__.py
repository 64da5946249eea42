"""Inputs that contradict each other, caught before any backend fuses them.

The stage runs on the time-ordered measurements (:class:`~fusion_vo.sensors.streams.SensorStreams`), after
the frontend and before the backends (:func:`fusion_vo.backends.batch.fuse`). Each check estimates one
quantity from the data, compares it with what the recording's files state, decides, and says so in one
plain sentence that names the file and the key to change (:class:`Finding`):

``clocks``     a stream on a shifted clock (the yaw rates of camera, wheels and gyro against each other)
``mounting``   the IMU's rotation in the body frame (gyro axes against the other yaw rates, gravity in the
               accelerometer, the forward and centripetal accelerations against the accelerometer)
``wheels``     an encoder counting backwards; an odometry twist whose wz has the wrong sign, or whose
               velocity is not in the robot's frame
``scale``      the camera's and the wheels' distances, against both their priors

A sensor is corrected when the estimate is unambiguous, left out when its stated configuration is
contradicted but the data do not say what is right, and left as stated (with a warning) when the data
cannot decide. :func:`check_streams` runs them in order (:mod:`fusion_vo.consistency.stage`).
"""

import lazy_loader

# the checks load on first use: the configuration section (imported by the backends' configuration) is cheap
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "config": ["ConsistencyConfig"],
    "finding": ["Finding"],
    "stage": ["Checked", "check_streams"],
})
