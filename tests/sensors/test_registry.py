"""Adding a sensor is one module plus its registration: a compass defined and registered in this file alone is
fused by the EKF and the factor graph; the built-in sensors live in their own modules."""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass

import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends.result import SensorCount
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.sensors import registry
from fusion_vo.sensors.model import MeasurementModel
from fusion_vo.sensors.registry import Sensor, Step
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


# --------------------------------------------------------------------------- the compass: everything it needs
@dataclass
class CompassData:
    """Absolute headings [rad] at times ``t``."""

    t: np.ndarray
    yaw: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class CompassNoise:
    """Compass noise.

    Attributes
    ----------
    sigma : float
        Standard deviation of one heading [rad] (default 0.02).
    """

    sigma: float = 0.02


@dataclass(frozen=True)
class CompassModel(MeasurementModel):
    """``h = ψ``: the pose's heading."""

    name: str = "compass"
    args: tuple = ("heading",)
    dim: int = 1
    angle_rows: tuple = (0,)

    def evaluate(self, heading):
        h = np.asarray(heading, dtype=np.float64)
        return h, {"heading": np.ones(h.shape + (1,))}


COMPASS = CompassModel()


def compass_intervals(iv, streams, config, counts):
    data = streams.extra["compass"]
    T = iv.t
    j = np.clip(np.searchsorted(data.t, T), 1, len(data.t) - 1)
    near = np.minimum(np.abs(data.t[j] - T), np.abs(data.t[j - 1] - T)) <= config.max_gap
    iv.extra["compass"] = (near, se2.wrap_angle(np.interp(T, data.t, np.unwrap(data.yaw))))
    counts.setdefault("compass", SensorCount()).used += int(near.sum())


def compass_measurements(iv, config):
    if "compass" not in iv.extra:
        return {}
    ok, yaw = iv.extra["compass"]
    return {"compass": (ok, yaw, config.section("compass").sigma ** 2)}


def compass_block(ekf, meas, k):
    m = meas.get("compass")
    return [ekf.block(COMPASS, m[1][k + 1], m[2])] if m is not None and m[0][k + 1] else []


def compass_factor(builder, nf, node):
    if "compass" not in builder.iv.extra:
        return
    ok, yaw = builder.iv.extra["compass"]
    if ok[node.g1]:
        var = builder.config.section("compass").sigma ** 2
        nf.factors.append(builder.model_factor(COMPASS, [yaw[node.g1]], [[var]], {"heading": (node.xj,)}))
        nf.sensors.append("compass")


COMPASS_SENSOR = Sensor(name="compass", where="compass0/", config=("compass", CompassNoise),
                        intervals=Step(100, compass_intervals), ekf_measurements=compass_measurements,
                        ekf_blocks=(Step(100, compass_block),), graph_unary=(Step(100, compass_factor),))


# --------------------------------------------------------------------------- tests
@pytest.fixture(scope="module")
def drive():
    """Wheels alone on a robot whose wheel base is 5 % larger than configured: their heading drifts."""
    s = synthetic_streams(SyntheticOptions(duration=30.0, wheel_base_factor=1.05), seed=4)
    rng = np.random.default_rng(7)
    t = np.arange(s.truth.t[0], s.truth.t[-1], 0.1)
    true_yaw = np.interp(t, s.truth.t, np.unwrap(s.truth.xyyaw[:, 2]))
    compass = CompassData(t, se2.wrap_angle(true_yaw + rng.normal(0.0, 0.02, len(t))))
    return s, compass


def _errors(track, truth):
    yaw = np.interp(track.t, truth.t, np.unwrap(truth.xyyaw[:, 2]))
    xy = np.column_stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)])
    heading = np.abs(se2.wrap_angle(track.xyyaw[:, 2] - yaw))
    return float(np.sqrt(np.mean(heading**2))), float(np.linalg.norm(track.xyyaw[-1, :2] - xy[-1]))


