"""Configuration of the fusion backends: :class:`FusionConfig` and its sections.

Every option is a field with its default, range, unit and description (:mod:`fusion_vo.config`); a sensor's
noise model is defined in its sensor's module and is a section here (``wheel``, ``imu`` ...). A sensor registered
outside the library (:mod:`fusion_vo.sensors.registry`) adds its own section (``fusion: {compass: {sigma:
0.02}}``) and the priors of the states it adds (``fusion: {states: {NAME: {initial, sigma, random_walk}}}``),
checked the same way. A bad value raises :class:`~fusion_vo.config.base.ConfigError` (a ``ValueError``) naming
the key; read from a file (:func:`fusion_vo.config.files.validate`), an error names the file and the key path.
"""

from __future__ import annotations

import math
import numbers
from typing import Annotated, Any, Literal

from pydantic import Field, PrivateAttr, ValidationError, field_validator, model_serializer, model_validator
from pydantic_core import PydanticCustomError

from fusion_vo.config.base import (NUMBER, Count, Float, Fraction, Int, NonNegative, Positive, Section, Sigma,
                                   Walk)
from fusion_vo.consistency.config import ConsistencyConfig
from fusion_vo.measurements import MAX_CAMERA_HEIGHT_M, MAX_POSITION_M
from fusion_vo.robust import ROBUST_KERNELS
from fusion_vo.sensors import registry
from fusion_vo.sensors.gps import GpsNoise
from fusion_vo.sensors.imu import ImuNoise
from fusion_vo.sensors.range import RangeNoise
from fusion_vo.sensors.registry import StatePrior
from fusion_vo.sensors.visual_noise import VisualNoiseConfig
from fusion_vo.sensors.wheel import WheelNoise, odom_twist_noise

#: ``initial_pose``: x and y [m], within :data:`~fusion_vo.measurements.MAX_POSITION_M`
_Coordinate = Annotated[float, Field(ge=-MAX_POSITION_M, le=MAX_POSITION_M)]
#: ``initial_pose``: the yaw [rad], within a turn either way
_Yaw = Annotated[float, Field(ge=-2 * math.pi, le=2 * math.pi)]


class EkfConfig(Section):
    """EKF process noise and options."""

    accel_sigma: Sigma = Field(0.5, description="Forward acceleration noise of the constant-twist model [m/s²·√s].")
    lateral_accel_sigma: Sigma = Field(0.1, description="Sideways acceleration noise [m/s²·√s] (a wheeled robot "
                                                        "barely slides).")
    yaw_accel_sigma: Sigma = Field(1.0, description="Angular acceleration noise [rad/s²·√s].")
    scale_random_walk: Walk = Field(1e-4, description=(
        "Random walk of the wheels' radius factor and their wheel-base factor [1/√s], in both backends (tyres that "
        "warm up or wear)."))
    visual_scale_random_walk: Walk = Field(1e-5, description=(
        "Random walk of the visual scale (the camera height) [1/√s], in both backends (a rigidly mounted camera "
        "keeps its height, and a range finder measures one that changes). Nothing but the height prior holds the "
        "common scale of camera and wheels, and a walk as large as the wheels' lets their slip, shared between "
        "the two scale factors, move the camera's scale (docs/decisions/0016-visual-scale-random-walk.md, "
        "docs/decisions/0036-visual-scale-model.md). Not 0: the graph ties each calibration segment's visual scale "
        "to the previous one with this walk, and ties of 1e-6 are too stiff for GTSAM's elimination (an "
        "indeterminate system on the drive of ``tests/backends/test_chain.py``)."))
    smoother: bool = Field(True, description="Run the Rauch–Tung–Striebel pass.")


