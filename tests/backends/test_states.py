"""The run's scalar states: one table, declared by the sensors, that the EKF and the factor graph both consume."""

import dataclasses

import gtsam
import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends.ekf import DIM, filter_for
from fusion_vo.backends.graph_builder import GraphBuilder
from fusion_vo.backends.states import live_context, run_states
from fusion_vo.backends.timeline import build_intervals
from fusion_vo.measurements import TwistData
from fusion_vo.sensors import registry
from fusion_vo.sensors.registry import Sensor, State
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

#: the scale priors a live run's files give (``StateContext.facts``)
PRIORS = {"visual_scale_sigma": 0.02, "wheel_scale_sigma": 0.01}



@pytest.fixture(scope="module")
def drive():
    return synthetic_streams(SyntheticOptions(duration=4.0), seed=3)


def _grid(drive, config=None, **which):
    streams = SensorStreams(camera_height=drive.camera_height, **which)
    config = config or FusionConfig()
    return build_intervals(streams, config), config


def test_wheels_and_gyro_estimate_the_wheel_base_and_hold_the_camera_scale(drive):
    iv, config = _grid(drive, wheel=drive.wheel, imu=drive.imu)
    table = {st.name: st for st in iv.states}
    assert [n for n in table if n in ("visual_scale", "wheel_base_factor", "wheel_scale", "gyro_bias")] == [
        "visual_scale", "wheel_base_factor", "wheel_scale", "gyro_bias"]  # the registry's order
    assert table["wheel_base_factor"].estimated and table["gyro_bias"].estimated
    # no camera: its scale is held, and so the wheels' distance scale (only their ratio would be measured)
    assert not table["visual_scale"].estimated and not table["wheel_scale"].estimated
    assert table["wheel_base_factor"].sigma == config.wheel_base_sigma
    assert table["gyro_bias"].random_walk == config.imu.gyro_random_walk
    # the EKF carries every state of the table, a held one frozen; the graph has variables for the estimated ones
    ekf = filter_for(iv, config)
    assert ekf.dim == DIM + len(iv.states)
    for name, st in table.items():
        var = ekf.P[ekf.columns[name], ekf.columns[name]][0, 0]
        assert var == pytest.approx(st.sigma**2 if st.estimated else 1e-12)
    builder = GraphBuilder(iv, config)
    assert {st.name for st in builder.variables} == {n for n, st in table.items() if st.estimated}
    assert builder.state_variable("visual_scale", 0) is None and builder.state_initial("visual_scale") == 1.0
    assert builder.state_variable("gyro_bias", 0) is not None


def test_self_calibration_off_holds_the_three_calibrations(drive):
    config = FusionConfig.from_dict({"self_calibration": False})
    iv, _ = _grid(drive, config, visual=drive.visual, wheel=drive.wheel, imu=drive.imu)
    held = {st.name for st in iv.states if not st.estimated}
    assert {"visual_scale", "wheel_base_factor", "wheel_scale"} <= held
    on, _ = _grid(drive, visual=drive.visual, wheel=drive.wheel, imu=drive.imu)
    assert not {"visual_scale", "wheel_base_factor", "wheel_scale"} & {st.name for st in on.states if not st.estimated}


def test_a_live_run_decides_from_the_sensors_it_fuses():
    config = FusionConfig()
    table = {st.name: st for st in run_states(live_context(config, ["camera", "odom", "imu"], PRIORS))}
    assert table["visual_scale"].estimated and table["wheel_base_factor"].estimated and table["wheel_scale"].estimated
    assert table["visual_scale"].sigma == 0.02 and table["wheel_scale"].sigma == 0.01
    assert table["wheel_base_factor"].sigma == config.odom_base_sigma  # an odometry twist's prior
    alone = {st.name: st for st in run_states(live_context(config, ["odom"], PRIORS))}
    assert not any(st.estimated for st in alone.values())
    ticks = {st.name: st for st in run_states(live_context(config, ["camera", "wheel", "odom", "imu"], PRIORS))}
    assert ticks["wheel_base_factor"].sigma == config.wheel_base_sigma != config.odom_base_sigma


def test_an_odometry_twist_stands_in_for_the_wheels_on_a_grid_as_in_a_live_run(drive):
    """The wheels' base-factor prior is the odometry twist's where only the twist is fused, the ticks' where they
    are there, on a whole recording's grid as in a live run."""
    config = FusionConfig()
    twist = TwistData(drive.wheel.t, np.full(len(drive.wheel.t), 0.5), np.zeros(len(drive.wheel.t)),
                      np.zeros(len(drive.wheel.t)))
    for which, sigma in (({"odom": twist}, config.odom_base_sigma),
                         ({"odom": twist, "wheel": drive.wheel}, config.wheel_base_sigma)):
        iv, _ = _grid(drive, config, visual=drive.visual, imu=drive.imu, **which)
        assert {st.name: st for st in iv.states}["wheel_base_factor"].sigma == sigma, which


