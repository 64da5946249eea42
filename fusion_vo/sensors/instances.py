"""Further instances of the odometry-twist and IMU kinds: ``odom1`` ... ``odom9`` and ``imu1`` ... ``imu9``.

Instance 0 of each kind is the sensor ``odom`` (``odom0/``, :mod:`fusion_vo.sensors.wheel`) or ``imu``
(``imu0/``, :mod:`fusion_vo.sensors.imu`). Instance ``N`` is made by the factories here the first time its name is
asked for (:func:`fusion_vo.sensors.registry.register_kind`), reads ``odomN/`` or ``imuN/`` (the same
``data.csv`` columns and ``sensor.yaml`` keys as instance 0), has its own configuration section
``fusion: {odomN: ...}`` or ``fusion: {imuN: ...}`` and is fused by both backends through its readings.

Odometry twist ``odomN``
------------------------
Samples ``(v_x, v_y, ω)`` held between samples (zero-order hold of the earlier one). The ``mask`` of its section
chooses the components it contributes (``vx``, ``vy``, ``yaw_rate``); a component left out is set to zero before
anything is computed from the samples (the travel, the gate, the noise), and its row is not a reading, so its values
have no influence on the estimate. Over a node interval ``Δt`` the held twist integrates, as for ``odom0``
(:func:`fusion_vo.sensors.wheel.twist_to_travel` on a nominal base ``b``), to the arc ``(d, d_y, θ)`` with
``d = ∫ v_x dt``, ``d_y = ∫ v_y dt``, ``θ = ∫ ω dt``; with the forward and sideways slope factors ``c_x, c_y`` of
an AHRS (:mod:`fusion_vo.sensors.imu`) the reading is the increment ``z = exp(c_x d, c_y d_y, θ)`` of the motion,
``h(δ) = δ`` (rows of the mask). Its noise is ``odom0``'s (:func:`fusion_vo.sensors.wheel.arc_twist`, the
defaults of :func:`~fusion_vo.sensors.wheel.odom_twist_noise`) in the arc's coordinates ``(d, d_y, θ)``, carried to
the increment's by the exponential's Jacobian ``J``: ``Σ = J Σ_arc Jᵀ``, of the mask's rows. With ``vx`` and
``yaw_rate`` in the mask, an interval with both nominal wheels slower than ``standstill_speed`` is also a
standstill reading (zero heading change, :class:`~fusion_vo.sensors.wheel.StandstillModel`). Not done for
``odomN`` (done for ``odom0``): the delay estimate against the gyro, the consistency checks of sign and frame, the
heading monitor, a wheel-base or distance scale state.

Gyro ``imuN``
-------------
The body yaw rate ``ω_z = (R_BS ω_S)_z`` of its samples, ``R_BS`` from ``imuN/sensor.yaml``'s ``T_BS`` (or the
section's ``T_BS`` for samples fed live), gated against a running median as ``imu0``'s
(:func:`fusion_vo.sensors.imu.gated_yaw_rate`), integrated over each node interval to ``Θ`` and read as the heading
change with its own bias state ``imuN_gyro_bias``: ``h(δ, b) = d_ψ + b Δt``, ``R = σ_g² Δt``
(:class:`~fusion_vo.sensors.imu.GyroModel`). ``σ_g`` is ``gyroscope_noise_density`` of ``imuN/sensor.yaml`` when
given, else the section's ``gyro_noise_density``; the bias's prior and random walk are those of
``fusion: {states: {imuN_gyro_bias: ...}}`` (default σ 0.02 rad/s, walk 2e-5 rad/s²/√Hz, as ``imu0``'s). Only
the gyro's yaw rate is used (no AHRS heading, no slope factors, no rest noise density).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from pydantic import Field, field_validator

from fusion_vo.config.base import Int, NonNegative, Positive, Section, Sigma
from fusion_vo.geometry import se2
from fusion_vo.measurements import ImuData, ImuSample, SensorCount, TwistData, TwistSample
from fusion_vo.measurements.grid import coverage, ordered_fields
from fusion_vo.sensors.imu import GyroModel, ImuNoise, body_yaw_rate, cumulative_angle, gated_yaw_rate, read_imu
from fusion_vo.sensors.model import MeasurementModel
from fusion_vo.sensors.readings import Readings
from fusion_vo.sensors.registry import Live, Sensor, State, Step, register_kind
from fusion_vo.sensors.wheel import (STANDSTILL, WheelNoise, arc_twist, gyro_turn, odom_twist_noise, standstill,
                                     read_twist, twist_to_travel)

logger = logging.getLogger(__name__)

#: the components an odometry twist may contribute, in the order of the motion's rows ``(d_x, d_y, d_ψ)``
MASK_COMPONENTS = ("vx", "vy", "yaw_rate")
#: nominal base [m] on which a twist becomes wheel travel for its noise model (as ``odom0``'s)
NOMINAL_BASE = 0.5
#: the place of the instances' readings among the built-in sensors' (:data:`fusion_vo.sensors.readings.ORDER`)
ODOM_ORDER = 25.0
STANDSTILL_ORDER = 45.0
GYRO_ORDER = 35.0

_ODOM_DEFAULTS = odom_twist_noise()


# --------------------------------------------------------------------------- odomN
class OdomInstanceNoise(Section):
    """Configuration of an odometry twist ``odomN`` (``fusion: {odom1: ...}``): the components it contributes and
    ``odom0``'s noise model (:class:`~fusion_vo.sensors.wheel.WheelNoise`, defaults of
    :func:`~fusion_vo.sensors.wheel.odom_twist_noise`)."""

    mask: list[str] = Field(default_factory=lambda: list(MASK_COMPONENTS), description=(
        "Components of the twist this odometry contributes, of ``vx``, ``vy`` and ``yaw_rate`` (at least one): a "
        "component left out has no influence on the estimate."))
    k: Positive = Field(_ODOM_DEFAULTS.k, description="Travel noise [m^½] of each nominal wheel: variance ``k² |d|``.")
    sigma_floor: Sigma = Field(_ODOM_DEFAULTS.sigma_floor, description="Standard deviation added to every travel [m].")
    k_lateral: NonNegative = Field(_ODOM_DEFAULTS.k_lateral, description=(
        "Sideways noise [m^½]: variance ``k_lateral² |d|`` on the sideways motion."))
    k_yaw: NonNegative = Field(_ODOM_DEFAULTS.k_yaw, description="Turn noise [rad^½]: variance ``k_yaw² |θ|``.")
    yaw_scale: NonNegative = Field(_ODOM_DEFAULTS.yaw_scale, description=(
        "Relative standard deviation of the reported heading change (skid steering)."))
    yaw_scale_time: NonNegative = Field(_ODOM_DEFAULTS.yaw_scale_time, description=(
        "Correlation time [s] of that heading error (0: white)."))
    max_speed: Positive = Field(_ODOM_DEFAULTS.max_speed, description=(
        "A sample whose nominal wheel speed exceeds this [m/s] is gated."))
    standstill_speed: NonNegative = Field(_ODOM_DEFAULTS.standstill_speed, description=(
        "Both nominal wheels slower than this [m/s] over an interval is a standstill (needs ``vx`` and ``yaw_rate`` "
        "in the mask; 0 disables it)."))
    standstill_yaw_rate: NonNegative = Field(_ODOM_DEFAULTS.standstill_yaw_rate, description=(
        "Standard deviation [rad/s] of the zero yaw rate at a standstill."))

    @field_validator("mask", mode="before")
    @classmethod
    def _components(cls, value: Any) -> Any:
        if isinstance(value, str) or not isinstance(value, (list, tuple)):
            raise ValueError(f"must be a list of {', '.join(MASK_COMPONENTS)}, not {value!r}")
        bad = [v for v in value if v not in MASK_COMPONENTS]
        if bad:
            raise ValueError(f"unknown component {bad[0]!r} (use {', '.join(MASK_COMPONENTS)})")
        if not value:
            raise ValueError(f"must name at least one of {', '.join(MASK_COMPONENTS)}")
        if len(set(value)) != len(value):
            raise ValueError(f"names a component twice: {list(value)!r}")
        return list(value)

    def rows(self) -> tuple[int, ...]:
        """The motion's rows the mask keeps, in order."""
        return tuple(i for i, c in enumerate(MASK_COMPONENTS) if c in self.mask)

    def wheel_noise(self) -> WheelNoise:
        """These values as ``odom0``'s noise model."""
        return WheelNoise(k=self.k, sigma_floor=self.sigma_floor, k_lateral=self.k_lateral, k_yaw=self.k_yaw,
                          yaw_scale=self.yaw_scale, yaw_scale_time=self.yaw_scale_time, max_speed=self.max_speed,
                          standstill_speed=self.standstill_speed, standstill_yaw_rate=self.standstill_yaw_rate)