class GraphConfig(Section):
    """Factor-graph options."""

    robust: Literal[ROBUST_KERNELS] = Field("huber", description=(
        "M-estimator on the visual, wheel, gyro and heading factors: ``huber``, ``cauchy`` or ``none``."))
    robust_k: Positive = Field(3.2905, description=(
        "Kernel width for a factor of one row, in standard deviations; a factor of ``m`` rows gets the width with "
        "the same tail probability on its whitened distance, ``sqrt(chi2.ppf(chi2.cdf(k², 1), m))`` "
        "(:func:`fusion_vo.backends.graph_builder.kernel_width`). 3.2905: where the EKF's default gate "
        "(``gate_probability`` 0.999) starts, so that a measurement the filter takes at full weight keeps its full "
        "weight in the graph (1.345 is Huber's classic for one row, 2.3849 Cauchy's)."))
    keyframe_every: Count = Field(1, description="Keep one pose variable every this many nodes (1: every camera "
                                                 "frame).")
    batch: bool = Field(True, description="Batch Levenberg–Marquardt smoothing over the whole recording (``gtsam``).")
    online: bool = Field(True, description="Incremental iSAM2, one update per node (``gtsam_online``).")
    fixed_lag: NonNegative = Field(0.0, description=(
        "Lag [s] of an incremental fixed-lag smoother (``gtsam_fixed_lag``); 0 disables it."))
    max_iterations: Int = Field(20, ge=1, le=1000, description=(
        "Levenberg–Marquardt iterations (at most 1000: each one linearises and solves the whole graph)."))
    relative_tolerance: NonNegative = Field(1e-3, description=(
        "Stop when an iteration decreases the cost by less than this fraction (later iterations move the poses by "
        "far less than their uncertainty)."))
    marginals: bool = Field(True, description="Compute marginal pose covariances of the batch solution.")
    calibration_interval: Positive = Field(1.0, description=(
        "Length [s] of the segments that share one gyro-bias and calibration variable."))
    residuals: bool = Field(False, description=(
        "Compute each sensor's NIS at the batch and iSAM2 solutions (``FusionResult.residuals``, "
        ":mod:`fusion_vo.backends.residuals`; a consistency check, costs joint marginals)."))
    reweight_passes: Int = Field(2, ge=0, le=10, description=(
        "iSAM2 (and the streaming fusion's) linearises a node's sensor-model factors again at its updated "
        "estimate, at most this many times, when a robust weight there differs from the one at the prediction "
        "(:func:`fusion_vo.backends.isam.update_reweighted`; 0: the weights at the prediction; at most 10: each "
        "pass is one more update of every node)."))