def _observed(state: State, context) -> State:
    """A state whose rule estimates it where the run can tell it apart (``State.needs``), as ``k_v``'s and ``k_b``'s
    do."""
    return dataclasses.replace(state, estimated=context.observable[state.name])


def test_a_registered_state_needing_another_sensors_heading_is_estimated_only_beside_one(drive):
    """A beacon whose bearing scale needs a heading from another sensor (``State(needs="heading")``): estimated
    beside the IMU (its gyro and AHRS declare ``absolute_heading``), held alone (its own bearings, which it
    declares a heading, do not count) or beside the wheels, which measure no heading; live from the sensors fused,
    and on a recording's node grid from the measurements there (the beacon measured on every interval)."""
    beacon = Sensor(name="beacon", on_grid=lambda iv: len(iv.t) > 1, absolute_heading=True,
                    states=(State("beacon_scale", initial=1.0, rule=_observed, needs="heading"),))
    config = FusionConfig()

    def live(*sensors):
        return {st.name: st.estimated for st in run_states(live_context(config, list(sensors), PRIORS))}

    with registry.registered(beacon):
        assert live("beacon", "imu")["beacon_scale"] and not live("beacon")["beacon_scale"]
        assert not live("beacon", "wheel")["beacon_scale"] and not live("imu")["beacon_scale"]
        assert live("beacon", "wheel")["wheel_base_factor"]  # its bearings are a heading beside the wheels
        # the built-in ones by the same rule: the camera's scale beside a distance, the wheel base beside a heading
        # measured by a sensor that is not the wheels or the odometry twist standing in for them
        both = live("camera", "wheel")
        assert both["visual_scale"] and both["wheel_base_factor"]
        assert not live("camera", "imu")["visual_scale"] and not live("wheel", "odom")["wheel_base_factor"]
        assert live("odom", "imu")["wheel_base_factor"] and not live("odom", "imu")["visual_scale"]
        on_grid, _ = _grid(drive, wheel=drive.wheel, imu=drive.imu)
        assert {s.name: s.estimated for s in on_grid.states}["beacon_scale"]
        wheels_only, _ = _grid(drive, wheel=drive.wheel)
        assert not {s.name: s.estimated for s in wheels_only.states}["beacon_scale"]
    with pytest.raises(ValueError, match="needs must be"):
        State("bad", needs="speed")


def test_a_registered_distance_scale_lets_the_wheels_distance_scale_be_estimated():
    """The wheels' distance scale ``k_r`` is estimated beside another sensor's distance scale (a state that needs a
    distance), as beside the camera's: a registered lidar odometer whose scale needs the wheels' distance, with the
    IMU's heading for the wheel base. Without the lidar, or with it held by self-calibration off, ``k_r`` is held.
    Fails if ``k_r``'s rule names the camera's scale."""
    lidar = Sensor(name="lidar", on_grid=lambda iv: len(iv.t) > 1,
                   states=(State("lidar_scale", initial=1.0, rule=_observed, needs="distance"),))
    config = FusionConfig()

    def live(*sensors, config=config):
        return {st.name: st.estimated for st in run_states(live_context(config, list(sensors), PRIORS))}

    with registry.registered(lidar):
        fused = live("lidar", "wheel", "imu")
        assert fused["lidar_scale"] and fused["wheel_base_factor"] and fused["wheel_scale"]
        assert not fused["visual_scale"]
        assert not live("wheel", "imu")["wheel_scale"]
        assert not live("lidar", "wheel")["wheel_scale"]  # no heading: the wheel base is held, and so k_r
        assert not live("lidar", "wheel", "imu", config=FusionConfig.from_dict({"self_calibration": False}))[
            "wheel_scale"]


def _trim(state: State, context) -> State:
    """A state whose rule estimates it only beside the wheels (as a built-in calibration's does)."""
    return dataclasses.replace(state, sigma=0.3, estimated="wheel" in context.used)


TRIM = Sensor(name="trim", states=(State("trim_offset", initial=0.5, rule=_trim),))


