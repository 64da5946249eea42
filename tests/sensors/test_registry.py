"""Adding a sensor is one module plus its registration: a compass defined in compass_sensor.py (beside this file)
and registered here is fused by the EKF and the factor graph, adds a state variable both estimate, goes through
the configuration schema, the command line and run.yaml, and streams through ``StreamingFusion.add``; the
built-in sensors live in their own modules."""

from __future__ import annotations

import dataclasses
import inspect
import numpy as np
import pytest

from compass_sensor import COMPASS_LIVE, COMPASS_SENSOR, NORTH_COMPASS_SENSOR, OFFSET_COMPASS_SENSOR, CompassData

from fusion_vo.backends import FusionConfig, SensorStreams, dead_reckoning, fuse
from fusion_vo.backends.graph_builder import GraphBuilder
from fusion_vo.backends.streaming import StreamingFusion, streaming_for, time_ordered_messages
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.measurements import ImuSample, PoseData, TwistData, TwistSample
from fusion_vo.sensors import registry
from fusion_vo.sensors.instances import imu_instance
from fusion_vo.sensors.registry import Sensor, State, Step
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams
from fusion_vo.sensors.wheel import ticks_to_travel, wheel_grid, wheel_track

#: the offset compass's true offset [rad]
OFFSET = 0.2


# the compass (data, noise section, models, hooks and the Sensor(...) registrations) is in compass_sensor.py,
# a module of these tests: nothing of it is in the library
# --------------------------------------------------------------------------- tests
def _drive(duration: float):
    """Wheels alone on a robot whose wheel base is 5 % larger than configured (their heading drifts), and the
    readings of a compass (0.02 rad noise, 10 Hz)."""
    s = synthetic_streams(SyntheticOptions(duration=duration, wheel_base_factor=1.05), seed=4)
    rng = np.random.default_rng(7)
    t = np.arange(s.truth.t[0], s.truth.t[-1], 0.1)
    true_yaw = np.interp(t, s.truth.t, np.unwrap(s.truth.xyyaw[:, 2]))
    compass = CompassData(t, se2.wrap_angle(true_yaw + rng.normal(0.0, 0.02, len(t))))
    return s, compass


@pytest.fixture(scope="module")
def drive():
    """30 s of :func:`_drive`."""
    return _drive(30.0)


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


def _heading_track(data: CompassData, config) -> PoseData:
    """The compass's headings alone, at the origin: a track of its own."""
    return PoseData(data.t.copy(), np.column_stack([np.zeros((len(data), 2)), data.yaw]))


def test_a_registered_sensors_dead_reckoning_is_kept_beside_the_fused_tracks(drive):
    """``Sensor.dead_reckoning``: the track a sensor's data alone give is kept under its name, as the wheels' is as
    ``wheel`` (from the ticks, before the odometry twist)."""
    s, compass = drive
    with registry.registered(dataclasses.replace(COMPASS_SENSOR, dead_reckoning=("compass", _heading_track))):
        streams = SensorStreams(wheel=s.wheel, extra={"compass": compass}).select(["wheel", "compass"])
        fused = fuse(streams, "ekf", FusionConfig.from_dict({"compass": {"sigma": 0.02}}))
    assert set(fused.trajectories) == {"wheel", "compass", "ekf", "ekf_smoothed"}
    np.testing.assert_array_equal(fused.trajectories["compass"].xyyaw, _heading_track(compass, None).xyyaw)
    ticks = wheel_track(ticks_to_travel(s.wheel, FusionConfig().wheel))
    np.testing.assert_array_equal(fused.trajectories["wheel"].xyyaw, ticks.xyyaw)
    t = np.arange(s.wheel.t[0], s.wheel.t[-1], 0.04)  # a twist of 0.5 m/s straight ahead at 25 Hz
    twist = SensorStreams(wheel=s.wheel, odom=TwistData(t, np.full(len(t), 0.5), np.zeros(len(t)), np.zeros(len(t))))
    assert dead_reckoning(twist)["wheel"].t.size == len(s.wheel)  # the ticks' track, not the twist's
    np.testing.assert_array_equal(dead_reckoning(twist)["wheel"].xyyaw, ticks.xyyaw)
    only_twist = dead_reckoning(SensorStreams(odom=twist.odom))["wheel"]
    assert only_twist.t.size == len(t)
    np.testing.assert_allclose(only_twist.xyyaw[-1], [0.5 * (t[-1] - t[0]), 0.0, 0.0], atol=1e-9)


#: the late compass's stated latency [s]
LATENCY = 0.3


def _compass_clock(streams, config):
    """A compass's clock step: its readings, stamped :data:`LATENCY` late, moved back onto the wheels' clock."""
    data = streams.get("compass")
    if data is None:
        return streams, None
    return (streams.replace(compass=CompassData(data.t - LATENCY, data.yaw)),
            registry.ClockOffset("compass_latency", LATENCY, "compass stamped 300 ms late: its timestamps corrected"))


