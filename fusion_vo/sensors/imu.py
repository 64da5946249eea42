"""IMU: gyro yaw rate with bias, AHRS heading and the slope correction of travelled distance.

Gyro
----
The body yaw rate is the body-z component of the IMU's rate rotated into the body frame::

    ω_B = R_BS ω_S,      ω_z = (R_BS ω_S)_z = ω + b_g + n

with a bias ``b_g`` that the backends estimate (random walk, ``σ_bw`` = ``gyroscope_random_walk``
[rad/s²/√Hz]) and white noise of density ``σ_g`` = ``gyroscope_noise_density`` [rad/s/√Hz]. At sample
rate ``f`` one sample has standard deviation ``σ_g √f``; the mean rate over an interval ``Δt`` has
variance ``σ_g² / Δt`` and the integrated angle ``σ_g² Δt``.

At rest the gyro measures only its own noise: no driving vibration, no true rate. A recorded density
(e.g. from a ROS message's covariance) that includes the vibration, or is merely conservative, makes
the zero-velocity update (:mod:`fusion_vo.sensors.wheel`) fix the bias less than the samples at rest
allow; ``gyro_rest_noise_density``, when set, is used instead for the intervals in which the wheels
report rest (:func:`rest_noise_density` measures it from such samples). It is not measured by default
(``docs/decisions/0025-gyro-rest-noise-density-off.md``).

Spikes (an impossible sample) are found against a running median: a sample further than ``spike_threshold``
from the median of its ``2w+1`` neighbours, or above ``max_rate``, or not finite, is gated (counted) and
replaced by the median so integration carries on. The rate, its gating and the noise section are in
:mod:`fusion_vo.sensors.gyro`.

AHRS
----
An orientation quaternion ``q_WS`` of the IMU gives the body orientation ``R_WB = R_WS R_BSᵀ``; its
heading ``atan2(R_WB[1,0], R_WB[0,0])`` is an absolute yaw measurement (relative to the AHRS's own
north, aligned to the estimate by the first sample) up to an offset that wanders slowly
(``ahrs_offset_walk``; the backends estimate it). On a slope the body axes leave the horizontal
plane; body-frame travel ``(d_x, d_y)`` projects to the floor plan by the horizontal lengths of the body
axes, ``c_x = ‖(R_WB[0,0], R_WB[1,0])‖`` and ``c_y = ‖(R_WB[0,1], R_WB[1,1])‖``.

The accelerometer is not needed by the planar backends; :func:`tilt_from_accel` gives roll and pitch
from gravity when no AHRS orientation is recorded.
"""

from __future__ import annotations

import logging
import math
import dataclasses
from dataclasses import dataclass

import numpy as np

from fusion_vo.config.sensor_files import ImuFile
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.measurements import ImuData, ImuSample, MAX_ACCELERATION, MAX_ANGULAR_RATE
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import coverage, ordered_fields
from fusion_vo.recording.csvio import check_magnitude, unit_quaternions
from fusion_vo.sensors.gyro import (GYRO, GyroModel, GyroYaw, ImuNoise, body_yaw_rate, discrete_sigma, gated_yaw_rate,
                                    gyro_yaw, running_median)
from fusion_vo.sensors.model import MeasurementModel
from fusion_vo.sensors.readings import ORDER, Readings
from fusion_vo.sensors.registry import Carry, HeadingSource, Live, Sensor, State, Step, register
from fusion_vo.sensors.visual import FIRST_GUESS_INTERVALS, camera_heading_reference
from fusion_vo.sensors.wheel import at_rest
from fusion_vo.sensors.wheel_arc import wheel_motion

logger = logging.getLogger(__name__)


#: fewest gyro samples at rest (about 2 s at 30 Hz) for :func:`rest_noise_density`: the relative error of a
#: standard deviation from ``n`` samples is about ``1/√(2n)``, 9 % here
REST_MIN_SAMPLES = 60