@dataclass(frozen=True)
class TwistIncrementModel(MeasurementModel):
    """An odometry's increment as a measurement of the body motion: ``h(δ) = δ``, ``∂h/∂δ = I`` (rows of its mask;
    the EKF reads the increment's logarithm, the interval's twist). Argument ``motion``."""

    name: str = "odom1"
    args: tuple = ("motion",)
    dim: int = 3
    turn_rows: tuple = (2,)
    increment: bool = True
    guess_rank: tuple = (2, 2)

    def identity(self, fixed: dict) -> bool:
        return True

    def guess(self, z, estimate: dict, dt: float):
        """The increment itself (a component outside the mask gives none: :attr:`guess_rank` None)."""
        return np.asarray(z[:2], dtype=np.float64), float(z[2])

    def evaluate(self, motion):
        d = np.asarray(motion, dtype=np.float64)
        if d.ndim == 1:
            return d.copy(), {"motion": np.eye(3)}
        return d.copy(), {"motion": np.broadcast_to(np.eye(3), d.shape[:-1] + (3, 3)).copy()}


@dataclass
class TwistOnGrid:
    """An odometry twist on the node grid: per interval whether it is covered (``ok``), the nominal wheels' travels
    ``dl, dr`` [m] and the sideways travel ``side`` [m], of the mask's components."""

    ok: np.ndarray
    dl: np.ndarray
    dr: np.ndarray
    side: np.ndarray