def test_a_registered_sensors_clock_step_puts_its_data_on_the_run_clock(drive):
    """``Sensor.clock``: a compass stamped 0.3 s late, whose step moves its stamps back, is fused as the compass on
    time (to 1e-9); the offset is reported beside the odometry twist's (``time_offsets``, a note). Without the
    step the late compass leaves a larger heading error."""
    s, compass = drive
    late = CompassData(compass.t + LATENCY, compass.yaw)

    def fused(data, sensor):
        with registry.registered(sensor):
            return fuse(SensorStreams(wheel=s.wheel, extra={"compass": data}).select(["wheel", "compass"]), "ekf",
                        FusionConfig.from_dict({"compass": {"sigma": 0.02}}))

    on_time = fused(compass, COMPASS_SENSOR)
    moved = fused(late, dataclasses.replace(COMPASS_SENSOR, clock=Step(5, _compass_clock)))
    unmoved = fused(late, COMPASS_SENSOR)
    # (the same readings: their times differ only by the rounding of adding and removing the latency)
    np.testing.assert_allclose(moved.trajectories["ekf"].xyyaw, on_time.trajectories["ekf"].xyyaw, rtol=0, atol=1e-9)
    assert moved.time_offsets == {"compass_latency": LATENCY} and on_time.time_offsets == {}
    assert "compass stamped 300 ms late: its timestamps corrected" in moved.notes
    assert _errors(unmoved.trajectories["ekf"], s.truth)[0] > 1.5 * _errors(moved.trajectories["ekf"], s.truth)[0]


def _turn_of(turn: float):
    """A motion step that replaces the heading change of every interval whose motion is known by ``turn``."""
    def step(iv, motion):
        out = motion.copy()
        out[np.isfinite(out[:, 2]), 2] = turn
        return out
    return step


def test_a_registered_motion_step_is_the_engines_motion_between_nodes():
    """``Sensor.motion``: the streaming engine's motion over a sliver between a node and a time between nodes (a
    late increment's frame, a GPS fix) is the registered steps' in their order: the odometry twist's arc (0.5 m/s,
    0.08 rad/s) with the gyro's turn (0.1 rad/s) over 13 ms, inverted backwards; a registered step after them
    replaces the turn, and one that leaves the motion unknown leaves the sliver unplaced."""
    fusion = StreamingFusion("ekf", FusionConfig(), ["imu", "odom"], steps_per_call=None)
    for k in range(300):
        t = 1000.0 + 0.01 * k
        fusion.add_imu(ImuSample(t, np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.0, 9.81])))
        fusion.add("odom", TwistSample(t, 0.5, 0.0, 0.08))
    x, y, dt = 1001.0, 1001.013, 0.013
    motion, var = fusion._sliver(x, y)
    d, arc = 0.5 * dt, 0.08 * dt  # the twist's arc: its chord, turned by half its angle; the gyro's turn
    np.testing.assert_allclose(motion, [d * np.sin(arc) / arc, d * (1.0 - np.cos(arc)) / arc, 0.1 * dt], rtol=0,
                               atol=1e-12)
    np.testing.assert_allclose(fusion._sliver(y, x)[0], se2.inverse(motion), rtol=0, atol=1e-12)
    np.testing.assert_allclose(var, (0.02 * np.abs(motion)) ** 2 + 1e-8)
    with registry.registered(Sensor(name="turnmeter", motion=Step(30, _turn_of(0.002)))):
        assert fusion._sliver(x, y)[0][2] == 0.002
    with registry.registered(Sensor(name="turnmeter", motion=Step(30, _turn_of(float("nan"))))):
        assert fusion._sliver(x, y) is None
    assert fusion._sliver(x, y)[0][2] == motion[2]