def test_a_registered_state_with_a_rule_is_carried_like_the_built_in_ones(drive):
    with registry.registered(TRIM):
        iv, config = _grid(drive, wheel=drive.wheel, imu=drive.imu)
        st = {s.name: s for s in iv.states}["trim_offset"]  # carried although the sensor has no data
        assert st.estimated and st.sigma == 0.3
        ekf = filter_for(iv, config)
        col = ekf.columns["trim_offset"]
        assert ekf.x[col][0] == 0.5 and ekf.P[col, col][0, 0] == pytest.approx(0.09)
        assert "trim_offset" in {s.name for s in GraphBuilder(iv, config).variables}
        held, _ = _grid(drive, imu=drive.imu)
        st = {s.name: s for s in held.states}["trim_offset"]
        assert not st.estimated and GraphBuilder(held, config).state_initial("trim_offset") == 0.5
        # its prior is its rule's: not a key of fusion.states
        assert "trim_offset" not in {s.name for s in registry.configurable_states()}


def test_a_registered_distance_sensor_lets_the_camera_scale_be_estimated(drive):
    """The visual scale is estimated where a distance is measured besides the camera's, whichever sensor measures
    it: a registered one declaring ``absolute_distance`` (a measuring tape beside the camera and the IMU) counts as
    the wheels or the range finder do, in a batch run (on the node grid, where it says it measures) and live."""
    def scale(states):
        return {st.name: st for st in states}["visual_scale"].estimated

    config = FusionConfig()
    iv, _ = _grid(drive, visual=drive.visual, imu=drive.imu)
    assert not scale(iv.states)  # the camera alone measures no distance of its own
    assert not scale(run_states(live_context(config, ["camera", "imu"], PRIORS)))
    with registry.registered(Sensor(name="tape", absolute_distance=lambda iv: len(iv.t) > 1)):
        iv, _ = _grid(drive, visual=drive.visual, imu=drive.imu)
        assert scale(iv.states)
        assert scale(run_states(live_context(config, ["camera", "imu", "tape"], PRIORS)))
        assert not scale(run_states(live_context(config, ["camera", "imu"], PRIORS)))
    with registry.registered(Sensor(name="tape", absolute_distance=lambda iv: False)):
        iv, _ = _grid(drive, visual=drive.visual, imu=drive.imu)
        assert not scale(iv.states)  # it says it measured none on this grid


@pytest.mark.parametrize("symbol", ["x", "b", "B", "ab"])
def test_a_states_graph_letter_is_its_own(symbol):
    """x is the poses' letter and b the gyro bias's: a sensor's state may name neither (nor two letters)."""
    with pytest.raises(ValueError, match="symbol must be a lower-case letter"):
        registry.register(Sensor(name="lettered", states=(State("lettered_offset", symbol=symbol),)))
    assert "lettered" not in registry.names()


def test_a_free_letter_is_not_one_another_state_names(drive):
    """The curvature bias takes the first free letter, ``a``, unless a registered state names ``a`` itself."""
    named = Sensor(name="named", states=(State("named_offset", symbol="a", rule=lambda st, ctx: st),))
    config = FusionConfig.from_dict({"wheel": {"estimate_curvature": True}})
    iv, _ = _grid(drive, config, wheel=drive.wheel, imu=drive.imu)
    assert chr(gtsam.Symbol(GraphBuilder(iv, config).state_key("wheel_curvature", 0)).chr()) == "a"
    with registry.registered(named):
        iv, _ = _grid(drive, config, wheel=drive.wheel, imu=drive.imu)
        builder = GraphBuilder(iv, config)
        letters = {name: chr(gtsam.Symbol(builder.state_key(name, 0)).chr())
                   for name in ("wheel_curvature", "named_offset")}
        assert letters == {"wheel_curvature": "c", "named_offset": "a"}


def test_every_backend_reports_the_same_calibration_keys(drive):
    streams = SensorStreams(visual=drive.visual, wheel=drive.wheel, imu=drive.imu, camera_height=drive.camera_height)
    result = fuse(streams, "all")
    keys = {name: set(cal) for name, cal in result.calibration.items()}
    assert keys["ekf"] >= {"visual_scale", "visual_scale_sigma", "camera_height", "wheel_base_factor", "wheel_base",
                           "wheel_scale", "gyro_bias", "gyro_bias_sigma"}
    assert keys["gtsam"] == keys["ekf"] == keys["ekf_smoothed"] == keys["gtsam_online"], keys
    for name in ("gtsam", "gtsam_online"):
        cal = result.calibration[name]
        assert np.isfinite(cal["gyro_bias_sigma"]) and cal["gyro_bias_sigma"] < FusionConfig().imu.gyro_bias_sigma
