"""The gyro's body yaw rate, its noise section and its spike gating.

The body yaw rate is the body-z component of the IMU's rate rotated into the body frame, ``ω_z = (R_BS ω_S)_z``
(:func:`body_yaw_rate`). Spikes (an impossible sample) are found against a running median: a sample further than
``spike_threshold`` from the median of its ``2w+1`` neighbours, or above ``max_rate``, or not finite, is gated
(counted) and replaced by the median so integration carries on (:func:`gated_yaw_rate`). The gyro's measurement
model (:class:`GyroModel`) is here too; the rest of the IMU is in :mod:`fusion_vo.sensors.imu`. This module is what
the clock alignment of :mod:`fusion_vo.sensors.sync` and the camera's noise estimate
(:mod:`fusion_vo.sensors.visual_noise`) need of the gyro.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from fusion_vo.config.base import Int, Positive, Section, Sigma, Walk
from fusion_vo.measurements import ImuData
from fusion_vo.sensors.model import MeasurementModel

logger = logging.getLogger(__name__)


class ImuNoise(Section):
    """Gyro noise, bias and gating parameters.

    ``gyroscope_noise_density`` and ``gyroscope_random_walk`` of the recording's ``imu0/sensor.yaml`` replace the
    two noise defaults when present (:meth:`with_sensor_keys`).
    """

    gyro_noise_density: Sigma = Field(1.7e-3, description="``σ_g`` [rad/s/√Hz] (a MEMS gyro).")
    gyro_random_walk: Walk = Field(2e-5, description="``σ_bw`` [rad/s²/√Hz].")
    gyro_bias_sigma: Sigma = Field(0.02, description=(
        "Prior standard deviation of the initial bias [rad/s] (0.02: an uncalibrated MEMS gyro). A filter that has "
        "not yet seen the robot at rest learns the bias only from the other heading sources; with a "
        "factory-calibrated gyro, a prior of its specified turn-on bias (e.g. 0.002) keeps the wheels' "
        "turn-correlated yaw errors from dragging it (on robot_localization's Husky log the filtered track's RMS "
        "against GPS goes from 5.7 m to 3.4 m)."))
    ahrs_yaw_sigma: Sigma = Field(0.02, description="Standard deviation of an AHRS heading's white noise [rad].")
    ahrs_offset_walk: Walk = Field(0.0, description=(
        "Random walk ``σ_ow`` [rad/√s] of the AHRS heading's offset from the true heading (0: the AHRS heading is "
        "absolute, as robot_localization treats an IMU's orientation, and the world frame follows it; an AHRS "
        "whose heading strays from the gyro's and the wheels' by more than their noise allows is dropped by the "
        "consistency monitor, :mod:`fusion_vo.backends.monitor`. A positive value, e.g. 0.02 for a magnetometer "
        "that may stray by about 10° in a minute or two, lets the backends estimate a wandering offset "
        "instead)."))
    gyro_rest_noise_density: Walk = Field(0.0, description=(
        "``σ_rest`` [rad/s/√Hz]: the gyro's white noise density at rest, used instead of ``σ_g`` (when lower) for "
        "the intervals in which the wheels report a standstill (0: ``σ_g`` everywhere). Used by ``fusion-vo run`` "
        "(EKF, RTS, GTSAM batch, iSAM2); streaming fusion (``replay``, "
        ":class:`~fusion_vo.backends.streaming.StreamingFusion`) keeps ``σ_g`` and logs a warning."))
    spike_threshold: Positive = Field(1.0, description="Distance from the running median that marks a spike "
                                                       "[rad/s].")
    spike_window: Int = Field(2, ge=0, le=50, description="Half width ``w`` of the running median.")
    max_rate: Positive = Field(10.0, description="Largest believable yaw rate [rad/s].")

    def density(self, at_rest) -> np.ndarray:
        """``σ_g`` per interval, ``min(σ_g, σ_rest)`` where ``at_rest`` (bool or bool array) when ``σ_rest`` is set."""
        rest = self.gyro_rest_noise_density
        rest = min(rest, self.gyro_noise_density) if rest > 0 else self.gyro_noise_density
        return np.where(at_rest, rest, self.gyro_noise_density)

    def with_sensor_keys(self, keys: dict) -> ImuNoise:
        """Copy with the EuRoC keys of ``imu0/sensor.yaml`` applied where present and positive (the file's values
        are checked when it is read, :class:`fusion_vo.config.sensor_files.ImuFile`)."""
        changes = {}
        nd = keys.get("gyroscope_noise_density")
        rw = keys.get("gyroscope_random_walk")
        if nd is not None and float(nd) > 0:
            changes["gyro_noise_density"] = float(nd)
        if rw is not None and float(rw) > 0:
            changes["gyro_random_walk"] = float(rw)
        return self.model_copy(update=changes) if changes else self


def discrete_sigma(noise_density: float, rate_hz: float) -> float:
    """Standard deviation of one sample of white noise with ``noise_density`` sampled at ``rate_hz``."""
    return float(noise_density * np.sqrt(rate_hz))


@dataclass
class GyroYaw:
    """Body yaw rate samples after gating.

    ``t`` (N,), ``rate`` (N,) [rad/s] with spikes replaced, ``gated`` (N,) bool, ``n_gated``.
    """

    t: np.ndarray
    rate: np.ndarray
    gated: np.ndarray
    n_gated: int


def body_yaw_rate(data: ImuData) -> np.ndarray:
    """Body-z rate ``(R_BS ω_S)_z`` of every sample (N,)."""
    r_bs = np.asarray(data.T_BS, dtype=np.float64)[:3, :3]
    return np.asarray(data.gyro, dtype=np.float64) @ r_bs[2]


def gyro_yaw(data: ImuData, noise: ImuNoise | None = None) -> GyroYaw:
    """Yaw rate in the body frame with spikes and non-finite samples gated (see the module docstring)."""
    return gated_yaw_rate(data.t, body_yaw_rate(data), noise)


def gated_yaw_rate(t, rate, noise: ImuNoise | None = None) -> GyroYaw:
    """:func:`gyro_yaw` of body yaw rates already computed: ``t`` (N,), ``rate`` (N,) [rad/s]."""
    noise = noise or ImuNoise()
    t = np.asarray(t, dtype=np.float64)
    rate = np.asarray(rate, dtype=np.float64)
    finite = np.isfinite(rate)
    med = running_median(np.where(finite, rate, 0.0), noise.spike_window, finite)
    gated = ~finite | (np.abs(rate - med) > noise.spike_threshold) | (np.abs(rate) > noise.max_rate)
    n_gated = int(np.count_nonzero(gated))
    if n_gated:
        logger.info("imu: gated %d gyro samples (spikes or non-finite)", n_gated)
    return GyroYaw(t, np.where(gated, med, rate), gated, n_gated)


def running_median(x: np.ndarray, half_width: int, valid: np.ndarray | None = None) -> np.ndarray:
    """Median of each sample's ``2w+1`` neighbourhood (edges padded by reflection), ignoring invalid ones."""
    x = np.asarray(x, dtype=np.float64)
    if len(x) == 0 or half_width <= 0:
        return x.copy()
    w = int(half_width)
    vals = np.where(valid, x, np.nan) if valid is not None else x
    padded = np.pad(vals, w, mode="reflect") if len(x) > w else np.pad(vals, w, mode="edge")
    windows = np.sort(np.lib.stride_tricks.sliding_window_view(padded, 2 * w + 1), axis=1)  # NaN sort last
    k = np.count_nonzero(~np.isnan(windows), axis=1)  # valid samples per window
    rows = np.arange(len(windows))
    lo, hi = np.maximum((k - 1) // 2, 0), np.maximum(k // 2, 0)
    med = 0.5 * (windows[rows, lo] + windows[rows, hi])  # nanmedian without its slow masked-array path
    med[k == 0] = np.nan
    return np.where(np.isfinite(med), med, 0.0)


@dataclass(frozen=True)
class GyroModel(MeasurementModel):
    """The gyro's integrated angle over an interval ``Δt`` as a measurement of the heading change.

    ``z = Θ = ∫ ω_z dt``, ``h(δ, b_g) = d_ψ + b_g Δt``, ``R = σ_g² Δt``; Jacobians ``∂h/∂δ = (0, 0, 1)``,
    ``∂h/∂b_g = Δt``. Arguments ``motion``, ``gyro_bias``; parameter ``dt`` (the EKF evaluates it per
    unit time: ``z = Θ/Δt``, ``R = σ_g²/Δt``, ``dt = 1``).
    """

    name: str = "gyro"
    linear: bool = True
    args: tuple = ("motion", "gyro_bias")
    dim: int = 1
    turn_rows: tuple = (0,)
    uses_dt: bool = True
    guess_rank: tuple = (None, 0)

    def guess(self, z, estimate: dict, dt: float):
        """The heading change: the angle less the running bias estimate's share, ``Θ - b̂ Δt``."""
        return None, float(z[0]) - estimate.get("gyro_bias", 0.0) * dt

    def evaluate(self, motion, gyro_bias, dt=1.0):
        d = np.asarray(motion, dtype=np.float64)
        if d.ndim == 1 and isinstance(dt, (int, float)):  # one measurement: without array overhead
            t = float(dt)
            return (np.array([float(d[2]) + float(gyro_bias[0]) * t]),
                    {"motion": np.array([[0.0, 0.0, 1.0]]), "gyro_bias": np.array([[t]])})
        b = np.asarray(gyro_bias, dtype=np.float64)
        dt = np.asarray(dt, dtype=np.float64)
        h = d[..., 2:3] + b * dt[..., None] if dt.ndim else d[..., 2:3] + b * float(dt)
        j_d = np.zeros(d.shape[:-1] + (1, 3))
        j_d[..., 0, 2] = 1.0
        j_b = np.broadcast_to(dt, d.shape[:-1]).astype(np.float64)[..., None, None].copy()
        return h, {"motion": j_d, "gyro_bias": j_b}

    @staticmethod
    def variance(noise_density: float, dt):
        """``σ_g² Δt`` of the integrated angle over ``dt`` [s]."""
        return noise_density**2 * np.asarray(dt, dtype=np.float64)


#: the gyro's measurement model
GYRO = GyroModel()


__all__ = ["GyroModel", "GYRO", "ImuNoise", "GyroYaw", "discrete_sigma", "body_yaw_rate", "gyro_yaw", "gated_yaw_rate",
           "running_median"]