def test_a_registered_whole_recording_step_sees_every_sensor_on_the_grid(drive):
    """``Sensor.whole_recording``: a compass's step runs once on a whole recording's grid, after every sensor's samples
    are on it (the wheels' too, whatever the steps' order) and before the readings are taken: here it leaves out the
    compass's first half, and the EKF uses the other half only. The streaming engine does not run it."""
    s, compass = drive
    calls = []

    def second_half(iv, config):
        calls.append((len(iv.t), bool(wheel_grid(iv).ok.any())))
        near, yaw = iv.extra["compass"]
        iv.extra["compass"] = (near & (iv.t >= iv.t[len(iv.t) // 2]), yaw)

    sensor = dataclasses.replace(COMPASS_SENSOR, live=COMPASS_LIVE, whole_recording=Step(1, second_half))
    with registry.registered(sensor):
        streams = SensorStreams(wheel=s.wheel, extra={"compass": compass}).select(["wheel", "compass"])
        half = fuse(streams, "ekf", FusionConfig.from_dict({"compass": {"sigma": 0.02}}))
        assert calls == [(len(half.trajectories["ekf"]), True)]
        _stream("ekf", s, compass)
    assert len(calls) == 1
    with registry.registered(COMPASS_SENSOR):
        whole = fuse(streams, "ekf", FusionConfig.from_dict({"compass": {"sigma": 0.02}}))
    used, all_used = half.counts["ekf"]["compass"].used, whole.counts["ekf"]["compass"].used
    assert abs(used - all_used / 2) <= 2, (used, all_used)


def test_a_registered_sensors_first_guess_starts_the_graph_beside_the_built_in_ones(drive):
    """``Sensor.first_guesses``: the graph's initial values of the states, each sensor's step given those before it.
    On wheels whose base is 5 % long and a gyro with a bias, without a camera: the gyro's bias against the wheels'
    heading changes, then the wheel base against the gyro's corrected ones, then the compass's own guess."""
    s, compass = drive
    seen = []

    def offset_guess(iv, guesses):
        seen.append(dict(guesses))
        return {"compass_offset": 0.2}

    sensor = dataclasses.replace(OFFSET_COMPASS_SENSOR, first_guesses=Step(40, offset_guess))
    with registry.registered(sensor):
        streams = SensorStreams(wheel=s.wheel, imu=s.imu, extra={"compass": compass}).select(["wheel", "imu", "compass"])
        config = FusionConfig.from_dict({"compass": {"sigma": 0.02}})
        guesses = GraphBuilder(build_intervals(streams, config), config).initial_estimate
    assert list(guesses) == ["gyro_bias", "wheel_base_factor", "compass_offset"]
    assert seen == [{k: guesses[k] for k in ("gyro_bias", "wheel_base_factor")}]
    assert guesses["compass_offset"] == 0.2
    # measured: 1.053 against the drive's 5 % long wheel base, and a bias of 0.0145 rad/s against its 0.01 (the
    # wheels' heading changes it is read against are those of the long base)
    assert abs(guesses["wheel_base_factor"] - 1.05) < 0.02, guesses
    assert abs(guesses["gyro_bias"] - SyntheticOptions().gyro_bias) < 0.01, guesses


def test_a_registered_sensors_configuration_goes_through_the_schema(drive):
    with registry.registered(COMPASS_SENSOR):
        assert FusionConfig.from_dict({"compass": {"sigma": 0.5}}).section("compass").sigma == 0.5
        assert FusionConfig().section("compass").sigma == 0.02
        with pytest.raises(ValueError, match=r"^FusionConfig: compass\.sigam: unknown key \(known: sigma\)$"):
            FusionConfig.from_dict({"compass": {"sigam": 0.5}})
        with pytest.raises(ValueError, match=r"^FusionConfig: compass: sigma must be positive, not -1\.0$"):
            FusionConfig.from_dict({"compass": {"sigma": -1.0}})
        with pytest.raises(ValueError, match="must be a fusion_vo.config.base.Section"):  # one base for every section
            registry.register(dataclasses.replace(COMPASS_SENSOR, name="plain", config=("plain", dict)))
        with pytest.raises(ValueError, match="already registered"):
            registry.register(COMPASS_SENSOR)
    with pytest.raises(ValueError, match="compass: unknown key"):
        FusionConfig.from_dict({"compass": {"sigma": 0.5}})  # not registered: an unknown key
    with pytest.raises(InputError, match="unknown sensor 'compass'"):
        SensorStreams().select(["compass"])


def test_each_built_in_sensor_lives_in_its_own_module():
    """Every hook of a built-in sensor, its heading sources' too, is defined in that sensor's module or one of its
    parts (``wheel_arc``, ``wheel_states``, the IMU's ``gyro``, the camera's ``visual_noise``: GPS, range ... need no
    backend edits)."""
    home = {"camera": "fusion_vo.sensors.visual", "wheel": "fusion_vo.sensors.wheel", "odom": "fusion_vo.sensors.wheel",
            "imu": "fusion_vo.sensors.imu", "range": "fusion_vo.sensors.range", "gps": "fusion_vo.sensors.gps"}
    assert registry.names()[:6] == tuple(home)
    for sensor in registry.sensors()[:6]:
        hooks = []
        for f in dataclasses.fields(sensor):
            value = getattr(sensor, f.name)
            for item in value if isinstance(value, tuple) else (value,):
                if isinstance(item, (registry.Live, registry.HeadingSource, registry.DistanceSource)):  # intake, monitor
                    hooks += [(f"{f.name}.{g.name}", getattr(item, g.name)) for g in dataclasses.fields(item)
                              if inspect.isfunction(getattr(item, g.name))]
                    continue
                fn = item.run if isinstance(item, Step) else item
                if inspect.isfunction(fn) or inspect.isclass(fn):
                    hooks.append((f.name, fn))
        assert len(hooks) >= 3, sensor.name
        for field_name, fn in hooks:
            parts = (home[sensor.name], home[sensor.name] + "_arc", home[sensor.name] + "_states")
            parts += {"imu": ("fusion_vo.sensors.gyro",), "camera": ("fusion_vo.sensors.visual_noise",)}.get(sensor.name, ())
            assert fn.__module__ in parts, (sensor.name, field_name, fn.__module__)
    assert {h.key for _, h in registry.heading_sources()} == {"camera", "wheel", "gyro", "ahrs"}
    assert {d.key for _, d in registry.distance_sources()} == {"camera", "wheel"}
    assert [s.name for s in registry.sensors()[:6] if s.live is not None] == list(home)
    assert [s.name for s in registry.sensors()[:6] if s.live.take is not None] == ["camera", "gps"]
    gps = registry.get("gps")
    assert gps.intervals is not None and gps.readings is not None and gps.absolute_position
    assert gps.node_times is not None and not gps.by_default({})


def test_the_built_in_sensors_configuration_sections_are_the_fusion_configs():
    config = FusionConfig()
    for sensor in registry.sensors():
        if sensor.config is not None:
            name, cls = sensor.config
            assert isinstance(config.section(name), cls), sensor.name
    assert {s.config[0] for s in registry.sensors() if s.config} == {"wheel", "odom", "imu", "range", "gps"}


# --------------------------------------------------------------------------- state a sensor adds
def _offset_compass(compass: CompassData) -> CompassData:
    """The same readings from a compass whose heading is off by ``OFFSET``."""
    return CompassData(compass.t, se2.wrap_angle(compass.yaw + OFFSET))


def test_a_registered_sensor_adds_a_state_that_both_backends_estimate(drive):
    """A compass with an unknown constant offset declares it as a state; EKF, RTS, GTSAM batch and iSAM2 estimate
    it against the known start heading, and the heading is right. The same readings from a compass taken as
    absolute (no state) leave the whole offset in the heading: the state is what makes the difference."""
    s, compass = drive
    streams = SensorStreams(wheel=s.wheel, camera_height=s.camera_height, extra={"compass": _offset_compass(compass)})
    config = FusionConfig.from_dict({"graph": {"fixed_lag": 0.0}})
    with registry.registered(OFFSET_COMPASS_SENSOR):
        fused = fuse(streams.select(["wheel", "compass"]), "all", config)
    with registry.registered(COMPASS_SENSOR):
        absolute = fuse(streams.select(["wheel", "compass"]), "all", config)
    for name in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online"):
        yaw_with, _ = _errors(fused.trajectories[name], s.truth)
        yaw_absolute, _ = _errors(absolute.trajectories[name], s.truth)
        estimate = fused.calibration[name]["compass_offset"]
        # measured: offset 0.1977-0.1982 (EKF σ 0.011), heading 0.008-0.011 rad RMS; absolute: 0.195-0.197 rad
        assert abs(estimate - OFFSET) < 0.01, (name, estimate)
        assert yaw_with < 0.015, (name, yaw_with)
        assert yaw_absolute > 0.15, (name, yaw_absolute)
        assert fused.counts[name]["compass"].used >= 600, (name, fused.counts[name]["compass"])
    sigma = fused.calibration["ekf"]["compass_offset_sigma"]
    assert 0.003 < sigma < 0.03 and abs(fused.calibration["ekf"]["compass_offset"] - OFFSET) < 3 * sigma


@pytest.fixture(scope="module")
def short_drive():
    """10 s of :func:`_drive`, the compass's heading off by ``OFFSET``."""
    s, compass = _drive(10.0)
    return s, SensorStreams(wheel=s.wheel, camera_height=s.camera_height, extra={"compass": _offset_compass(compass)})


def test_a_states_prior_and_random_walk_come_from_the_configuration(short_drive):
    """``fusion: {states: {compass_offset: ...}}`` replaces the prior and random walk the sensor registers, in
    both backends: with a prior σ_p (centred on the truth) the offset's posterior σ is the information sum
    ``(σ_p⁻² + σ_d⁻²)^-½`` of that prior and of what the data alone give (σ_d, under a prior of 100 rad); a
    random walk leaves the end's offset less certain than a constant."""
    _, streams = short_drive
    names = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")
    with registry.registered(OFFSET_COMPASS_SENSOR):
        def run(prior):
            config = FusionConfig.from_dict({"graph": {"fixed_lag": 0.0}, "states": {"compass_offset": prior}})
            assert config.states["compass_offset"] == OFFSET_COMPASS_SENSOR.states[0].prior().merged(prior)
            calibration = fuse(streams.select(["wheel", "compass"]), "all", config).calibration
            return {name: calibration[name]["compass_offset_sigma"] for name in names}, calibration

        data, _ = run({"sigma": 100.0})
        tight, estimate = run({"initial": OFFSET, "sigma": 0.005})
        walk, _ = run({"random_walk": 0.01})
    for name in names:
        expected = (0.005**-2 + data[name] ** -2) ** -0.5
        # measured: σ_d 0.0096 (batch) to 0.0108 (EKF); posterior 0.00443-0.00454 against 0.00443-0.00454
        # expected (iSAM2 2 % below); with the random walk 0.027-0.031
        assert 0.007 < data[name] < 0.015, (name, data[name])
        assert abs(tight[name] / expected - 1.0) < 0.05, (name, tight[name], expected)
        assert abs(estimate[name]["compass_offset"] - OFFSET) < 0.005, (name, estimate[name])
        assert walk[name] > 2.0 * data[name], (name, walk[name], data[name])


def test_a_registered_heading_sensor_makes_the_wheel_base_observable(drive):
    """A sensor that declares ``absolute_heading`` is a heading reference beside the wheels, as the IMU's AHRS
    is: the wheel-base factor (5 % off) is estimated with it, and not with the same sensor undeclared."""
    s, compass = drive
    streams = SensorStreams(wheel=s.wheel, camera_height=s.camera_height, extra={"compass": _offset_compass(compass)})
    declared = dataclasses.replace(OFFSET_COMPASS_SENSOR, absolute_heading=True)
    config = FusionConfig.from_dict({"graph": {"fixed_lag": 0.0}})
    with registry.registered(OFFSET_COMPASS_SENSOR):
        plain = fuse(streams.select(["wheel", "compass"]), "all", config)
    with registry.registered(declared):
        calibrated = fuse(streams.select(["wheel", "compass"]), "all", config)
    for name in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online"):
        assert "wheel_base_factor" not in plain.calibration[name], (name, plain.calibration[name])
        # measured: 1.046-1.047 (EKF, GTSAM batch), 1.062 (iSAM2)
        assert abs(calibrated.calibration[name]["wheel_base_factor"] - 1.05) < 0.015, (name, calibrated.calibration[name])


def test_a_registered_heading_sensor_is_a_reference_for_the_wheels_curvature(drive):
    """A sensor that declares ``absolute_heading`` has no bias of its own: beside encoder ticks and a gyro it tells
    the wheels' curvature from the gyro's bias, so ``estimate_curvature: auto`` estimates it, as with a camera, an
    AHRS or GPS; ``heading_reference=False`` (a second gyro's) leaves it out and says why."""
    s, compass = drive
    streams = SensorStreams(wheel=s.wheel, imu=s.imu, extra={"compass": compass})
    results = {}
    for ref in (None, False):
        with registry.registered(dataclasses.replace(COMPASS_SENSOR, absolute_heading=True, heading_reference=ref)):
            results[ref] = fuse(streams.select(["wheel", "imu", "compass"]), "ekf", FusionConfig())
    assert "wheel_curvature" in results[None].calibration["ekf"], results[None].calibration
    assert not [n for n in results[None].notes if "curvature bias not estimated" in n], results[None].notes
    assert "wheel_curvature" not in results[False].calibration["ekf"], results[False].calibration
    assert [n for n in results[False].notes if "curvature bias not estimated" in n], results[False].notes
    # live, from the sensors declared: the camera and GPS are references, the IMU only once its samples show an
    # AHRS, a second gyro never
    assert [registry.get(n).references_heading(None) for n in ("camera", "gps", "imu", "wheel")] == [
        True, True, False, False]
    assert imu_instance(1).references_heading(None) is False


def test_a_state_is_checked_when_registered():
    with pytest.raises(ValueError, match="sigma"):
        State("compass_offset", sigma=0.0)
    with pytest.raises(ValueError, match="random_walk"):
        State("compass_offset", random_walk=float("nan"))
    clash = dataclasses.replace(OFFSET_COMPASS_SENSOR, states=(State("gyro_bias"),))
    with pytest.raises(ValueError, match="gyro_bias"):
        registry.register(clash)
    assert "compass" not in registry.names()


# --------------------------------------------------------------------------- streaming
def _stream(backend: str, s, compass: CompassData, extra_samples=()):
    """Stream the wheels and the compass as a replay does: every message through ``add(kind, message)``."""
    streams = SensorStreams(wheel=s.wheel, extra={"compass": compass})
    fusion = streaming_for(streams, backend, {"reorder_window": 0.1})
    assert fusion.sensors == ["wheel", "compass"]
    messages = [(t, 0, kind, m) for t, kind, m in time_ordered_messages(streams)] + list(extra_samples)
    assert {kind for _, _, kind, _ in messages} == {"wheel", "compass"}
    for _, _, kind, message in sorted(messages, key=lambda m: (m[0], m[1])):
        fusion.add(kind, message)
    return fusion, fusion.finish()


def _batch_and_streamed(streams: SensorStreams, backend: str) -> tuple:
    """The batch run of ``streams`` with ``backend`` and the same streams fed to the engine in time order."""
    batch = fuse(streams, backend, FusionConfig())
    fusion = streaming_for(streams, backend, FusionConfig())
    fusion.feed(time_ordered_messages(streams))
    return batch, fusion.finish()


class _LatencyClock:
    """A compass's live clock (``Live.clock``): its stamps :data:`LATENCY` late, moved back; nodes wait that long
    for its samples. It records the streams it was shown."""

    stream = "compass"
    offset = LATENCY

    def __init__(self):
        self.seen = set()

    def correct(self, t, payload):
        return t - LATENCY

    def observe(self, stream, t, payload):
        self.seen.add(stream)

    def remounted(self, t, rates):
        pass

    def lag(self):
        return LATENCY

    def note(self, t_first):
        return "compass stamped 300 ms late: its timestamps corrected"


def test_a_registered_sensors_live_clock_puts_its_samples_on_the_run_clock(drive):
    """``Live.clock``: streamed, a compass stamped 0.3 s late whose clock moves its stamps back (and makes the nodes
    wait for it) gives the track of the compass on time (to 1e-9), with its note; the clock is shown the other
    streams' samples. Without the clock the late compass leaves a larger heading error."""
    s, compass = drive
    late = CompassData(compass.t + LATENCY, compass.yaw)
    live = dataclasses.replace(COMPASS_SENSOR, live=COMPASS_LIVE)
    clocks = []

    def clock(fusion):
        clocks.append(_LatencyClock())
        return clocks[-1]

    with registry.registered(live):
        on_time = _stream("ekf", s, compass)[1]
        unmoved = _stream("ekf", s, late)[1]
    with registry.registered(dataclasses.replace(live, live=dataclasses.replace(COMPASS_LIVE, clock=clock))):
        moved = _stream("ekf", s, late)[1]
    np.testing.assert_allclose(moved.trajectories["ekf"].xyyaw, on_time.trajectories["ekf"].xyyaw, rtol=0, atol=1e-9)
    assert "compass stamped 300 ms late: its timestamps corrected" in moved.notes
    assert len(clocks) == 1 and clocks[0].seen == {"wheel"}
    assert _errors(unmoved.trajectories["ekf"], s.truth)[0] > 1.5 * _errors(moved.trajectories["ekf"], s.truth)[0]


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_a_registered_sensor_streams_through_the_generic_add(drive, backend):
    """``StreamingFusion.add("compass", sample)`` dispatches through the registry (the sensor's Live intake) with
    no streaming code of its own; its state (the offset) is carried online too. A malformed sample is counted as
    gated, an unknown sensor is an error."""
    from compass_sensor import CompassSample

    s, compass = drive
    with registry.registered(OFFSET_COMPASS_SENSOR):
        bad = [(10.005, 1, "compass", CompassSample(10.005, float("nan"))), (10.006, 1, "compass", "north")]
        fusion, result = _stream(backend, s, _offset_compass(compass), bad)
        with pytest.raises(InputError, match="unknown sensor 'magnet'"):
            fusion.add("magnet", CompassSample(31.0, 0.0))
    name = "ekf" if backend == "ekf" else "gtsam_online"
    yaw, _ = _errors(result.trajectories[name], s.truth)
    # measured: 0.011 rad (EKF) and 0.011 rad (iSAM2); wheels alone 0.088, the absolute compass 0.195
    assert yaw < 0.02, (backend, yaw)
    count = result.counts[name]["compass"]
    assert count.used >= 550 and count.gated == 2, (backend, count)
    # the state at the newest node, with its σ (measured: 0.198, σ 0.0095, both backends)
    calibration = result.calibration[name]
    assert abs(calibration["compass_offset"] - OFFSET) < 0.01 and 0.003 < calibration["compass_offset_sigma"] < 0.03, \
        calibration


@pytest.mark.parametrize("backend, track", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_a_stream_reports_the_states_as_the_batch_runs_online_track_does(drive, backend, track):
    """``StreamingFusion.finish().calibration`` holds each estimated state at the newest node with its σ and what is
    derived from it, as a batch run's online track does: the same values where the two tracks are the same (the
    camera's frames the nodes of both, the wheels and the IMU's gyro)."""
    s, _ = drive
    streams = SensorStreams(visual=s.visual, wheel=s.wheel, imu=s.imu, camera_height=s.camera_height)
    batch, streamed = _batch_and_streamed(streams, backend)
    assert np.abs(streamed.trajectories[track].xyyaw - batch.trajectories[track].xyyaw).max() < 1e-9
    ours, theirs = streamed.calibration[track], batch.calibration[track]
    assert set(ours) == set(theirs) >= {"gyro_bias", "gyro_bias_sigma", "visual_scale", "camera_height",
                                        "wheel_base_factor", "wheel_base", "wheel_curvature"}, (ours, theirs)
    for key, value in theirs.items():
        assert ours[key] == pytest.approx(value, rel=1e-6, abs=1e-12), (key, ours[key], value)
    assert abs(ours["wheel_base_factor"] - 1.05) < 0.01, ours  # (the wheel base is 5 % off)


@pytest.mark.parametrize("backend, track", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_the_engine_fed_in_time_order_is_the_batch_runs_online_track_with_a_registered_sensor(drive, backend, track):
    """Camera, wheels and the offset compass, whose last reading (10 Hz) comes before the last two frames: streamed
    in time order, the track is the batch run's online track. At the end no later reading comes, so the last
    intervals read the compass's earlier readings, as the batch run's hook does (without that, measured: the last
    node 1.3 mm off). iSAM2 takes the first node's own readings (the compass's heading at it) in an update of their
    own before the second node's, as a batch run does (merged into one update, measured: the tracks 15 µm apart)."""
    s, compass = drive
    t_frames = sorted(float(v.t1) for v in s.visual)
    assert compass.t[-1] < t_frames[-2]
    streams = SensorStreams(visual=s.visual, wheel=s.wheel, camera_height=s.camera_height,
                            extra={"compass": _offset_compass(compass)})
    with registry.registered(OFFSET_COMPASS_SENSOR):
        batch, streamed = _batch_and_streamed(streams.select(["camera", "wheel", "compass"]), backend)
    a, b = streamed.trajectories[track], batch.trajectories[track]
    assert np.array_equal(a.t, b.t)
    difference = np.abs(a.xyyaw - b.xyyaw).max(axis=1)
    assert difference.max() < 1e-9, difference
    assert streamed.counts[track]["compass"].used == batch.counts[track]["compass"].used


@pytest.mark.parametrize("backend, track", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_a_value_a_sensor_finds_once_is_carried_from_node_to_node(drive, backend, track):
    """The north compass of compass_sensor.py, whose north is 1 rad off the start frame, finds that offset once from
    its first half second of readings and declares it carried (``Sensor.carry``, as the IMU's AHRS does). A batch
    run finds it over the whole grid; the engine, fed in time order, reads those readings ahead of its first
    interval, waits for them, and hands the offset from node to node: the tracks are the same, and the headings
    are the true ones. Found anew from each interval's own readings, every heading would be the initial one;
    without the readings ahead, the offset would be the first reading's alone."""
    s, compass = drive
    north = CompassData(compass.t, se2.wrap_angle(compass.yaw + 1.0))
    streams = SensorStreams(wheel=s.wheel, extra={"compass": north})
    with registry.registered(NORTH_COMPASS_SENSOR):
        batch, streamed = _batch_and_streamed(streams, backend)
    a, b = streamed.trajectories[track], batch.trajectories[track]
    assert np.array_equal(a.t, b.t)
    difference = np.abs(a.xyyaw - b.xyyaw).max(axis=1)
    assert difference.max() < 1e-9, difference
    yaw, _ = _errors(a, s.truth)
    # measured: RMS 0.040 rad for both backends (the robot turns 0.04 rad in the first half second, which the
    # offset takes in); the wheels alone 0.087, a compass whose north is the start frame's 0.011
    assert yaw < 0.05, yaw


# --------------------------------------------------------------------------- command line and run.yaml
@pytest.fixture(scope="module")
def compass_recording(tmp_path_factory):
    """A generated recording (wheels, IMU, small camera) with a ``compass0/`` folder whose headings are off by
    ``OFFSET``."""
    from fusion_vo.recording import Recording
    from fusion_vo.simulation import simulate

    tmp = tmp_path_factory.mktemp("compass")
    tiny = {"width": 80, "height": 48, "fu": 60.0, "fv": 60.0, "cu": 39.5, "cv": 23.5, "supersample": 1,
            "camera_rate": 2.0}
    rec = simulate(tmp / "rec", profile="random", seed=3, duration=20.0, **tiny)
    truth = Recording(rec).groundtruth()
    rng = np.random.default_rng(1)
    t = np.arange(truth.t[0], truth.t[-1], 0.1)
    yaw = se2.wrap_angle(np.interp(t, truth.t, np.unwrap(truth.xyyaw[:, 2])) + OFFSET + rng.normal(0, 0.02, len(t)))
    (rec / "compass0").mkdir()
    (rec / "compass0" / "data.csv").write_text(
        "#timestamp [ns],yaw [rad]\n" + "".join(f"{int(round(a * 1e9))},{b:.6f}\n" for a, b in zip(t, yaw)))
    return rec


def test_the_command_line_runs_a_sensor_an_installed_package_registers(compass_recording, tmp_path):
    """``fusion-vo run --sensors wheel,compass`` with the compass of a package that declares it in the
    ``fusion_vo.sensors`` entry point (a dist-info on the path): its section of run.yaml goes through the schema,
    it is read from its folder, fused by every backend and its offset state reported in summary.json."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    info = tmp_path / "plugins" / "compass_plugin-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: compass-plugin\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text("[fusion_vo.sensors]\ncompass = compass_sensor:register_offset_compass\n")
    (tmp_path / "run.yaml").write_text("sensors: [wheel, compass]\nfusion: {compass: {sigma: 0.03}}\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(tmp_path / "plugins"), str(Path(__file__).parent)]))
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, "-m", "fusion_vo.cli.main", "run", str(compass_recording), "--out", str(out),
                           "-c", str(tmp_path / "run.yaml"), "--no-evaluate"], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    summary = json.loads((out / "summary.json").read_text())["fusion"]
    for name in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online"):
        assert summary["counts"][name]["compass"]["used"] >= 190, (name, summary["counts"][name])
        # measured: 0.2015-0.2018 against the true 0.2
        assert abs(summary["calibration"][name]["compass_offset"] - OFFSET) < 0.01, (name, summary["calibration"])
    import yaml

    assert yaml.safe_load((out / "run.yaml").read_text())["fusion"]["compass"] == {"sigma": 0.03}
    # without the plugin on the path the name is unknown: one line, exit status 2
    env["PYTHONPATH"] = str(Path(__file__).parent)
    done = subprocess.run([sys.executable, "-m", "fusion_vo.cli.main", "run", str(compass_recording), "--out",
                           str(tmp_path / "out2"), "--sensors", "wheel,compass"], env=env, capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert "got 'compass'" in done.stderr and "'camera', 'wheel'" in done.stderr, done.stderr
    assert not (tmp_path / "out2").exists()


@pytest.mark.parametrize("text, message", [
    ("sensors: [wheel, magnet]\n", "sensors[1]: expected one of 'camera', 'wheel', 'imu', 'odom', 'range', 'gps' or "
                                   "'compass', got 'magnet'"),
    ("fusion: {compass: {sigma: 0}}\n", "fusion.compass: sigma must be positive, not 0"),
    ("fusion: {compass: {sigma: -0.1}}\n", "fusion.compass: sigma must be positive, not -0.1"),
    ("fusion: {compass: {sigma: .nan}}\n", "fusion.compass: sigma must be a finite number, not nan"),
    ("fusion: {compass: {sigma: 1.0e+300}}\n", "fusion.compass: sigma must be at most 1000, not 1e+300"),
    ("fusion: {compass: {sigam: 0.1}}\n", "fusion.compass.sigam: unknown key (known: sigma)"),
    ("fusion: {states: {compass_offset: {sigma: 0}}}\n", "fusion.states.compass_offset: sigma must be positive, not 0"),
    ("fusion: {states: {compass_offset: {sigma: -1}}}\n", "fusion.states.compass_offset: sigma must be positive, "
                                                           "not -1"),
    ("fusion: {states: {compass_offset: {sigma: .nan}}}\n", "fusion.states.compass_offset: sigma must be a finite "
                                                             "number, not nan"),
    ("fusion: {states: {compass_offset: {random_walk: -0.1}}}\n", "fusion.states.compass_offset: random_walk must "
                                                                   "be at least 0, not -0.1"),
    ("fusion: {states: {compass_ofset: {sigma: 1}}}\n", "fusion.states.compass_ofset: unknown key (known: "
                                                        "wheel_curvature, compass_offset)"),
])
def test_run_yaml_errors_about_a_registered_sensor_name_the_key(tmp_path, text, message):
    from fusion_vo.config import load_config

    path = tmp_path / "run.yaml"
    path.write_text(text)
    with registry.registered(OFFSET_COMPASS_SENSOR):
        with pytest.raises(InputError) as err:
            load_config(path)
        assert str(err.value) == f"{path}: {message}"
        ok = load_config(_write(tmp_path / "ok.yaml", "sensors: wheel,compass\nfusion: {compass: {sigma: 0.1}}\n"))
        assert ok.sensors == ["wheel", "compass"] and ok.fusion.section("compass").sigma == 0.1


def test_the_command_line_rejects_an_unknown_sensor_in_one_line(compass_recording, tmp_path, capsys):
    from fusion_vo.cli.main import main

    with registry.registered(OFFSET_COMPASS_SENSOR):
        status = main(["run", str(compass_recording), "--out", str(tmp_path / "out"), "--sensors", "wheel,magnet"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert "got 'magnet'" in err and "'gps' or 'compass'" in err, err
    assert not (tmp_path / "out").exists()


def _write(path, text):
    path.write_text(text)
    return path