class FusionConfig(Section):
    """Everything the backends need besides the measurements.

    Besides its fields it holds the sections of the sensors registered outside the library
    (:attr:`sensors`, read from ``fusion: {NAME: ...}``; :meth:`section`) and the priors of the states they add
    (:attr:`states`, read from ``fusion: {states: {NAME: ...}}``); both are part of :meth:`to_dict`, at the keys
    they are read from.
    """

    step_hz: Float = Field(20.0, gt=0, le=1000, description=(
        "Node rate [Hz] where no camera frame provides the nodes (at most 1000: every node is a state of both "
        "backends, so the work grows with the rate)."))
    max_gap: Positive = Field(0.25, description="A gap between two samples of a stream longer than this [s] is not "
                                                "bridged.")
    reorder_window: NonNegative = Field(0.3, description=(
        "Streaming use: samples are held this long [s] to put out-of-order arrivals back in order; anything "
        "arriving later is counted as late."))
    gate_probability: Float = Field(0.999, gt=0, le=1, description=(
        "Mahalanobis gate: a measurement whose squared Mahalanobis distance exceeds the chi-square quantile of this "
        "probability (degrees of freedom = measurement size) is rejected."))
    self_calibration: bool = Field(True, description="Estimate the visual scale (camera height) and the wheel base.")
    visual_scale_sigma: Sigma = Field(0.002, description=(
        "Prior standard deviation of the visual scale ``k_v = h_configured / h_true`` around 1 (0.002: the camera "
        "height is a mounting dimension, measured once, that no tyre, load, slip or floor changes). A "
        "``height_sigma`` [m] in ``cam0/sensor.yaml`` replaces it by ``height_sigma / height``. Camera and wheels "
        "measure only the ratio ``k_v / k_r``; with these two priors a disagreement ``ρ`` of their distances moves "
        "the camera's scale by ``ρ σ_v² / (σ_v² + σ_r²)``: 1 % of it at the defaults (0.002 and 0.02), so that the "
        "wheels' radius error does not become the camera's scale (docs/decisions/0036-visual-scale-model.md)."))
    wheel_base_sigma: Sigma = Field(0.05, description="Prior standard deviation of the wheel-base factor around 1.")
    wheel_scale_sigma: Sigma = Field(0.02, description=(
        "Prior standard deviation of the wheels' distance scale ``k_r = r_configured / r_true`` (their common "
        "radius error) around 1 (0.02: a tyre's effective rolling radius differs from its nominal one by a few per "
        "cent with pressure, load and floor); a ``radius_sigma`` [m] in ``wheel0/sensor.yaml`` replaces it by "
        "``radius_sigma / radius``. It also sets the prior of the wheels' curvature bias when ``radius_sigma`` is "
        "not stated (:class:`~fusion_vo.sensors.wheel.CurvedWheelModel`)."))
    visual_frame_error: Float = Field(0.0, ge=0, lt=1, description=(
        "Fraction of each visual increment's stated variance that is the error of its two frames' own measurements "
        "rather than of the increment (0: independent increments). A frontend that measures each frame against the "
        "previous one puts that frame's error into both increments it belongs to, with opposite signs, so "
        "consecutive increments' errors correlate at ``-visual_frame_error / 2``. Both backends then model the "
        "increment between frames ``a`` and ``b`` as ``z = motion + e_b - e_a + w``, each frame's error ``e`` with "
        "covariance ``visual_frame_error / 2`` times the stated one and ``w`` with ``1 - visual_frame_error`` times "
        "it (:mod:`fusion_vo.sensors.visual`)."))
    visual_noise: VisualNoiseConfig = Field(default_factory=VisualNoiseConfig, description=(
        "Estimate the camera's heading noise (a scale of its stated variance, and ``visual_frame_error``) from the "
        "camera's and the gyro's heading changes over the recording, without ground truth "
        "(:mod:`fusion_vo.sensors.visual_noise`; ``estimate``, off by default; batch runs only)."))
    odom_base_sigma: Sigma = Field(0.3, description=(
        "Prior standard deviation of the wheel-base factor when the wheels are an odometry twist (the effective "
        "track width of a skid-steered base is known only roughly)."))
    sync_odometry: bool = Field(True, description=(
        "Estimate the delay of an odometry twist behind the gyro from their yaw rates "
        "(:func:`~fusion_vo.sensors.sync.odometry_delay`) and move the twist's timestamps back by it (a "
        "controller's odometry is often stamped when published, late): over the whole recording in batch use, over "
        "the samples seen so far in streaming use (:class:`~fusion_vo.sensors.sync.TwistDelay`)."))
    max_odom_delay: Float = Field(1.0, ge=0, le=10, description=(
        "Largest delay [s] searched (at most 10: the search's work grows with it times the recording's length)."))
    monitor: bool = Field(True, description=(
        "Check the heading sources (wheel yaw rate, gyro, AHRS, camera) and the speeds (wheels, camera) against "
        "each other over windows and drop the component that contradicts the others there "
        "(:mod:`fusion_vo.backends.monitor`)."))
    monitor_window: Positive = Field(2.0, description="Window length [s] of that check.")
    monitor_probability: Float = Field(0.9999, gt=0, lt=1, description=(
        "A window whose NIS exceeds the chi-square quantile of this probability (1 degree of freedom) is "
        "inconsistent (0.9999: NIS 15.1)."))
    monitor_bias_sigma: Sigma = Field(0.001, description=(
        "Uncertainty [rad/s] of the gyro bias taken from the standstills (or the AHRS) in that check (a median over "
        "many samples at rest)."))
    monitor_scale_sigma: Sigma = Field(0.02, description=(
        "How far [relative] the ratio of the wheels' to the camera's distance may wander from its median over the "
        "recording before a window counts as a disagreement of speeds."))
    monitor_whole_fraction: Fraction = Field(0.5, description=(
        "A component inconsistent over more than this fraction of the time it was checked is dropped for the whole "
        "recording."))
    consistency: ConsistencyConfig = Field(default_factory=ConsistencyConfig, description=(
        "Before fusion, each stream's stated configuration is checked against the data (the IMU's mounting, the "
        "encoders' signs, an odometry twist's sign and frame, the clocks, the camera's and the wheels' scales) and "
        "corrected, left out or left as stated, with a sentence naming the file and key "
        "(:mod:`fusion_vo.consistency`)."))
    camera_height: Annotated[float, Field(gt=0, le=MAX_CAMERA_HEIGHT_M), NUMBER] | None = Field(None, description=(
        "Configured camera height [m] the visual increments were computed with; needed by the range finder (null: "
        "taken from the camera's ``T_BS`` by the caller)."))
    initial_pose: tuple[_Coordinate, _Coordinate, _Yaw] = Field((0.0, 0.0, 0.0), description=(
        "``(x, y, yaw)`` of the first node [m, m, rad]: x and y within 1e7 m, the yaw within a turn either way."))
    initial_velocity_sigma: Sigma = Field(0.5, description="Prior standard deviation of the initial speed [m/s].")
    wheel: WheelNoise = Field(default_factory=WheelNoise, description="Noise model of encoder ticks.")
    odom: WheelNoise = Field(default_factory=odom_twist_noise, description=(
        "Noise model of an odometry twist (:func:`~fusion_vo.sensors.wheel.odom_twist_noise`)."))
    imu: ImuNoise = Field(default_factory=ImuNoise, description="Gyro noise, bias and gating.")
    range: RangeNoise = Field(default_factory=RangeNoise, description="Range-finder noise and gating.")
    gps: GpsNoise = Field(default_factory=GpsNoise, description=(
        "Gate and robust kernel of GPS fixes (:class:`~fusion_vo.sensors.gps.GpsNoise`); the fixes carry their own "
        "covariance."))
    gps_reacquire: NonNegative = Field(5.0, description=(
        "After every fix of this many seconds [s] has failed the gate, the estimate rather than the fixes is taken "
        "to be wrong (a drift during an outage, a bad start): the next fix is applied anyway, the EKF first "
        "widening its position covariance by the squared innovation (the recovery of PX4's EKF2 after GPS "
        "rejection). A multipath jump lasting longer is then followed."))
    ekf: EkfConfig = Field(default_factory=EkfConfig, description="EKF options.")
    graph: GraphConfig = Field(default_factory=GraphConfig, description=(
        "Factor-graph options (``gtsam``, ``gtsam_online``, ``gtsam_fixed_lag``)."))

    _sensors: dict[str, Section] = PrivateAttr(default_factory=dict)
    _states: dict[str, StatePrior] = PrivateAttr(default_factory=dict)

    @field_validator("initial_pose", mode="before")
    @classmethod
    def _three_numbers(cls, value: Any) -> Any:
        """Three finite numbers (a NaN one made every pose NaN); a numpy array is fine."""
        try:
            values = tuple(value)
        except TypeError:
            values = None
        if values is None or len(values) != 3 or not all(
                not isinstance(v, bool) and isinstance(v, numbers.Real) and math.isfinite(v) for v in values):
            shown = repr(list(value) if isinstance(value, tuple) else value)
            shown = shown if len(shown) <= 60 else shown[:57] + "..."
            raise ValueError(f"must be three finite numbers (x, y, yaw), not {shown}")
        return tuple(float(v) for v in values)

    @model_validator(mode="wrap")
    @classmethod
    def _registered(cls, data: Any, handler):
        """The sections and state priors of the registered sensors, taken out of the mapping before its own
        fields are checked (module docstring)."""
        if not isinstance(data, dict):
            return handler(data)
        data = dict(data)
        # the instances of a kind that the configuration names (``odom1``, or a state ``imu1_gyro_bias``)
        states_given = data.get("states") if isinstance(data.get("states"), dict) else {}
        registry.ensure([k for k in data if isinstance(k, str)] +
                        [k.split("_")[0] for k in states_given if isinstance(k, str)])
        errors: list = []
        sensors: dict[str, Section] = {}
        own = cls.model_fields
        for sensor in registry.sensors():
            if sensor.config is None or sensor.config[0] in own:
                continue
            if registry.is_instance(sensor.name) and sensor.config[0] not in data:
                continue  # an instance's defaults come from section() when it is used
            name, model = sensor.config
            value = data.pop(name, None)
            try:
                sensors[name] = value if isinstance(value, model) else model.model_validate(value or {})
            except ValidationError as exc:
                errors += _moved(exc, (name,), model)
        states = _state_priors(data.pop("states", None), errors)
        if errors:
            raise ValidationError.from_exception_data(cls.__name__, errors)
        config = handler(data)
        config._sensors = sensors
        config._states = states
        return config

    @model_serializer(mode="wrap")
    def _with_registered(self, handler, info) -> dict:
        out = handler(self)
        for name, section in self._sensors.items():
            out[name] = section.model_dump(mode=info.mode)
        if self._states:
            out["states"] = {name: prior.model_dump(mode=info.mode) for name, prior in self._states.items()}
        return out

    @property
    def sensors(self) -> dict[str, Section]:
        """The sections of the sensors registered outside the library (their defaults when not configured), by
        section name."""
        return self._sensors

    @property
    def states(self) -> dict[str, StatePrior]:
        """The prior and random walk of every state the registered sensors add, by state name (as each sensor
        registers it unless configured)."""
        return self._states

    def wheel_model(self, twist: bool) -> tuple[WheelNoise, float]:
        """Noise model and wheel-base prior sigma of encoder ticks (``twist=False``) or an odometry twist."""
        return (self.odom, self.odom_base_sigma) if twist else (self.wheel, self.wheel_base_sigma)

    def section(self, name: str) -> Section:
        """The configuration section ``name``: a field (``imu``, ``gps`` ...) or a registered sensor's section
        (:attr:`sensors`; the defaults of a sensor registered after this configuration was made)."""
        if name in type(self).model_fields:
            return getattr(self, name)
        if name not in self._sensors:
            for sensor in registry.sensors():
                if sensor.config is not None and sensor.config[0] == name:
                    self._sensors[name] = sensor.config[1]()
                    break
            else:
                raise KeyError(name)
        return self._sensors[name]


