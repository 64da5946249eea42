"""Configuration of the fusion backends (dataclasses with documented defaults).

:meth:`FusionConfig.from_dict` builds a configuration from a (YAML) mapping through the one configuration
schema (:func:`fusion_vo.schema.build`) and raises :class:`~fusion_vo.errors.InputError` naming the file,
the key path and the expected type for unknown keys or values of the wrong type, so that a typo in a
configuration file is an error rather than a silently ignored setting.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass, field

from fusion_vo.consistency.config import ConsistencyConfig
from fusion_vo.errors import InputError
from fusion_vo.measurements import MAX_CAMERA_HEIGHT_M, MAX_POSITION_M
from fusion_vo.schema import AT_LEAST_1, FRACTION, POSITIVE, Range
from fusion_vo.sensors.gps import GpsNoise
from fusion_vo.sensors.imu import ImuNoise
from fusion_vo.sensors.range import RangeNoise
from fusion_vo.sensors.wheel import WheelNoise, odom_twist_noise
from fusion_vo.sensors.visual_noise import VisualNoiseConfig
from fusion_vo import schema
from fusion_vo.sensors import registry

ROBUST_KERNELS = ("huber", "cauchy", "none")


@dataclass
class EkfConfig:
    """EKF process noise and options.

    Attributes
    ----------
    accel_sigma : float
        Forward acceleration noise of the constant-twist model [m/s²·√s] (default 0.5).
    lateral_accel_sigma : float
        Sideways acceleration noise [m/s²·√s] (default 0.1; a wheeled robot barely slides).
    yaw_accel_sigma : float
        Angular acceleration noise [rad/s²·√s] (default 1.0).
    scale_random_walk : float
        Random walk of the wheels' radius factor and their wheel-base factor [1/√s], in both backends
        (default 1e-4: tyres that warm up or wear).
    visual_scale_random_walk : float
        Random walk of the visual scale (the camera height) [1/√s], in both backends (default 1e-5: a rigidly
        mounted camera keeps its height, and a range finder measures one that changes). Nothing but the
        height prior holds the common scale of camera and wheels. With a walk as large as the wheels'
        (1e-4), the wheels' slip, shared between the two scale factors, moved the camera's scale: at the
        generator's true noise the fused tracks on ``square`` and ``random60`` were 2 and 1.5 times worse
        than with 1e-5. At the default priors the
        walks no longer matter on clean drives: 1e-7 here, or 1e-3 for the wheels, moved no profile's mean ATE
        ratio to visual odometry by more than 0.01 (docs/decisions/0036-visual-scale-model.md). Not 0: the graph
        ties each calibration segment's visual scale to the previous one with this walk, and ties of 1e-6 are too
        stiff for GTSAM's elimination (an indeterminate system on the drive of ``tests/backends/test_chain.py``).
    smoother : bool
        Run the Rauch–Tung–Striebel pass (default True).
    """

    accel_sigma: float = 0.5
    lateral_accel_sigma: float = 0.1
    yaw_accel_sigma: float = 1.0
    scale_random_walk: float = 1e-4
    visual_scale_random_walk: float = 1e-5
    smoother: bool = True


@dataclass
class GraphConfig:
    """Factor-graph options.

    Attributes
    ----------
    robust : str
        M-estimator on the visual, wheel, gyro and heading factors: ``"huber"``, ``"cauchy"`` or
        ``"none"`` (default ``"huber"``).
    robust_k : float
        Kernel width for a factor of one row, in standard deviations; a factor of ``m`` rows gets the width
        with the same tail probability on its whitened distance, ``sqrt(chi2.ppf(chi2.cdf(k², 1), m))``
        (:func:`fusion_vo.backends.graph_builder.kernel_width`). Default 3.2905: where the EKF's default gate
        (``gate_probability`` 0.999) starts, so that a measurement the filter takes at full weight keeps its
        full weight in the graph (1.345 is Huber's classic for one row, 2.3849 Cauchy's).
    keyframe_every : int
        Keep one pose variable every this many nodes (default 1: every camera frame).
    batch : bool
        Batch Levenberg–Marquardt smoothing over the whole recording (``"gtsam"``; default True).
    online : bool
        Incremental iSAM2, one update per node (``"gtsam_online"``; default True).
    fixed_lag : float
        Lag [s] of an incremental fixed-lag smoother (``"gtsam_fixed_lag"``); 0 disables it (default 0).
    max_iterations : int
        Levenberg–Marquardt iterations (default 20; at most 1000: each one linearises and solves the whole
        graph).
    relative_tolerance : float
        Stop when an iteration decreases the cost by less than this fraction (default 1e-3; later
        iterations move the poses by far less than their uncertainty).
    marginals : bool
        Compute marginal pose covariances of the batch solution (default True).
    calibration_interval : float
        Length [s] of the segments that share one gyro-bias and calibration variable (default 1).
    residuals : bool
        Compute each sensor's NIS at the batch and iSAM2 solutions (``FusionResult.residuals``,
        :mod:`fusion_vo.backends.residuals`; a consistency check, costs joint marginals; default False).
    reweight_passes : int
        iSAM2 (and the streaming fusion's) linearises a node's sensor-model factors again at its updated
        estimate, at most this many times, when a robust weight there differs from the one at the
        prediction (:func:`fusion_vo.backends.isam.update_reweighted`; default 2, 0: the weights at the
        prediction; at most 10: each pass is one more update of every node).
    """

    robust: str = "huber"
    robust_k: float = 3.2905
    keyframe_every: int = 1
    batch: bool = True
    online: bool = True
    fixed_lag: float = 0.0
    max_iterations: int = 20
    relative_tolerance: float = 1e-3
    marginals: bool = True
    calibration_interval: float = 1.0
    residuals: bool = False
    reweight_passes: int = 2


@dataclass
class FusionConfig:
    """Everything the backends need besides the measurements.

    Attributes
    ----------
    step_hz : float
        Node rate [Hz] where no camera frame provides the nodes (default 20; at most 1000: every node is a
        state of both backends, so the work grows with the rate, and 1e9 Hz never finished).
    max_gap : float
        A gap between two samples of a stream longer than this [s] is not bridged (default 0.25).
    reorder_window : float
        Streaming use: samples are held this long [s] to put out-of-order arrivals back in order;
        anything arriving later is counted as late (default 0.3).
    gate_probability : float
        Mahalanobis gate: a measurement whose squared Mahalanobis distance exceeds the chi-square
        quantile of this probability (degrees of freedom = measurement size) is rejected (default 0.999).
    self_calibration : bool
        Estimate the visual scale (camera height) and the wheel base (default True).
    visual_scale_sigma : float
        Prior standard deviation of the visual scale ``k_v = h_configured / h_true`` around 1 (default 0.002:
        the camera height is a mounting dimension, measured once, that no tyre, load, slip or floor changes).
        A ``height_sigma`` [m] in ``cam0/sensor.yaml`` replaces it by ``height_sigma / height``. Camera and
        wheels measure only the ratio ``k_v / k_r``; with these two priors a disagreement ``ρ`` of their
        distances moves the camera's scale by ``ρ σ_v² / (σ_v² + σ_r²)``: 1 % of it at the defaults (0.002
        and 0.02), 96 % at the former 0.05 and 0.01, which on clean generated drives put the wheels' radius
        error into the camera's scale (docs/decisions/0036-visual-scale-model.md).
    wheel_base_sigma : float
        Prior standard deviation of the wheel-base factor around 1 (default 0.05).
    visual_frame_error : float
        Fraction of each visual increment's stated variance that is the error of its two frames' own
        measurements rather than of the increment (default 0: independent increments). A frontend that
        measures each frame against the previous one puts that frame's error into both increments it
        belongs to, with opposite signs, so consecutive increments' errors correlate at
        ``-visual_frame_error / 2``. Both backends then model the increment between frames ``a`` and ``b``
        as ``z = motion + e_b - e_a + w``, each frame's error ``e`` with covariance ``visual_frame_error / 2``
        times the stated one and ``w`` with ``1 - visual_frame_error`` times it
        (:mod:`fusion_vo.sensors.visual`). Must be below 1.
    visual_noise : VisualNoiseConfig
        Estimate the camera's heading noise (a scale of its stated variance, and ``visual_frame_error``)
        from the camera's and the gyro's heading changes over the recording, without ground truth
        (:mod:`fusion_vo.sensors.visual_noise`; ``estimate``, default False; batch runs only).
    wheel_scale_sigma : float
        Prior standard deviation of the wheels' distance scale ``k_r = r_configured / r_true`` (their common
        radius error) around 1 (default 0.02: a tyre's effective rolling radius differs from its nominal one
        by a few per cent with pressure, load and floor); a ``radius_sigma`` [m] in ``wheel0/sensor.yaml``
        replaces it by ``radius_sigma / radius``. It also sets the prior of the wheels' curvature bias when
        ``radius_sigma`` is not stated (:class:`~fusion_vo.sensors.wheel.CurvedWheelModel`).
    odom_base_sigma : float
        Prior standard deviation of the wheel-base factor when the wheels are an odometry twist
        (default 0.3: the effective track width of a skid-steered base is known only roughly).
    sync_odometry : bool
        Estimate the delay of an odometry twist behind the gyro from their yaw rates
        (:func:`~fusion_vo.sensors.sync.odometry_delay`) and move the twist's timestamps back by it
        (default True; a controller's odometry is often stamped when published, late): over the whole
        recording in batch use, over the samples seen so far in streaming use
        (:class:`~fusion_vo.sensors.sync.TwistDelay`).
    max_odom_delay : float
        Largest delay [s] searched (default 1; at most 10: the search's work grows with it times the
        recording's length).
    monitor : bool
        Check the heading sources (wheel yaw rate, gyro, AHRS, camera) and the speeds (wheels, camera)
        against each other over windows and drop the component that contradicts the others there
        (:mod:`fusion_vo.backends.monitor`; default True).
    monitor_window : float
        Window length [s] of that check (default 2).
    monitor_probability : float
        A window whose NIS exceeds the chi-square quantile of this probability (1 degree of freedom)
        is inconsistent (default 0.9999: NIS 15.1).
    monitor_whole_fraction : float
        A component inconsistent over more than this fraction of the time it was checked is dropped
        for the whole recording (default 0.5).
    monitor_scale_sigma : float
        How far [relative] the ratio of the wheels' to the camera's distance may wander from its median
        over the recording before a window counts as a disagreement of speeds (default 0.02).
    monitor_bias_sigma : float
        Uncertainty [rad/s] of the gyro bias taken from the standstills (or the AHRS) in that check
        (default 0.001; a median over many samples at rest).
    consistency : ConsistencyConfig
        Before fusion, each stream's stated configuration is checked against the data (the IMU's mounting,
        the encoders' signs, an odometry twist's sign and frame, the clocks, the camera's and the wheels'
        scales) and corrected, left out or left as stated, with a sentence naming the file and key
        (:mod:`fusion_vo.consistency`; ``check``, default True).
    camera_height : float or None
        Configured camera height [m] the visual increments were computed with; needed by the range
        finder (default None: taken from the camera's ``T_BS`` by the caller; else in (0, 100]).
    initial_pose : tuple
        ``(x, y, yaw)`` of the first node [m, m, rad]: x and y within 1e7 m, the yaw in [-2π, 2π] (default
        the origin).
    initial_velocity_sigma : float
        Prior standard deviation of the initial speed [m/s] (default 0.5).
    wheel, odom, imu, range : WheelNoise, WheelNoise, ImuNoise, RangeNoise
        Sensor noise models (``wheel`` for encoder ticks, ``odom`` for an odometry twist, see
        :func:`~fusion_vo.sensors.wheel.odom_twist_noise`).
    gps : GpsNoise
        Gate and robust kernel of GPS fixes (:class:`~fusion_vo.sensors.gps.GpsNoise`: ``gate_chi2``,
        ``kernel``, ``kernel_width``, ``min_sigma``, ``estimate_sigma``); the fixes carry their own covariance.
    gps_reacquire : float
        After every fix of this many seconds [s] has failed the gate, the estimate rather than the fixes
        is taken to be wrong (a drift during an outage, a bad start): the next fix is applied anyway, the
        EKF first widening its position covariance by the squared innovation (default 5; the recovery
        of PX4's EKF2 after GPS rejection). A multipath jump lasting longer is then followed.
    ekf, graph : EkfConfig, GraphConfig
        Backend options.
    sensors : dict
        Configuration sections of sensors registered outside the library (:mod:`fusion_vo.sensors.registry`,
        ``Sensor.config``): section name -> its dataclass, read from the configuration's ``section:`` key
        through the same schema (default: the dataclass's defaults); see :meth:`section`.
    states : dict
        Prior and random walk of the state variables registered sensors add, by state name (``initial``,
        ``sigma``, ``random_walk``: :class:`~fusion_vo.sensors.registry.StatePrior`), read from the configuration's
        ``states:`` key (default: as each sensor registers it, ``Sensor.states``).

    Every number has a range (:meth:`validate`, the tables at the end of this module): standard deviations,
    noise densities and random walks are positive (or not negative) and at most :data:`MAX_SIGMA`; the
    numbers that set how much work a run does have their own upper bounds (``_AT_MOST``); any other number
    lies in [0, :data:`MAX_NUMBER`].
    """

    step_hz: float = 20.0
    max_gap: float = 0.25
    reorder_window: float = 0.3
    gate_probability: float = 0.999
    self_calibration: bool = True
    visual_scale_sigma: float = 0.002
    wheel_base_sigma: float = 0.05
    wheel_scale_sigma: float = 0.02
    visual_frame_error: float = 0.0
    visual_noise: VisualNoiseConfig = field(default_factory=VisualNoiseConfig)
    odom_base_sigma: float = 0.3
    sync_odometry: bool = True
    max_odom_delay: float = 1.0
    monitor: bool = True
    monitor_window: float = 2.0
    monitor_probability: float = 0.9999
    monitor_bias_sigma: float = 0.001
    monitor_scale_sigma: float = 0.02
    monitor_whole_fraction: float = 0.5
    consistency: ConsistencyConfig = field(default_factory=ConsistencyConfig)
    camera_height: float | None = None
    initial_pose: tuple = (0.0, 0.0, 0.0)
    initial_velocity_sigma: float = 0.5
    wheel: WheelNoise = field(default_factory=WheelNoise)
    odom: WheelNoise = field(default_factory=odom_twist_noise)
    imu: ImuNoise = field(default_factory=ImuNoise)
    range: RangeNoise = field(default_factory=RangeNoise)
    gps: GpsNoise = field(default_factory=GpsNoise)
    gps_reacquire: float = 5.0
    ekf: EkfConfig = field(default_factory=EkfConfig)
    graph: GraphConfig = field(default_factory=GraphConfig)
    sensors: dict = field(default_factory=dict)
    states: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`InputError` for values that cannot work."""
        if self.step_hz <= 0 or self.max_gap <= 0 or self.reorder_window < 0:
            raise InputError("step_hz and max_gap must be positive, reorder_window non-negative")
        if not 0.0 < self.gate_probability <= 1.0:
            raise InputError("gate_probability must be in (0, 1]")
        if self.graph.robust not in ROBUST_KERNELS:
            raise InputError(f"graph.robust must be one of {', '.join(ROBUST_KERNELS)}, not {self.graph.robust!r}")
        if not self.graph.robust_k > 0:
            raise InputError(f"'graph.robust_k' must be positive, not {self.graph.robust_k}")
        if not self.visual_frame_error < 1.0:
            raise InputError(f"'visual_frame_error' must be below 1, not {self.visual_frame_error}")
        if self.graph.calibration_interval <= 0:
            raise InputError("graph.calibration_interval must be positive")
        if not self.monitor_window > 0 or not 0.0 < self.monitor_probability < 1.0 or not self.monitor_bias_sigma > 0:
            raise InputError("monitor_window and monitor_bias_sigma must be positive, monitor_probability in (0, 1)")
        for key, values in _number_lists(self):  # (a registered sensor's section may hold lists of numbers)
            for i, value in enumerate(values):
                if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                    raise InputError(f"'{key}' must hold finite numbers, not {_shown(values)} (item {i + 1})")
        for key, value in _numbers(self):
            if not math.isfinite(value):
                raise InputError(f"'{key}' must be a finite number, not {value}")
            leaf = key.rsplit(".", 1)[-1]
            problem = _RANGES[leaf].error(f"'{key}'", value) if leaf in _RANGES else None
            if problem:
                raise InputError(problem)
            if ("sigma" in leaf or leaf in _POSITIVE) and value <= 0:
                raise InputError(f"'{key}' must be positive, not {value}")
            if value < 0:
                raise InputError(f"'{key}' must not be negative, not {value}")
            problem = _upper_bound(leaf).error(f"'{key}'", value)
            if problem:
                raise InputError(problem)
        if not self.range.min_range < self.range.max_range:
            raise InputError(f"'range.min_range' must be below 'range.max_range' ({self.range.max_range}), "
                             f"not {self.range.min_range}")
        _check_pose(self.initial_pose)
        if self.camera_height is not None:
            problem = _CAMERA_HEIGHT.error("'camera_height'", self.camera_height)
            if problem:
                raise InputError(problem)
        for name, prior in self.states.items():
            try:
                prior.check(f"states.{name}")
            except ValueError as exc:
                raise InputError(str(exc)) from None

    def wheel_model(self, twist: bool) -> tuple[WheelNoise, float]:
        """Noise model and wheel-base prior sigma of encoder ticks (``twist=False``) or an odometry twist."""
        return (self.odom, self.odom_base_sigma) if twist else (self.wheel, self.wheel_base_sigma)

    @classmethod
    def from_dict(cls, data: dict | None, path=None, prefix: tuple = ()) -> "FusionConfig":
        """Build from a nested mapping through the configuration schema (:func:`fusion_vo.schema.build`).

        Unknown keys, values of the wrong type and values that cannot work raise :class:`InputError`
        naming ``path`` and the key path (``prefix`` is the mapping's own path, e.g. ``("fusion",)``).
        """

        data = dict(data or {})
        own = {f.name for f in dataclasses.fields(cls)}
        sections = {}
        for sensor in registry.sensors():
            if sensor.config is not None and sensor.config[0] not in own:
                name, section_cls = sensor.config
                sections[name] = schema.build(section_cls, data.pop(name, None) or {}, path, prefix + (name,))
        states = _state_priors(data.pop("states", None), path, prefix + ("states",))
        config = schema.build(cls, data, path, prefix, exclude=("sensors", "states"))
        if sections or states:
            config.sensors = sections
            config.states = states
            try:  # their values, named like the built-in sections' (``fusion: 'compass.sigma' must be ...``)
                config.validate()
            except InputError as exc:
                where = ".".join(prefix)
                raise InputError(f"{where}: {exc.message}" if where else exc.message, path) from None
        return config

    def section(self, name: str):
        """The configuration section ``name``: a field (``imu``, ``gps`` ...) or a registered sensor's section
        (:attr:`sensors`, its defaults when not configured)."""
        if name in {f.name for f in dataclasses.fields(self)}:
            return getattr(self, name)
        if name not in self.sensors:
            for sensor in registry.sensors():
                if sensor.config is not None and sensor.config[0] == name:
                    self.sensors[name] = sensor.config[1]()
                    break
            else:
                raise KeyError(name)
        return self.sensors[name]

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def _state_priors(data, path, prefix: tuple) -> dict:
    """The ``states:`` section: each registered state's :class:`~fusion_vo.sensors.registry.StatePrior`, its
    defaults the registered ones (every registered state when any is configured; none otherwise)."""

    data = {} if data is None else data
    where = ".".join(prefix)
    if not isinstance(data, dict):
        raise InputError(f"{where}: expected a mapping of key: value, got {data!r}", path)
    known = {state.name: state for state in registry.all_states()}
    for name in data:
        if name not in known:
            listed = f" (known: {', '.join(known)})" if known else " (no registered sensor adds a state)"
            raise InputError(f"{where}.{name}: unknown key{listed}", path)
    out = {}
    for name, state in known.items():
        model = schema.model_of(registry.StatePrior, defaults=state.prior())
        values = schema.validate(model, data.get(name) or {}, path, prefix + (name,))
        out[name] = schema.to_dataclass(registry.StatePrior, values, path, prefix + (name,))
    return out


#: noise parameters that must be strictly positive besides every ``*sigma*`` (a zero would claim a perfect sensor)
_POSITIVE = {"gyro_noise_density", "k", "sigma_floor", "max_speed", "max_rate", "spike_threshold", "step_hz", "max_gap",
             "scale_tolerance", "frame_error_tolerance"}


#: ranges of number fields (by their last name) besides those rules: counts of at least 1, fractions ...
#: (:class:`fusion_vo.schema.Range`; every other number must not be negative)
_RANGES = {"keyframe_every": AT_LEAST_1, "max_iterations": AT_LEAST_1, "monitor_whole_fraction": FRACTION,
           "mounting_min_fit": FRACTION, "mounting_tolerance_deg": Range(high=90),
           "mounting_agreement_deg": Range(high=90)}

#: upper bounds of the numbers that set how much work a run does (nodes, iterations, a search's width, a
#: window's memory), checked after the rules above, so that a typo (``step_hz: 1e9``, which never finished)
#: is an error rather than a run that does not end or exhausts the memory
_AT_MOST = {"step_hz": Range(high=1000), "max_iterations": Range(high=1000), "reweight_passes": Range(high=10),
            "max_odom_delay": Range(high=10), "spike_window": Range(high=50)}

#: the upper bound of every standard deviation, noise density and random walk without one above (``*sigma*``,
#: ``*_density``, ``*_walk``): its square is a variance (``initial_velocity_sigma: 1.0e300`` overflowed)
MAX_SIGMA = 1e3

#: the upper bound of every other number without one above, in whatever unit it has (m, s, Hz, rad/s, a
#: factor, a count): beyond it a value is a typo, not a setting
MAX_NUMBER = 1e6

#: ``camera_height`` [m] (``odometry.height`` has the same range); ``initial_pose``: x, y [m] and yaw [rad]
_CAMERA_HEIGHT = Range(0, MAX_CAMERA_HEIGHT_M, open_low=True)
_POSE_RANGES = (Range(-MAX_POSITION_M, MAX_POSITION_M), Range(-MAX_POSITION_M, MAX_POSITION_M),
                Range(-2 * math.pi, 2 * math.pi))


def _upper_bound(leaf: str) -> Range:
    """The upper bound of the number field named ``leaf`` (``_AT_MOST``, else :data:`MAX_SIGMA` or
    :data:`MAX_NUMBER`)."""
    if leaf in _AT_MOST:
        return _AT_MOST[leaf]
    if "sigma" in leaf or leaf.endswith(("_density", "_walk")):
        return Range(high=MAX_SIGMA)
    return Range(high=MAX_NUMBER)


def _shown(value) -> str:
    text = repr(list(value) if isinstance(value, tuple) else value)
    return text if len(text) <= 60 else text[:57] + "..."


def _check_pose(pose) -> None:
    """``initial_pose`` must be three finite numbers ``(x, y, yaw)`` (a NaN one made every pose NaN), x and y
    within :data:`~fusion_vo.measurements.MAX_POSITION_M` and the yaw within a turn either way."""
    try:
        values = tuple(pose)
    except TypeError:
        values = None
    if values is None or len(values) != 3 or not all(
            not isinstance(v, bool) and isinstance(v, numbers.Real) and math.isfinite(v) for v in values):
        raise InputError(f"'initial_pose' must be three finite numbers (x, y, yaw), not {_shown(pose)}")
    for name, value, bound in zip(("x", "y", "yaw"), values, _POSE_RANGES):
        problem = bound.error(f"'initial_pose' {name}", value)
        if problem:
            raise InputError(problem)


def _number_lists(obj, prefix: str = ""):
    """``(dotted key, list)`` of every list- or tuple-valued field holding numbers of a (nested) config
    dataclass, registered sensors' sections included, except the pose (checked by :func:`_check_pose`)."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            yield from _number_lists(value, f"{prefix}{f.name}.")
        elif isinstance(value, dict) and f.name == "sensors":
            for name, section in value.items():
                if dataclasses.is_dataclass(section):
                    yield from _number_lists(section, f"{prefix}{name}.")
        elif isinstance(value, (list, tuple)) and f.name != "initial_pose" and any(
                isinstance(v, numbers.Real) and not isinstance(v, bool) for v in value):
            yield f"{prefix}{f.name}", value


def _numbers(obj, prefix: str = ""):
    """``(dotted key, value)`` of every number field (float or int) of a (nested) config dataclass, except the
    pose."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            yield from _numbers(value, f"{prefix}{f.name}.")
        elif isinstance(value, dict) and f.name == "sensors":  # the registered sensors' sections
            for name, section in value.items():
                if dataclasses.is_dataclass(section):
                    yield from _numbers(section, f"{prefix}{name}.")
        elif isinstance(value, (float, int)) and not isinstance(value, bool) \
                and f.name not in ("initial_pose", "camera_height"):
            yield f"{prefix}{f.name}", value