def masked_twist(data: TwistData, mask) -> TwistData:
    """``data`` with the components outside ``mask`` (of :data:`MASK_COMPONENTS`) set to zero."""
    keep = {c: c in mask for c in MASK_COMPONENTS}
    zero = np.zeros(len(data.t))
    return TwistData(np.asarray(data.t, dtype=np.float64),
                     np.asarray(data.vx, dtype=np.float64) if keep["vx"] else zero,
                     np.asarray(data.vy, dtype=np.float64) if keep["vy"] else zero,
                     np.asarray(data.wz, dtype=np.float64) if keep["yaw_rate"] else zero)


def twist_on_grid(data: TwistData, T: np.ndarray, noise: OdomInstanceNoise, max_gap: float,
                  count: SensorCount) -> TwistOnGrid:
    """The mask's components of the twist ``data`` integrated over the node intervals of ``T`` (module docstring);
    gated and missing intervals counted in ``count``."""
    data = masked_twist(ordered_fields(data, ("vx", "vy", "wz"), count), noise.mask)
    travel = twist_to_travel(data, wheel_base=NOMINAL_BASE, max_speed=noise.max_speed)
    count.gated += travel.n_gated
    dt = np.diff(travel.t)
    vy = np.asarray(data.vy, dtype=np.float64)[:-1]
    step = np.where(travel.valid & np.isfinite(vy), vy * dt, 0.0)
    side = np.concatenate([[0.0], np.cumsum(step)])
    ok = coverage(travel.t, ~travel.valid, T, max_gap)
    at = lambda x: np.diff(np.interp(T, travel.t, x))  # noqa: E731
    count.used += int(ok.sum())
    count.missing += int((~ok).sum())
    return TwistOnGrid(ok, at(travel.left), at(travel.right), at(side))


def odom_readings(name: str, on_grid: TwistOnGrid, iv, noise: OdomInstanceNoise) -> list[Readings]:
    """The readings of odometry ``name`` on the grid ``iv`` (module docstring)."""
    k = np.flatnonzero(on_grid.ok)
    if not len(k):
        return []
    wheel_noise = noise.wheel_noise()
    dl, dr, dt = on_grid.dl[k], on_grid.dr[k], iv.dt[k]
    turn = gyro_turn(iv)
    _, rate_cov = arc_twist(dl, dr, dt, NOMINAL_BASE, wheel_noise, None if turn is None else turn[k])
    xi = np.stack([0.5 * (dl + dr) * iv.cx[k], on_grid.side[k] * iv.cy[k], (dr - dl) / NOMINAL_BASE], axis=1)
    J = se2.exp_jacobian(xi)
    cov = J @ (rate_cov * (dt**2)[:, None, None]) @ np.transpose(J, (0, 2, 1))
    rows = noise.rows()
    translation, heading = (0 in rows or 1 in rows), 2 in rows
    model = TwistIncrementModel(name=name, guess_rank=(2 if translation else None, 2 if heading else None))
    if len(rows) < 3:
        cov = cov[:, list(rows)][:, :, list(rows)]
    out = [Readings(name, model, k, k + 1, se2.exp_many(xi), cov, rows=None if len(rows) == 3 else rows,
                    order=ODOM_ORDER)]
    if "vx" in noise.mask and "yaw_rate" in noise.mask:
        still = on_grid.ok & standstill(on_grid.dl, on_grid.dr, iv.dt, wheel_noise)
        if still.any():
            s = np.flatnonzero(still)
            sigma = noise.standstill_yaw_rate * np.maximum(iv.dt[s], 1e-3)
            out.append(Readings(f"{name}_standstill", STANDSTILL, s, s + 1, np.zeros(len(s)), sigma**2, robust=False,
                                order=STANDSTILL_ORDER))
    return out