def _moved(exc: ValidationError, prefix: tuple, model: type[Section]) -> list[dict]:
    """The errors of ``exc`` (validating ``model``) at the key path ``prefix`` + their own, as
    :meth:`~pydantic_core.ValidationError.from_exception_data` takes them (an error of a type pydantic does not
    know, a custom one, keeps its message; an unknown key lists the keys ``model`` knows there)."""
    out = []
    for error in exc.errors():
        if error["type"] == "extra_forbidden":
            known = _keys_at(model, tuple(error["loc"][:-1]))
            out.append({"type": PydanticCustomError("unknown_key", "unknown key (known: {known})",
                                                    {"known": ", ".join(known)}),
                        "loc": prefix + tuple(error["loc"]), "input": error.get("input")})
            continue
        entry = {"type": error["type"], "loc": prefix + tuple(error["loc"]), "input": error.get("input")}
        if "ctx" in error:
            entry["ctx"] = error["ctx"]
        try:
            ValidationError.from_exception_data("check", [entry])
        except (KeyError, TypeError, ValueError):
            entry = {"type": PydanticCustomError(error["type"], error["msg"]), "loc": entry["loc"],
                     "input": entry["input"]}
        out.append(entry)
    return out


def _keys_at(model: type[Section], loc: tuple) -> list[str]:
    """The keys of the section of ``model`` at the key path ``loc``."""
    for part in loc:
        model = model.model_fields[part].annotation
    return list(model.model_fields)