def test_a_sensor_registered_outside_the_library_is_fused_by_both_backends(drive):
    s, compass = drive
    config = {"graph": {"fixed_lag": 0.0}}
    wheels = SensorStreams(wheel=s.wheel, camera_height=s.camera_height)
    without = fuse(wheels.select(["wheel"]), "all", config)
    with registry.registered(COMPASS_SENSOR):
        assert "compass" in registry.names()
        streams = SensorStreams(wheel=s.wheel, camera_height=s.camera_height, extra={"compass": compass})
        assert streams.available() == ["wheel", "compass"]
        fused = fuse(streams.select(["wheel", "compass"]), "all", FusionConfig.from_dict(
            {**config, "compass": {"sigma": 0.02}}))
    assert "compass" not in registry.names()
    for name in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online"):
        yaw_without, end_without = _errors(without.trajectories[name], s.truth)
        yaw_with, end_with = _errors(fused.trajectories[name], s.truth)
        # measured: the wheels' heading is 0.087-0.089 rad RMS off and the end 0.74-0.75 m; with the compass
        # (0.02 rad per reading, 10 Hz) 0.008-0.011 rad and 0.02 m
        assert yaw_without > 0.07, (name, yaw_without)
        assert yaw_with < 0.015, (name, yaw_with)
        assert end_with < 0.1 * end_without, (name, end_with, end_without)
        assert fused.counts[name]["compass"].used >= 600, (name, fused.counts[name]["compass"])


def test_a_registered_sensors_configuration_goes_through_the_schema(drive):
    with registry.registered(COMPASS_SENSOR):
        assert FusionConfig.from_dict({"compass": {"sigma": 0.5}}).section("compass").sigma == 0.5
        assert FusionConfig().section("compass").sigma == 0.02
        with pytest.raises(InputError, match="compass.sigam"):
            FusionConfig.from_dict({"compass": {"sigam": 0.5}})
        with pytest.raises(InputError, match="compass.sigma"):
            FusionConfig.from_dict({"compass": {"sigma": -1.0}})
        with pytest.raises(ValueError, match="already registered"):
            registry.register(COMPASS_SENSOR)
    with pytest.raises(InputError, match="compass"):
        FusionConfig.from_dict({"compass": {"sigma": 0.5}})  # not registered: an unknown key
    with pytest.raises(InputError, match="unknown sensor 'compass'"):
        SensorStreams().select(["compass"])


def test_each_built_in_sensor_lives_in_its_own_module():
    """Every hook of a built-in sensor is defined in that sensor's module (GPS, range ... need no backend edits)."""
    home = {"camera": "fusion_vo.sensors.visual", "wheel": "fusion_vo.sensors.wheel", "odom": "fusion_vo.sensors.wheel",
            "imu": "fusion_vo.sensors.imu", "range": "fusion_vo.sensors.range", "gps": "fusion_vo.sensors.gps"}
    assert registry.names()[:6] == tuple(home)
    for sensor in registry.sensors()[:6]:
        hooks = []
        for f in dataclasses.fields(sensor):
            value = getattr(sensor, f.name)
            for item in value if isinstance(value, tuple) else (value,):
                fn = item.run if isinstance(item, Step) else item
                if inspect.isfunction(fn) or inspect.isclass(fn):
                    hooks.append((f.name, fn))
        assert len(hooks) >= 3, sensor.name
        for field_name, fn in hooks:
            assert fn.__module__ == home[sensor.name], (sensor.name, field_name, fn.__module__)
    gps = registry.get("gps")
    assert gps.intervals is not None and gps.ekf_run is not None and gps.graph_run is not None
    assert gps.node_times is not None and not gps.by_default({})


def test_the_built_in_sensors_configuration_sections_are_the_fusion_configs():
    config = FusionConfig()
    for sensor in registry.sensors():
        if sensor.config is not None:
            name, cls = sensor.config
            assert isinstance(config.section(name), cls), sensor.name
    assert {s.config[0] for s in registry.sensors() if s.config} == {"wheel", "odom", "imu", "range", "gps"}