def _twist_sample(m) -> tuple:
    """A live :class:`~fusion_vo.measurements.TwistSample`: ``(t, (vx, vy, wz))``."""
    return m.t, (m.vx, m.vy, m.wz)


def _twist_data(t, rows, fusion) -> TwistData:
    v = np.array(rows, dtype=np.float64)
    return TwistData(np.asarray(t, dtype=np.float64), v[:, 0], v[:, 1], v[:, 2])


def _twist_samples(data: TwistData):
    return [(float(t), TwistSample(float(t), float(vx), float(vy), float(wz)))
            for t, vx, vy, wz in zip(data.t, data.vx, data.vy, data.wz)]


def odometry_instance(n: int) -> Sensor:
    """The odometry twist ``odom{n}`` read from ``odom{n}/`` (module docstring)."""
    name, folder = f"odom{n}", f"odom{n}"

    def intervals(iv, streams, config, counts) -> None:
        count = counts.setdefault(name, SensorCount())
        iv.sensors[name] = twist_on_grid(streams[name], iv.t, config.section(name), config.max_gap, count)

    def readings(iv, config) -> list[Readings]:
        on_grid = iv.sensors.get(name)
        return [] if on_grid is None else odom_readings(name, on_grid, iv, config.section(name))

    return Sensor(name=name, where=f"{folder}/", min_samples=2, folder=folder,
                  read=lambda recording: read_twist(recording, folder), default=False, config=(name, OdomInstanceNoise),
                  intervals=Step(ODOM_ORDER, intervals), readings=readings,
                  live=Live(_twist_sample, _twist_data, samples=_twist_samples))