def _state_priors(data: Any, errors: list) -> dict[str, StatePrior]:
    """``fusion: {states: ...}``: each registered state's :class:`~fusion_vo.sensors.registry.StatePrior`, its
    defaults the registered ones; problems are appended to ``errors``."""
    data = {} if data is None else data
    given = data if isinstance(data, dict) else {}
    # an instance's states only when configured (its registered prior applies otherwise); a state with a rule
    # (the built-in calibrations) is configured in its sensor's section
    known = {state.name: state for s in registry.sensors() for state in s.states
             if state.configurable and (not registry.is_instance(s.name) or state.name in given)}
    if not isinstance(data, dict):
        errors.append({"type": "dict_type", "loc": ("states",), "input": data})
        return {}
    for name in data:
        if name not in known:
            listed = f"known: {', '.join(known)}" if known else "no registered sensor adds a state"
            errors.append({"type": PydanticCustomError("unknown_state", "unknown key ({listed})", {"listed": listed}),
                           "loc": ("states", name), "input": data[name]})
    out = {}
    for name, state in known.items():
        given = data.get(name)
        try:
            out[name] = given if isinstance(given, StatePrior) else StatePrior.model_validate(
                {**state.prior().model_dump(), **(given or {})} if isinstance(given, dict) or given is None else given)
        except ValidationError as exc:
            errors += _moved(exc, ("states", name), StatePrior)
    return out
