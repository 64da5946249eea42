"""The names a run configuration chooses among (``sensors``, ``backend``, ``frontend``).

A module of its own, importing nothing, so that both the configuration (:mod:`fusion_vo.config`) and the
stages it configures (:class:`fusion_vo.config.odometry.OdometryConfig`) check a name against the same list.
"""

#: the built-in sensors; ``sensors`` and ``--sensors`` take any registered one (:mod:`fusion_vo.sensors.registry`)
SENSORS = ("camera", "wheel", "imu", "odom", "range", "gps")
BACKENDS = ("none", "ekf", "gtsam", "all")
FRONTENDS = ("klt", "features", "direct")