# --------------------------------------------------------------------------- imuN
def _mounting(value: Any) -> Any:
    if value is None:
        return None
    m = np.asarray(value, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError("must be a 4x4 matrix of finite numbers (the IMU's pose in the body frame)")
    r = m[:3, :3]
    if np.abs(r @ r.T - np.eye(3)).max() > 1e-3 or abs(np.linalg.det(r) - 1.0) > 1e-3:
        raise ValueError("its upper-left 3x3 block must be a rotation (orthonormal, determinant 1)")
    return [[float(x) for x in row] for row in m]


class ImuInstanceNoise(Section):
    """Configuration of a gyro ``imuN`` (``fusion: {imu1: ...}``): its noise, its spike gate and, for samples fed
    live, its mounting. The bias's prior and random walk are the state's, ``fusion: {states: {imu1_gyro_bias:
    ...}}``."""

    gyro_noise_density: Sigma = Field(ImuNoise().gyro_noise_density, description=(
        "``σ_g`` [rad/s/√Hz] (``gyroscope_noise_density`` of ``imuN/sensor.yaml`` replaces it when given)."))
    spike_threshold: Positive = Field(ImuNoise().spike_threshold, description=(
        "Distance from the running median that marks a spike [rad/s]."))
    spike_window: Int = Field(ImuNoise().spike_window, ge=0, le=50, description="Half width of the running median.")
    max_rate: Positive = Field(ImuNoise().max_rate, description="Largest believable yaw rate [rad/s].")
    T_BS: list[list[float]] | None = Field(None, description=(
        "The IMU's pose in the body frame (4x4, rows) of samples fed live (``StreamingFusion.add``); a recording's "
        "``imuN/sensor.yaml`` states it for its own samples (null: aligned with the body)."))

    @field_validator("T_BS", mode="before")
    @classmethod
    def _rotation(cls, value: Any) -> Any:
        return _mounting(value)

    def imu_noise(self, keys: dict | None = None) -> ImuNoise:
        """These values as ``imu0``'s gyro noise and gate, with the noise keys of a ``sensor.yaml`` applied."""
        noise = ImuNoise(gyro_noise_density=self.gyro_noise_density, spike_threshold=self.spike_threshold,
                         spike_window=self.spike_window, max_rate=self.max_rate)
        return noise.with_sensor_keys(keys or {})


@dataclass(frozen=True)
class InstanceGyroModel(GyroModel):
    """:class:`~fusion_vo.sensors.imu.GyroModel` of a gyro whose bias is its own state: ``h(δ, b) = d_ψ + b Δt``.
    Arguments ``motion`` and the bias named in :attr:`args`; parameter ``dt``."""

    name: str = "imu1"
    args: tuple = ("motion", "imu1_gyro_bias")

    def guess(self, z, estimate: dict, dt: float):
        """The heading change: the angle less the running estimate of its own bias's share, ``Θ - b̂ Δt``."""
        return None, float(z[0]) - estimate.get(self.args[1], 0.0) * dt

    def evaluate(self, motion, dt=1.0, **bias):
        h, jac = GyroModel.evaluate(self, motion, bias[self.args[1]], dt)
        return h, {"motion": jac["motion"], self.args[1]: jac["gyro_bias"]}


def gyro_on_grid(data: ImuData, T: np.ndarray, noise: ImuNoise, max_gap: float,
                 count: SensorCount) -> tuple[np.ndarray, np.ndarray]:
    """``(ok, Θ)``: per node interval of ``T`` whether the gyro covers it and its integrated body yaw rate [rad]."""
    data = ordered_fields(data, ("gyro", "accel", "orientation"), count)
    gyro = gated_yaw_rate(data.t, body_yaw_rate(data), noise)
    count.gated += gyro.n_gated
    ok = coverage(gyro.t, np.zeros(max(len(gyro.t) - 1, 0), bool), T, max_gap)
    theta = np.interp(T, gyro.t, cumulative_angle(gyro)) if len(gyro.t) else np.zeros(len(T))
    count.used += int(ok.sum())
    count.missing += int((~ok).sum())
    return ok, np.diff(theta)


def _imu_sample(m) -> tuple:
    """A live :class:`~fusion_vo.measurements.ImuSample`: ``(t, (gyro, accel))`` (an orientation is not used)."""
    return m.t, (np.asarray(m.gyro, dtype=np.float64), np.asarray(m.accel, dtype=np.float64))


def imu_instance(n: int) -> Sensor:
    """The gyro ``imu{n}`` read from ``imu{n}/`` (module docstring)."""
    name, folder, bias = f"imu{n}", f"imu{n}", f"imu{n}_gyro_bias"
    model = InstanceGyroModel(name=name, args=("motion", bias))

    def intervals(iv, streams, config, counts) -> None:
        data = streams[name]
        noise = config.section(name).imu_noise(data.noise)
        ok, angle = gyro_on_grid(data, iv.t, noise, config.max_gap, counts.setdefault(name, SensorCount()))
        iv.sensors[name] = (ok, angle, noise.gyro_noise_density)

    def readings(iv, config) -> list[Readings]:
        if name not in iv.sensors:
            return []
        ok, angle, density = iv.sensors[name]
        k = np.flatnonzero(ok)
        var = GyroModel.variance(density, iv.dt[k])
        return [Readings(name, model, k, k + 1, angle[k], var, robust=False, order=GYRO_ORDER)]

    def live_data(t, rows, fusion) -> ImuData:
        mounting = fusion.config.section(name).T_BS
        return ImuData(np.asarray(t, dtype=np.float64), np.array([r[0] for r in rows]),
                       np.array([r[1] for r in rows]), None,
                       np.eye(4) if mounting is None else np.asarray(mounting, dtype=np.float64))

    def samples(data: ImuData):
        """Replayed samples: turned into the body frame by the recording's ``T_BS`` (the live mounting is for
        samples a program feeds)."""
        r_bs = np.asarray(data.T_BS, dtype=np.float64)[:3, :3]
        return [(float(t), ImuSample(float(t), r_bs @ np.asarray(g, dtype=np.float64), r_bs @ np.asarray(a)))
                for t, g, a in zip(data.t, data.gyro, data.accel)]

    return Sensor(name=name, where=f"{folder}/", min_samples=2, folder=folder,
                  read=lambda recording: read_imu(recording, folder), default=False, config=(name, ImuInstanceNoise),
                  states=(State(bias, initial=0.0, sigma=ImuNoise().gyro_bias_sigma,
                                random_walk=ImuNoise().gyro_random_walk),),
                  intervals=Step(GYRO_ORDER, intervals), readings=readings, absolute_heading=True,
                  heading_reference=False,  # a gyro: its bias is its own, so it cannot tell the wheels' curvature
                  live=Live(_imu_sample, live_data, neighbours=lambda config: int(config.section(name).spike_window) + 1,
                            samples=samples))


register_kind("odom", odometry_instance)
register_kind("imu", imu_instance)