def rest_noise_density(gyro: GyroYaw, at_rest: np.ndarray, min_samples: int = REST_MIN_SAMPLES) -> float | None:
    """White noise density [rad/s/√Hz] of the gyro measured at rest, or None with too few samples.

    Parameters
    ----------
    gyro : GyroYaw
        Body yaw rates (gated samples are left out).
    at_rest : ndarray (N,) bool
        The samples taken while the robot stood still (its true rate is zero: the gyro reads its bias
        plus its noise).
    min_samples : int
        Fewest samples at rest needed.

    Returns
    -------
    float or None
        The robust standard deviation (1.4826 times the median absolute deviation) of the samples about
        the median of their own standstill (the bias may differ between standstills), times
        ``1/√f`` at the gyro's sample rate ``f``. This is the density of white noise; the samples at rest
        of robot_localization's Husky log are white (their means over 0.03 to 2 s shrink as ``1/√n``).
    """
    at_rest = np.asarray(at_rest, bool) & ~gyro.gated
    if np.count_nonzero(at_rest) < min_samples or len(gyro.t) < 2:
        return None
    edges = np.diff(np.concatenate([[0], at_rest.astype(np.int8), [0]]))
    residuals = [gyro.rate[a:b] - np.median(gyro.rate[a:b])
                 for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)) if b - a >= 3]
    if not residuals or sum(len(r) for r in residuals) < min_samples:
        return None
    r = np.concatenate(residuals)
    sigma = 1.4826 * float(np.median(np.abs(r)))
    rate_hz = 1.0 / float(np.median(np.diff(gyro.t)))
    return sigma / math.sqrt(rate_hz) if sigma > 0 else None


def cumulative_angle(gyro: GyroYaw) -> np.ndarray:
    """Trapezoidal integral of the yaw rate from the first sample [rad] (N,)."""
    if len(gyro.t) == 0:
        return np.zeros(0)
    seg = 0.5 * (gyro.rate[1:] + gyro.rate[:-1]) * np.diff(gyro.t)
    return np.concatenate([[0.0], np.cumsum(seg)])


# --------------------------------------------------------------------------- orientation
def quat_to_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    """Rotation matrices (N x 3 x 3) of unit quaternions ``(w, x, y, z)`` (N x 4); normalises them."""
    q = np.asarray(q_wxyz, dtype=np.float64).reshape(-1, 4)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1),
    ], axis=1)


@dataclass
class AhrsHeading:
    """Body heading and slope factors from the AHRS orientation.

    ``t`` (N,), ``yaw`` (N,) body heading in the AHRS world [rad], ``cx``, ``cy`` (N,) horizontal
    lengths of the body x and y axes, ``valid`` (N,) bool (finite, unit-norm quaternion).
    """

    t: np.ndarray
    yaw: np.ndarray
    cx: np.ndarray
    cy: np.ndarray
    valid: np.ndarray


def ahrs_heading(data: ImuData) -> AhrsHeading | None:
    """Heading and slope factors of the body from the AHRS columns, or None when not recorded."""
    if data.orientation is None:
        return None
    q = np.asarray(data.orientation, dtype=np.float64)
    norm = np.linalg.norm(q, axis=1)
    valid = np.all(np.isfinite(q), axis=1) & (np.abs(norm - 1.0) < 0.1)
    q = np.where(valid[:, None], q, [1.0, 0.0, 0.0, 0.0])
    r_wb = quat_to_matrix(q) @ np.asarray(data.T_BS, dtype=np.float64)[:3, :3].T
    yaw = np.arctan2(r_wb[:, 1, 0], r_wb[:, 0, 0])
    cx = np.hypot(r_wb[:, 0, 0], r_wb[:, 1, 0])
    cy = np.hypot(r_wb[:, 0, 1], r_wb[:, 1, 1])
    return AhrsHeading(np.asarray(data.t, dtype=np.float64), yaw, cx, cy, valid)


def tilt_from_accel(accel: np.ndarray, T_BS: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Roll and pitch [rad] of the body from the gravity direction of accelerometer samples (N x 3).

    Valid when the robot does not accelerate much; returns ``(roll, pitch)`` arrays.
    """
    a = np.asarray(accel, dtype=np.float64).reshape(-1, 3)
    if T_BS is not None:
        a = a @ np.asarray(T_BS, dtype=np.float64)[:3, :3].T
    roll = np.arctan2(a[:, 1], a[:, 2])
    pitch = np.arctan2(-a[:, 0], np.hypot(a[:, 1], a[:, 2]))
    return roll, pitch


__all__ = [
    "ImuNoise", "GyroYaw", "GyroModel", "GYRO", "AhrsHeading", "discrete_sigma", "body_yaw_rate", "gyro_yaw",
    "gated_yaw_rate", "running_median", "rest_noise_density", "REST_MIN_SAMPLES",
    "cumulative_angle", "quat_to_matrix", "ahrs_heading", "tilt_from_accel",
]


# --------------------------------------------------------------------------- measurement models
@dataclass(frozen=True)
class AhrsModel(MeasurementModel):
    """The AHRS heading: ``z = ψ_AHRS``, ``h(ψ, o_ψ) = ψ + o_ψ`` (wrapped), ``R = σ_ψ²``; both Jacobians 1.

    Arguments ``heading``, ``ahrs_offset`` (an AHRS trusted as absolute has its offset fixed at 0).
    """

    name: str = "ahrs"
    linear: bool = True
    args: tuple = ("heading", "ahrs_offset")
    dim: int = 1
    angle_rows: tuple = (0,)

    def identity(self, fixed: dict) -> bool:
        return fixed.get("ahrs_offset") == 0.0

    def evaluate(self, heading, ahrs_offset):
        psi = np.asarray(heading, dtype=np.float64)
        o = np.asarray(ahrs_offset, dtype=np.float64)
        h = psi + o
        if h.ndim == 1:
            return h, {"heading": np.array([[1.0]]), "ahrs_offset": np.array([[1.0]])}
        one = np.ones(h.shape[:-1] + (1, 1))
        return h, {"heading": one, "ahrs_offset": one.copy()}


AHRS = AhrsModel()


# --------------------------------------------------------------------------- on the node grid
@dataclass
class ImuGrid:
    """The IMU's measurements on the node grid (``Intervals.sensors["imu"]``, :func:`imu_grid`).

    ``gyro_ok, gyro_angle`` (K,): where the gyro covers each node interval and its integrated body yaw
    rate over it [rad]; ``ahrs_ok, ahrs_yaw`` (K+1,): the AHRS heading at the nodes [rad], aligned so that the
    first one is the initial yaw (the offset is carried, ``Intervals.carry["imu"]``).
    """

    gyro_ok: np.ndarray
    gyro_angle: np.ndarray
    ahrs_ok: np.ndarray
    ahrs_yaw: np.ndarray

    @classmethod
    def empty(cls, n_steps: int, config=None) -> "ImuGrid":
        return cls(np.zeros(n_steps, bool), np.zeros(n_steps), np.zeros(n_steps + 1, bool), np.zeros(n_steps + 1))


def imu_grid(iv) -> ImuGrid:
    """The IMU's measurements on the node grid ``iv`` (an :class:`~fusion_vo.backends.timeline.Intervals`)."""
    return iv.sensors["imu"]


# --------------------------------------------------------------------------- registration
#: the AHRS's first samples [s] whose headings, carried to the first node by the gyro, are averaged into the offset
#: between AHRS north and the initial heading (:func:`add_intervals`)
AHRS_OFFSET_WINDOW = 0.25


def add_intervals(iv, streams, config, counts) -> None:
    """The gyro's integrated angle per node interval (:class:`ImuGrid` ``gyro_ok, gyro_angle``) and, with an AHRS
    orientation, its heading at the nodes aligned to the initial heading (``ahrs_ok, ahrs_yaw``; the offset
    ``Intervals.carry["imu"]``, found at the first AHRS sample, :data:`CARRY`) and the slope factors
    ``Intervals.cx, cy``."""

    imu, grid = streams.imu, imu_grid(iv)
    count = counts.setdefault("gyro", SensorCount())
    imu = ordered_fields(imu, ("gyro", "accel", "orientation"), count)
    gyro = gyro_yaw(imu, config.imu.with_sensor_keys(imu.noise))
    count.gated += gyro.n_gated
    T = iv.t
    ok = coverage(gyro.t, np.zeros(max(len(gyro.t) - 1, 0), bool), T, config.max_gap)
    theta = np.interp(T, gyro.t, cumulative_angle(gyro)) if len(gyro.t) else np.zeros(len(T))
    grid.gyro_ok, grid.gyro_angle = ok, np.diff(theta)
    count.used += int(ok.sum())
    count.missing += int((~ok).sum())
    heading = ahrs_heading(imu)
    if heading is None:
        return
    acount = counts.setdefault("ahrs", SensorCount())
    acount.gated += int((~heading.valid).sum())
    ht = heading.t[heading.valid]
    if len(ht) < 2:
        return
    yaw = np.unwrap(heading.yaw[heading.valid])
    near = np.abs(ht[np.clip(np.searchsorted(ht, T), 0, len(ht) - 1)] - T) <= config.max_gap
    ok_n = (T >= ht[0]) & (T <= ht[-1]) & near
    if not ok_n.any():
        return
    yaw_t = np.interp(T, ht, yaw)
    offset = iv.carry.get("imu")
    if offset is None:
        # AHRS north vs. the estimate's initial heading, averaged over the samples of the first
        # quarter second with the gyro carrying the heading (one noisy sample would bias all headings)
        first = int(np.argmax(ok_n))
        window = (ht >= T[first] - 1e-9) & (ht <= T[first] + AHRS_OFFSET_WINDOW)
        gyro_heading = np.zeros(int(window.sum()))
        if len(gyro.t):
            angle = cumulative_angle(gyro)
            gyro_heading = np.interp(ht[window], gyro.t, angle) - np.interp(T[first], gyro.t, angle)
        diffs = se2.wrap_angle(yaw[window] - yaw_t[first] - gyro_heading)
        mean = float(np.mean(diffs)) if len(diffs) else 0.0
        offset = iv.carry["imu"] = float(yaw_t[first] + mean - float(config.initial_pose[2]))
    grid.ahrs_ok = ok_n
    grid.ahrs_yaw = se2.wrap_angle(yaw_t - offset)
    acount.used += int(ok_n.sum())
    mid = 0.5 * (T[:-1] + T[1:])
    iv.cx = np.interp(mid, ht, heading.cx[heading.valid])
    iv.cy = np.interp(mid, ht, heading.cy[heading.valid])


def readings(iv, config) -> list[Readings]:
    """The gyro's integrated angle per interval (``σ_g² Δt``, ``σ_rest`` where the wheels are at rest; gated
    upstream, so not robust) and the AHRS heading at the nodes (``σ_ψ²``)."""
    out, grid = [], imu_grid(iv)
    if iv.uses("gyro"):
        k = np.flatnonzero(grid.gyro_ok)
        var = GYRO.variance(config.imu.density(at_rest(iv, config)), iv.dt)
        out.append(Readings("gyro", GYRO, k, k + 1, grid.gyro_angle[k], var[k], robust=False, order=ORDER["gyro"]))
    if grid.ahrs_ok.any():
        n = np.flatnonzero(grid.ahrs_ok)
        out.append(Readings("ahrs", AHRS, n, n, grid.ahrs_yaw[n], config.imu.ahrs_yaw_sigma**2, order=ORDER["ahrs"]))
    return out


def has_heading(iv) -> bool:
    """Whether the AHRS gives headings on the grid ``iv`` (a heading reference: ``Sensor.absolute_heading``)."""
    return bool(imu_grid(iv).ahrs_ok.any())


def _live_sample(m) -> tuple:
    """A live :class:`~fusion_vo.measurements.ImuSample`: ``(t, (gyro, accel, orientation or None))``."""
    q = None if m.orientation is None else np.asarray(m.orientation, dtype=np.float64)
    return m.t, (np.asarray(m.gyro, dtype=np.float64), np.asarray(m.accel, dtype=np.float64), q)


def _live_data(t, rows, fusion) -> ImuData:
    q = [r[2] for r in rows]
    return ImuData(t, np.array([r[0] for r in rows]), np.array([r[1] for r in rows]),
                   None if any(x is None for x in q) else np.array(q), fusion.imu_T_BS, None, fusion.imu_noise)


def _gyro_bias(state: State, context) -> State:
    """``b_g``: estimated with the gyro, its prior and random walk from the ``imu`` section."""
    imu = context.config.imu
    return dataclasses.replace(state, sigma=imu.gyro_bias_sigma, random_walk=imu.gyro_random_walk,
                               estimated="gyro" in context.used)


def _ahrs_offset(state: State, context) -> State:
    """``o_ψ``: estimated with AHRS headings when the ``imu`` section gives it a random walk (else the AHRS is
    an absolute heading, held at offset 0), its prior the AHRS heading's σ."""
    imu = context.config.imu
    return dataclasses.replace(state, sigma=imu.ahrs_yaw_sigma, random_walk=imu.ahrs_offset_walk,
                               estimated="ahrs" in context.used and imu.ahrs_offset_walk > 0)


#: the gyro's bias ``b_g`` [rad/s] (:class:`GyroModel`) and the AHRS heading's offset ``o_ψ`` [rad]
#: (:class:`AhrsModel`), states of every run
GYRO_BIAS = State("gyro_bias", symbol="b", rule=_gyro_bias)
AHRS_OFFSET = State("ahrs_offset", symbol="o", rule=_ahrs_offset)

# --------------------------------------------------------------------------- its headings, for the monitor
def _gyro_change(iv, config):
    """The gyro's integrated angle per interval (its bias in it) and its white noise's variance."""
    if not iv.uses("gyro"):
        return None
    imu = imu_grid(iv)
    return imu.gyro_ok.copy(), imu.gyro_angle, config.imu.gyro_noise_density**2 * iv.dt


def _gyro_drop(iv, bad, agrees) -> None:
    imu = imu_grid(iv)
    imu.gyro_ok = imu.gyro_ok & ~bad


def _gyro_clear(iv) -> None:
    imu_grid(iv).gyro_ok = np.zeros(iv.n_steps, bool)


def _ahrs_change(iv, config):
    """The AHRS heading's change per interval (wrapped), where it has headings at both nodes."""
    imu = imu_grid(iv)
    if not imu.ahrs_ok.any():
        return None
    ok = imu.ahrs_ok[:-1] & imu.ahrs_ok[1:]
    return ok, np.angle(np.exp(1j * (imu.ahrs_yaw[1:] - imu.ahrs_yaw[:-1]))), np.zeros(len(iv.dt))


def _ahrs_window(iv, config):
    """Over ``span`` seconds the AHRS heading's change has its two ends' noise and its offset's walk."""
    sigma, walk = config.imu.ahrs_yaw_sigma, config.imu.ahrs_offset_walk
    return lambda span, theta: 2.0 * sigma**2 + walk**2 * span


def _ahrs_drop(iv, bad, agrees) -> None:
    imu = imu_grid(iv)
    drop = np.zeros(len(iv.t), bool)
    drop[1:] |= bad
    imu.ahrs_ok = imu.ahrs_ok & ~drop


def _ahrs_clear(iv) -> None:
    imu_grid(iv).ahrs_ok = np.zeros(len(iv.t), bool)


def _ahrs_reference_error(iv, config, ok, var) -> float:
    """The error of the AHRS heading changes summed where ``ok``: its two ends' noise per run of them, and its
    offset's walk over the time summed."""
    runs = int(np.count_nonzero(np.diff(np.concatenate(([0], ok.astype(np.int8)))) == 1))
    return runs * 2.0 * config.imu.ahrs_yaw_sigma**2 + config.imu.ahrs_offset_walk**2 * float(np.sum(iv.dt[ok]))


#: the gyro's yaw rate, whose constant bias the monitor removes first
GYRO_HEADING = HeadingSource(
    "gyro", "gyro yaw rate", rank=10, change=_gyro_change, drop=_gyro_drop, biased=True,
    window=lambda iv, config: lambda span, theta: (config.monitor_bias_sigma * span) ** 2,
    kept=lambda iv: imu_grid(iv).gyro_ok, clear=_gyro_clear)
#: the AHRS heading, an absolute one
AHRS_HEADING = HeadingSource(
    "ahrs", "AHRS heading", rank=30, change=_ahrs_change, drop=_ahrs_drop, window=_ahrs_window, absolute=True,
    heading=lambda iv: (imu_grid(iv).ahrs_ok, imu_grid(iv).ahrs_yaw), kept=lambda iv: imu_grid(iv).ahrs_ok[1:],
    clear=_ahrs_clear, reference=0, reference_error=_ahrs_reference_error)


def _ahrs_ahead(rows: list) -> float:
    """While the AHRS's offset is not found: the samples of :data:`AHRS_OFFSET_WINDOW` after an interval's start
    that it is averaged over, when the buffered samples ``rows`` carry orientations."""
    return AHRS_OFFSET_WINDOW if rows and rows[-1][1][2] is not None else 0.0


def _turn_ahrs(iv, yaw: float) -> None:
    """The AHRS headings at the nodes once the world frame is turned by ``yaw`` (they were aligned to the
    configured initial heading, which the turn moves)."""
    grid = imu_grid(iv)
    if grid.ahrs_ok.any():
        grid.ahrs_yaw = se2.wrap_angle(grid.ahrs_yaw + yaw)


#: the offset between AHRS north and the initial heading, found once and kept (``Intervals.carry["imu"]``)
CARRY = Carry(turn=lambda offset, yaw: float(offset - yaw), ahead=_ahrs_ahead)


def _live_samples(data: ImuData) -> list:
    """Recorded IMU rows as live samples (with the AHRS orientation when recorded)."""
    q = data.orientation if data.orientation is not None else [None] * len(data.t)
    return [(t, ImuSample(t, g, a, o)) for t, g, a, o in zip(data.t, data.gyro, data.accel, q)]


# --------------------------------------------------------------------------- its stream in a recording
def read_imu(recording, folder: str = "imu0") -> ImuData:
    """``imu0/data.csv`` of a recording (or another IMU's ``folder``, ``imu1`` ...): gyro, accelerometer and (when the
    4 extra columns are present) an AHRS orientation, with the mounting, noise and rate of :func:`imu_calibration`.

    Rows are ``timestamp [ns], gyro x y z [rad/s], accel x y z [m/s²][, w x y z]``, checked by
    :meth:`fusion_vo.recording.Recording.table` (and each rate and acceleration against its physical range,
    each quaternion's norm against 1)."""
    tab, path = recording.table(folder, (6, 10), "IMU", "IMU values", min_rows=2)
    if tab.values.shape[1] not in (6, 10):
        raise InputError("expected 6 IMU columns (gyro xyz, accel xyz) or 10 (plus a quaternion w,x,y,z)", path,
                         int(tab.lines[0]))
    check_magnitude(tab, path, slice(0, 3), MAX_ANGULAR_RATE, "angular rate [rad/s]")
    check_magnitude(tab, path, slice(3, 6), MAX_ACCELERATION, "acceleration [m/s²]")
    orient = None
    if tab.values.shape[1] == 10:
        orient = unit_quaternions(tab.values[:, 6:10], tab.lines, path, "orientation quaternion")
    T, noise, rate = imu_calibration(recording, folder)
    return ImuData(tab.t, tab.values[:, 0:3], tab.values[:, 3:6], orient, T, rate, noise)


def imu_calibration(recording, folder: str = "imu0") -> tuple[np.ndarray, dict, float | None]:
    """``(T_BS, noise, rate_hz)`` of ``imu0/sensor.yaml`` (or ``folder``'s, required): the IMU's pose in the body
    frame (identity without ``T_BS``), its EuRoC noise keys that are given, and its rate. A default taken is warned
    about once, naming the file."""
    imu = recording.sensor_file(folder, ImuFile, required=True)  # never assumed without a word
    T, noise = imu.pose(np.eye(4)), imu.noise()
    recording.warn_defaults(folder, ([] if imu.T_BS is not None else
                                     ["no T_BS: the IMU is taken as aligned with the body (identity)"])
                            + ([] if noise else ["no noise keys: the configuration's IMU noise is used"]))
    return T, noise, imu.rate_hz


def _gyro_motion(iv, motion: np.ndarray) -> np.ndarray:
    """The IMU's :attr:`~fusion_vo.sensors.registry.Sensor.motion` step: the gyro's integrated turn replaces the
    heading change of each node interval whose motion is known and whose gyro is used."""
    imu = imu_grid(iv)
    if not iv.uses("gyro"):
        return motion
    out = motion.copy()
    turn = imu.gyro_ok & np.isfinite(out[:, 2])
    out[turn, 2] = imu.gyro_angle[turn]
    return out


def _first_gyro_bias(iv, guesses: dict) -> dict:
    """The gyro bias's first guess: ``b = Σ (θ_gyro - θ_ref) / Σ Δt`` over the intervals both cover (more than
    :data:`~fusion_vo.sensors.visual.FIRST_GUESS_INTERVALS`), the reference heading change the camera's
    (:func:`~fusion_vo.sensors.visual.camera_heading_reference`), else the wheels'."""
    ref = camera_heading_reference(iv)
    if ref is None:
        ref, _ = wheel_motion(iv)
    if not iv.uses("gyro") or ref is None:
        return {}
    imu = imu_grid(iv)
    ok = imu.gyro_ok & np.isfinite(ref)
    if ok.sum() <= FIRST_GUESS_INTERVALS:
        return {}
    return {"gyro_bias": float(np.sum(imu.gyro_angle[ok] - ref[ok]) / np.sum(iv.dt[ok]))}


register(Sensor(
    name="imu", where="imu0/", field="imu", min_samples=2, folder="imu0",
    read=read_imu, config=("imu", ImuNoise),
    grid=ImuGrid.empty, intervals=Step(10, add_intervals), readings=readings, states=(GYRO_BIAS, AHRS_OFFSET),
    carry=CARRY, turn=_turn_ahrs,
    coverage=lambda iv: ("gyro", imu_grid(iv).gyro_ok), absolute_heading=lambda iv: iv.uses("gyro") or has_heading(iv),
    heading_reference=lambda data: data is not None and data.orientation is not None,
    live=Live(_live_sample, _live_data, neighbours=lambda config: int(config.imu.spike_window) + 1, counted_as="gyro",
              also_counted=("ahrs",), samples=_live_samples, order=2),
    heading=(GYRO_HEADING, AHRS_HEADING), first_guesses=Step(10, _first_gyro_bias), motion=Step(20, _gyro_motion),
))
