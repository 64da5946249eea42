"""Differential-drive wheel odometry: encoder ticks -> wheel travel -> planar increments.

Ticks
-----
Encoder counters are signed 32-bit and may wrap. Between two rows the count change is taken modulo
``2^32`` into ``[-2^31, 2^31)``, so a wrap is invisible in the result::

    Δn = ((n_k - n_{k-1} + 2^31) mod 2^32) - 2^31
    d  = Δn / ticks_per_revolution · 2π r                 (wheel travel [m])

A change that would need a speed above ``max_speed`` is a glitch (a counter reset, a bit error); it is
*gated*: the interval gets no travel, is flagged invalid and is counted.

Arc model, noise model, odometry twist, standstill
--------------------------------------------------
In :mod:`fusion_vo.sensors.wheel_arc` (:class:`WheelNoise`, :func:`arc_increment`, :func:`arc_covariance`, ...).
"""

from __future__ import annotations

import dataclasses
import logging
import math
from dataclasses import dataclass

import numpy as np

from fusion_vo.config.sensor_files import WheelFile
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.measurements import (MAX_ANGULAR_RATE, MAX_SPEED, PoseData, TwistData, TwistSample, WheelConfig,
                                    WheelData, WheelTicks)
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import coverage, ordered_fields
from fusion_vo.recording.csvio import check_magnitude
from fusion_vo.sensors.gyro import gyro_yaw
from fusion_vo.sensors.model import MeasurementModel, scaled_motion
from fusion_vo.sensors.readings import ORDER, Readings
from fusion_vo.sensors.registry import (ClockOffset, DistanceSource, HeadingSource, Live, Sensor, Step, register,
                                        sensors as registered_sensors)
from fusion_vo.sensors.sync import TwistClock, odometry_delay
from fusion_vo.sensors.wheel_arc import (  # noqa: F401 (the arc model and noise, here too)
    WheelNoise, arc_covariance, arc_increment, arc_twist, odom_twist_noise, skid_variance, standstill,
    travel_variances,
)
from fusion_vo.sensors.wheel_states import (CURVATURE, WHEEL_BASE_FACTOR, WHEEL_SCALE, curvature_observable,
                                            curvature_states, first_wheel_base_factor)

logger = logging.getLogger(__name__)

_WRAP = 2**32
_HALF = 2**31


@dataclass
class WheelTravel:
    """Cumulative wheel travel after unwrapping and gating.

    Attributes
    ----------
    t : ndarray (N,)
        Sample times [s].
    left, right : ndarray (N,)
        Cumulative travel of each wheel since the first sample [m] (gated intervals add nothing).
    valid : ndarray (N-1,) bool
        False for the intervals that were gated.
    wheel_base : float
        Configured wheel base [m].
    n_gated : int
        Number of gated intervals.
    """

    t: np.ndarray
    left: np.ndarray
    right: np.ndarray
    valid: np.ndarray
    wheel_base: float
    n_gated: int = 0


def unwrap_ticks(ticks) -> np.ndarray:
    """Unwrap a signed 32-bit cumulative counter into a continuous int64 count (starting at its first value)."""
    n = np.asarray(ticks, dtype=np.int64)
    if len(n) == 0:
        return n.copy()
    diff = (np.diff(n) + _HALF) % _WRAP - _HALF
    return n[0] + np.concatenate([[0], np.cumsum(diff)])


def ticks_to_travel(data: WheelData, noise: WheelNoise | None = None) -> WheelTravel:
    """Unwrap the counters of ``data``, convert to metres and gate impossible jumps.

    Parameters
    ----------
    data : WheelData
        Times and cumulative counts as recorded.
    noise : WheelNoise, optional
        Provides ``max_speed`` for the gate.
    """
    noise = noise or WheelNoise()
    cfg = data.config
    t = np.asarray(data.t, dtype=np.float64)
    per_tick_l = 2.0 * math.pi * cfg.wheel_radius_left / cfg.ticks_per_revolution
    per_tick_r = 2.0 * math.pi * cfg.wheel_radius_right / cfg.ticks_per_revolution
    dl = np.diff(unwrap_ticks(data.left)).astype(np.float64) * per_tick_l
    dr = np.diff(unwrap_ticks(data.right)).astype(np.float64) * per_tick_r
    dt = np.diff(t)
    limit = noise.max_speed * np.maximum(dt, 1e-3) + 2.0 * max(per_tick_l, per_tick_r)
    valid = (np.abs(dl) <= limit) & (np.abs(dr) <= limit) & (dt > 0)
    n_gated = int(np.count_nonzero(~valid))
    if n_gated:
        logger.info("wheel: gated %d encoder jumps above %.1f m/s", n_gated, noise.max_speed)
    dl = np.where(valid, dl, 0.0)
    dr = np.where(valid, dr, 0.0)
    left = np.concatenate([[0.0], np.cumsum(dl)])
    right = np.concatenate([[0.0], np.cumsum(dr)])
    return WheelTravel(t, left, right, valid, float(cfg.wheel_base), n_gated)


def twist_to_travel(data: TwistData, wheel_base: float = 0.5, max_speed: float = 5.0) -> WheelTravel:
    """Express an odometry twist stream as equivalent cumulative wheel travel.

    The twist ``(v_x, ω)`` held over each sample interval (zero-order hold of the earlier sample) is
    turned into ``d_l = (v_x - ω b/2) Δt``, ``d_r = (v_x + ω b/2) Δt`` for a nominal base ``b``, so the
    same interval integration and noise model serve both ``wheel0`` and ``odom0``. ``v_y`` of a
    differential drive is zero and is ignored. Samples with NaN or speeds above ``max_speed`` are gated.
    """
    t = np.asarray(data.t, dtype=np.float64)
    vx = np.asarray(data.vx, dtype=np.float64)[:-1]
    wz = np.asarray(data.wz, dtype=np.float64)[:-1]
    dt = np.diff(t)
    valid = np.isfinite(vx) & np.isfinite(wz) & (np.abs(vx) + np.abs(wz) * wheel_base / 2 <= max_speed) & (dt > 0)
    dl = np.where(valid, (vx - wz * wheel_base / 2) * dt, 0.0)
    dr = np.where(valid, (vx + wz * wheel_base / 2) * dt, 0.0)
    return WheelTravel(t, np.concatenate([[0.0], np.cumsum(dl)]), np.concatenate([[0.0], np.cumsum(dr)]),
                       valid, float(wheel_base), int(np.count_nonzero(~valid)))


# --------------------------------------------------------------------------- measurement models
@dataclass(frozen=True)
class WheelModel(MeasurementModel):
    """The wheels' arc increment as a measurement of the body motion, with their calibration.

    ``z = (d, 0, θ)`` of the arc model (:func:`arc_increment`; the EKF uses its twist ``(d, 0, θ)/Δt``,
    :func:`arc_twist`), ``h(δ, k_r, k_b) = (k_r d_x, k_r d_y, k_b d_ψ)`` with the distance scale
    ``k_r = r_configured / r_true`` and the wheel-base factor ``k_b = b_true / b_configured``; noise
    :func:`arc_covariance` (:func:`arc_twist` per unit time). Jacobians ``∂h/∂δ = diag(k_r, k_r, k_b)``,
    ``∂h/∂k_r = (d_x, d_y, 0)ᵀ``, ``∂h/∂k_b = (0, 0, d_ψ)ᵀ``.
    Arguments ``motion``, ``wheel_scale``, ``wheel_base_factor``.
    """

    name: str = "wheel"
    args: tuple = ("motion", "wheel_scale", "wheel_base_factor")
    dim: int = 3
    turn_rows: tuple = (2,)
    increment: bool = True
    guess_rank: tuple = (1, 1)

    def identity(self, fixed: dict) -> bool:
        return all(fixed.get(name) == 1.0 for name in ("wheel_scale", "wheel_base_factor")) and \
            fixed.get("wheel_curvature", 0.0) == 0.0

    def guess(self, z, estimate: dict, dt: float):
        """The arc in the running radius and wheel-base estimates' units."""
        return (np.asarray(z[:2]) / estimate.get("wheel_scale", 1.0),
                float(z[2]) / estimate.get("wheel_base_factor", 1.0))

    def evaluate(self, motion, wheel_scale, wheel_base_factor):
        h, j_d, j_r, j_b = scaled_motion(motion, wheel_scale, wheel_base_factor)
        return h, {"motion": j_d, "wheel_scale": j_r, "wheel_base_factor": j_b}


@dataclass(frozen=True)
class StandstillModel(MeasurementModel):
    """Wheels at rest over an interval (:func:`standstill`): the heading change is zero.

    ``z = 0``, ``h(δ) = d_ψ``, ``σ = standstill_yaw_rate Δt`` (per unit time: the yaw rate, ``σ`` =
    ``standstill_yaw_rate``); ``∂h/∂δ = (0, 0, 1)``. Argument ``motion``.
    """

    name: str = "standstill"
    linear: bool = True
    args: tuple = ("motion",)
    dim: int = 1
    turn_rows: tuple = (0,)

    def evaluate(self, motion):
        d = np.asarray(motion, dtype=np.float64)
        if d.ndim == 1:
            return np.array([float(d[2])]), {"motion": np.array([[0.0, 0.0, 1.0]])}
        j = np.zeros(d.shape[:-1] + (1, 3))
        j[..., 0, 2] = 1.0
        return d[..., 2:3].copy(), {"motion": j}


@dataclass(frozen=True)
class CurvedWheelModel(WheelModel):
    """:class:`WheelModel` with unequal left and right radius errors (UMBmark's type A error), through the
    wheels' curvature bias ``c`` [rad/m].

    With per-wheel scales ``s_l, s_r`` (reported travel over rolled travel, ``r_configured / r_true`` of
    each wheel), configured base ``b`` and true base ``b_t``, a body motion of arc length ``d`` and turn
    ``θ`` rolls ``d ∓ θ b_t / 2`` and the wheels report::

        d_reported = k_r d + (c b² k_b / (4 k_r)) θ,    θ_reported = k_b θ + c d

    with ``k_r = (s_l + s_r) / 2``, ``k_b = k_r b_t / b`` and ``c = (s_r - s_l) / b``: the wheels report a
    turn ``c`` per metre driven that the body did not make, and, turning, a forward travel ``c b² / 4``
    per radian (the faster wheel's excess over the slower one's), exactly, whatever the motion. So
    ``h(δ, k_r, k_b, c) = (k_r d_x + q c d_ψ, k_r d_y, k_b d_ψ + c d_x)`` with ``q = b² k_b / (4 k_r)``;
    Jacobians as :class:`WheelModel`'s plus ``∂h_x/∂d_ψ = q c``, ``∂h_x/∂k_r = d_x - q c d_ψ / k_r``,
    ``∂h_x/∂k_b = q c d_ψ / k_b``, ``∂h_ψ/∂d_x = c`` and ``∂h/∂c = (q d_ψ, 0, d_x)ᵀ``. With relative radius
    errors ``ε_l, ε_r`` (true radius ``r (1 + ε)``), ``c ≈ (ε_l - ε_r) / b``; its prior
    (:data:`~fusion_vo.sensors.wheel_states.CURVATURE`) has mean 0 and ``σ_c = √2 σ_ε / b`` for independent per-wheel errors of standard deviation ``σ_ε``
    (``radius_sigma / radius`` of ``wheel0/sensor.yaml``, else ``wheel_scale_sigma``). Constant over the
    run: a tyre's radius changes with wear and load over hours, not within a recording.
    Arguments ``motion``, ``wheel_scale``, ``wheel_base_factor``, ``wheel_curvature``; parameter
    ``wheel_base`` (the configured ``b`` [m]).
    """

    args: tuple = ("motion", "wheel_scale", "wheel_base_factor", "wheel_curvature")

    def evaluate(self, motion, wheel_scale, wheel_base_factor, wheel_curvature, wheel_base):
        h, j_d, j_r, j_b = scaled_motion(motion, wheel_scale, wheel_base_factor)
        d = np.asarray(motion, dtype=np.float64)
        if d.ndim == 1:
            c = float(np.asarray(wheel_curvature, dtype=np.float64).reshape(-1)[0])
            k_r = float(np.asarray(wheel_scale, dtype=np.float64).reshape(-1)[0])
            k_b = float(np.asarray(wheel_base_factor, dtype=np.float64).reshape(-1)[0])
            b = float(np.asarray(wheel_base, dtype=np.float64).reshape(-1)[0])
        else:
            c = np.asarray(wheel_curvature, dtype=np.float64)[..., 0]
            k_r = np.asarray(wheel_scale, dtype=np.float64)[..., 0]
            k_b = np.asarray(wheel_base_factor, dtype=np.float64)[..., 0]
            b = np.broadcast_to(np.asarray(wheel_base, dtype=np.float64), c.shape)
        q = 0.25 * b**2 * k_b / k_r
        turn = q * c * d[..., 2]  # forward travel the radius difference reports while turning
        h[..., 0] += turn
        h[..., 2] += c * d[..., 0]
        j_d[..., 0, 2] += q * c
        j_d[..., 2, 0] += c
        j_r[..., 0, 0] -= turn / k_r
        j_b[..., 0, 0] += turn / k_b
        j_c = np.zeros(d.shape[:-1] + (3, 1))
        j_c[..., 0, 0] = q * d[..., 2]
        j_c[..., 2, 0] = d[..., 0]
        return h, {"motion": j_d, "wheel_scale": j_r, "wheel_base_factor": j_b, "wheel_curvature": j_c}


WHEEL = WheelModel()
CURVED_WHEEL = CurvedWheelModel()
STANDSTILL = StandstillModel()
def wheel_model(states) -> WheelModel:
    """The wheel model with the curvature bias when ``wheel_curvature`` is among the estimated ``states``."""
    return CURVED_WHEEL if any(st.name == CURVATURE.name for st in states) else WHEEL


# --------------------------------------------------------------------------- dead reckoning
def wheel_track(travel: WheelTravel, initial_pose=(0.0, 0.0, 0.0)) -> PoseData:
    """Dead-reckoned wheel-only trajectory at the encoder's sample times."""
    inc = arc_increment(np.diff(travel.left), np.diff(travel.right), travel.wheel_base)
    poses = np.zeros((len(travel.t), 3))
    if len(poses):
        poses[0] = initial_pose
        poses[1:] = _chain(np.asarray(initial_pose, dtype=np.float64), inc)
    return PoseData(travel.t.copy(), poses)


def _chain(start: np.ndarray, inc: np.ndarray) -> np.ndarray:
    """Compose increments from ``start`` (vectorised through the cumulative heading)."""
    yaw = start[2] + np.cumsum(inc[:, 2])
    yaw_before = np.concatenate([[start[2]], yaw[:-1]])
    c, s = np.cos(yaw_before), np.sin(yaw_before)
    x = start[0] + np.cumsum(c * inc[:, 0] - s * inc[:, 1])
    y = start[1] + np.cumsum(s * inc[:, 0] + c * inc[:, 1])
    return np.stack([x, y, se2.wrap_angle(yaw)], axis=1)



# --------------------------------------------------------------------------- on the node grid
@dataclass
class WheelGrid:
    """The wheels' measurements on the node grid (``Intervals.sensors["wheel"]``, :func:`wheel_grid`).

    ``ok, dl, dr`` (K,): where the wheels cover each node interval and each wheel's travel over it [m];
    ``base``: the configured wheel base [m] (1 for an odometry twist, ``twist`` True, whose ``dl, dr`` are
    the travel of wheels one metre apart); ``yaw_ok``, ``speed_ok`` (K,): where the consistency monitor keeps
    the wheels' yaw and their speed (:mod:`fusion_vo.backends.monitor`).
    """

    ok: np.ndarray
    dl: np.ndarray
    dr: np.ndarray
    yaw_ok: np.ndarray
    speed_ok: np.ndarray
    base: float = 1.0
    twist: bool = False

    @classmethod
    def empty(cls, n_steps: int, config=None) -> "WheelGrid":
        return cls(np.zeros(n_steps, bool), np.zeros(n_steps), np.zeros(n_steps), np.ones(n_steps, bool),
                   np.ones(n_steps, bool))


def wheel_grid(iv) -> WheelGrid:
    """The wheels' measurements on the node grid ``iv`` (an :class:`~fusion_vo.backends.timeline.Intervals`)."""
    return iv.sensors["wheel"]


# --------------------------------------------------------------------------- registration
def add_intervals(iv, streams, config, counts) -> None:
    """Wheel travel (encoder ticks, else the odometry twist) interpolated at the node times (:class:`WheelGrid`)."""

    count = counts.setdefault("wheel", SensorCount())
    w = wheel_grid(iv)
    if streams.wheel is not None:
        data = ordered_fields(streams.wheel, ("left", "right"), count)
        travel: WheelTravel = ticks_to_travel(data, config.wheel)
    else:
        data = ordered_fields(streams.odom, ("vx", "vy", "wz"), count)
        travel = twist_to_travel(data, max_speed=config.odom.max_speed)
        w.twist = True
    count.gated += travel.n_gated
    T = iv.t
    ok = coverage(travel.t, ~travel.valid, T, config.max_gap)
    left = np.interp(T, travel.t, travel.left)
    right = np.interp(T, travel.t, travel.right)
    w.ok, w.dl, w.dr = ok, np.diff(left), np.diff(right)
    w.base = travel.wheel_base
    if streams.wheel is not None:
        observable = curvature_observable(s.references_heading(data) for s in registered_sensors()
                                          if (data := s.data(streams)) is not None)
        iv.states = curvature_states(iv.states, config, iv.facts.get("wheel_scale_sigma", config.wheel_scale_sigma),
                                     travel.wheel_base, observable)
        if config.wheel.estimate_curvature == "auto" and not observable:
            iv.notes.append("wheel curvature bias not estimated: without a camera, an AHRS heading, GPS or another "
                            "heading reference only the wheels and the gyro measure the turn, and a radius difference "
                            "cannot be told from the gyro's bias (fusion.wheel.estimate_curvature: true estimates it "
                            "anyway)")
    count.used += int(ok.sum())
    count.missing += int((~ok).sum())


def _add_twist_intervals(iv, streams, config, counts) -> None:
    if streams.wheel is None:  # ticks, when both are there, are the wheel's
        add_intervals(iv, streams, config, counts)


def gyro_turn(iv) -> np.ndarray | None:
    """The gyro's heading change per interval (NaN where it has none), or None without a gyro: the
    independent measure of the turn that scales the wheels' skid variance (:func:`skid_variance`)."""
    if not iv.uses("gyro"):
        return None
    imu = iv.sensors["imu"]
    return np.where(imu.gyro_ok, imu.gyro_angle, np.nan)


def at_rest(iv, config) -> np.ndarray:
    """True for the node intervals in which the wheels are usable and both at rest (:func:`standstill`);
    all False without wheels."""
    if not iv.uses("wheel"):
        return np.zeros(iv.n_steps, bool)
    w = wheel_grid(iv)
    return w.ok & standstill(w.dl, w.dr, iv.dt, config.wheel_model(w.twist)[0])


def readings(iv, config) -> list[Readings]:
    """The arc over each node interval the wheels cover, and the standstills.

    The arc's noise lives where the wheels make it: in its own coordinates ``(d, lateral, θ)`` (each wheel's travel,
    the lateral slip, the skid; :func:`arc_twist`), carried to the increment's ``(d_x, d_y, d_ψ)`` by the exponential's
    Jacobian (:func:`fusion_vo.geometry.se2.exp_jacobian`); the travel is projected to the horizontal by the forward
    slope factor (``Intervals.cx``) before the arc is made. Intervals in which the consistency monitor dropped a component of the wheels
    (:attr:`WheelGrid.yaw_ok`, ``speed_ok``) are readings with that component dropped. Both wheels at rest
    over an interval: its heading change is zero (``σ_still Δt``; not robust)."""
    out, w = [], wheel_grid(iv)
    if iv.uses("wheel") and w.ok.any():
        noise = config.wheel_model(w.twist)[0]
        k = np.flatnonzero(w.ok)
        dl, dr, dt = w.dl[k], w.dr[k], iv.dt[k]
        turn = gyro_turn(iv)
        _, rate_cov = arc_twist(dl, dr, dt, w.base, noise, None if turn is None else turn[k])
        # the arc's twist (d, 0, θ), its forward travel projected to the horizontal (Intervals.cx): the reading is its
        # exponential, so that the EKF, which reads the logarithm, gets the twist itself
        xi = np.stack([0.5 * (dl + dr) * iv.cx[k], np.zeros(len(k)), (dr - dl) / w.base], axis=1)
        J = se2.exp_jacobian(xi)
        cov = J @ (rate_cov * (dt**2)[:, None, None]) @ np.transpose(J, (0, 2, 1))
        z = se2.exp_many(xi)
        model = wheel_model(iv.states)
        params = {"wheel_base": w.base} if model is CURVED_WHEEL else {}
        yaw_ok = w.yaw_ok[k]
        speed_ok = w.speed_ok[k]
        for yaw in (True, False):
            for speed in (True, False):
                sel = (yaw_ok == yaw) & (speed_ok == speed)
                if sel.any():
                    dropped = (() if yaw else ("yaw",)) + (() if speed else ("speed",))
                    out.append(Readings("wheel", model, k[sel], k[sel] + 1, z[sel], cov[sel], params=params,
                                        order=ORDER["wheel"], dropped=dropped))
    still = at_rest(iv, config)
    if still.any():
        k = np.flatnonzero(still)
        sigma = config.wheel_model(w.twist)[0].standstill_yaw_rate * np.maximum(iv.dt[k], 1e-3)
        out.append(Readings("standstill", STANDSTILL, k, k + 1, np.zeros(len(k)), sigma**2, robust=False,
                            order=ORDER["standstill"]))
    return out


def _pick_ticks(streams, selected):
    """Encoder ticks when ``wheel`` is selected and recorded."""
    use = "wheel" in selected and streams.wheel is not None and len(streams.wheel) > 1
    return streams.wheel if use else None


def _pick_twist(streams, selected):
    """The odometry twist for ``odom``, or for ``wheel`` when there are no encoder ticks."""
    if _pick_ticks(streams, selected) is None and ("odom" in selected or "wheel" in selected):
        return streams.odom
    return None


def _live_ticks(m) -> tuple:
    """A live :class:`~fusion_vo.measurements.WheelTicks` sample: ``(t, (left, right))``."""
    return m.t, (m.left, m.right)


def _live_ticks_data(t, rows, fusion) -> WheelData:
    ticks = np.array(rows, dtype=np.int64)
    return WheelData(t, ticks[:, 0], ticks[:, 1], fusion.wheel_config)


def _live_twist(m) -> tuple:
    """A live :class:`~fusion_vo.measurements.TwistSample`: ``(t, (vx, vy, wz))``."""
    return m.t, (m.vx, m.vy, m.wz)


# --------------------------------------------------------------------------- its yaw, for the monitor
def _heading_change(iv, config):
    """The wheels' yaw change per interval (a twist's yaw rate integrated); its variance depends on the turn."""
    if not iv.uses("wheel"):
        return None
    whl = wheel_grid(iv)
    return whl.ok.copy(), arc_increment(whl.dl, whl.dr, whl.base)[:, 2], None


def _heading_variance(iv, config, angle, found):
    """Its noise model's yaw variance, the turn taken from the gyro where it has one (``found["gyro"]``, without its
    bias), else from the wheels' own yaw."""
    whl = wheel_grid(iv)
    noise = config.wheel_model(whl.twist)[0]
    d = np.abs(0.5 * (whl.dl + whl.dr))
    gyro = found.get("gyro")
    turn = np.abs(np.where(gyro[0], gyro[1], angle)) if gyro is not None else np.abs(angle)
    return noise.k_yaw**2 * turn + 2.0 * (noise.k**2 * d + noise.sigma_floor**2) / whl.base**2


def _heading_window(iv, config):
    """The relative error of the track width, shared over a window: ``(yaw_scale² + base_sigma²)`` of the turn (the
    gyro's over the window where it has one)."""
    noise, base_sigma = config.wheel_model(wheel_grid(iv).twist)
    rel = noise.yaw_scale**2 + base_sigma**2
    return lambda span, theta: rel * theta.get("gyro", theta["wheel"]) ** 2


def _heading_drop(iv, bad, agrees) -> None:
    whl = wheel_grid(iv)
    whl.yaw_ok = whl.yaw_ok & ~bad


def _heading_clear(iv) -> None:
    wheel_grid(iv).yaw_ok = np.zeros(iv.n_steps, bool)


def _distance_change(iv, config):
    """The axle's travel per interval, projected to the horizontal, with its variance from the wheels' noise."""
    if not iv.uses("wheel"):
        return None
    whl = wheel_grid(iv)
    vl, vr = travel_variances(whl.dl, whl.dr, config.wheel_model(whl.twist)[0])
    return whl.ok.copy(), 0.5 * (whl.dl + whl.dr) * iv.cx, 0.25 * (vl + vr)


def _distance_drop(iv, bad) -> None:
    whl = wheel_grid(iv)
    whl.speed_ok = whl.speed_ok & ~bad


#: the wheels' distance, the one dropped when it and the camera's disagree
DISTANCE = DistanceSource("wheel", "speed", rank=20, change=_distance_change, drop=_distance_drop, suspect=True)

#: the wheels' yaw: the one dropped when only two heading sources disagree
HEADING = HeadingSource(
    "wheel", "yaw rate", rank=20, change=_heading_change, variance=_heading_variance, window=_heading_window,
    drop=_heading_drop, kept=lambda iv: wheel_grid(iv).yaw_ok, clear=_heading_clear, suspect=True, reference=2,
    at_rest=lambda iv, config: at_rest(iv, config))


def _live_ticks_samples(data: WheelData) -> list:
    """Recorded tick counts as live samples."""
    return [(t, WheelTicks(t, int(lt), int(rt))) for t, lt, rt in zip(data.t, data.left, data.right)]


def _live_twist_samples(data: TwistData) -> list:
    """A recorded twist as live samples."""
    return [(t, TwistSample(t, vx, vy, wz)) for t, vx, vy, wz in zip(data.t, data.vx, data.vy, data.wz)]


def _live_twist_data(t, rows, fusion) -> TwistData:
    v = np.array(rows)
    return TwistData(t, v[:, 0], v[:, 1], v[:, 2])


# --------------------------------------------------------------------------- its streams in a recording
#: tick counts are 32-bit counters, signed or unsigned (their changes are taken modulo 2^32): a count outside
#: [-2^31, 2^32) is not one
TICK_RANGE = (-(2.0**31), 2.0**32)


def read_ticks(recording, folder: str = "wheel0") -> WheelData:
    """``wheel0/data.csv`` of a recording: ``timestamp [ns], left, right`` cumulative encoder counts (integers, 32-bit
    counters), with the calibration of :func:`wheel_config`."""
    tab, path = recording.table(folder, 2, "wheel encoder", "tick counts", min_rows=2)
    frac = np.abs(tab.values - np.round(tab.values))
    if np.any(frac > 0):
        i = int(np.flatnonzero(frac.max(axis=1) > 0)[0])
        raise InputError("tick counts must be integers", path, int(tab.lines[i]))
    out = ((tab.values < TICK_RANGE[0]) | (tab.values >= TICK_RANGE[1])).any(axis=1)
    if np.any(out):
        i = int(np.flatnonzero(out)[0])
        raise InputError(f"tick count {tab.values[i][np.argmax(np.abs(tab.values[i]))]:.0f} is not a 32-bit counter "
                         "(signed or unsigned)", path, int(tab.lines[i]))
    counts = tab.values.astype(np.int64)
    return WheelData(tab.t, counts[:, 0], counts[:, 1], wheel_config(recording, folder))


def wheel_config(recording, folder: str = "wheel0") -> WheelConfig:
    """The wheel calibration of ``wheel0/sensor.yaml`` (required, as are its four keys:
    :class:`~fusion_vo.config.sensor_files.WheelFile`)."""
    wheel = recording.sensor_file(folder, WheelFile, required=True)
    return WheelConfig(wheel.ticks_per_revolution, wheel.wheel_radius_left, wheel.wheel_radius_right,
                       wheel.wheel_base, wheel.radius_sigma)


def read_twist(recording, folder: str = "odom0") -> TwistData:
    """``odom0/data.csv`` of a recording (or another odometry's ``folder``, ``odom1`` ...): ``timestamp [ns], vx, vy
    [m/s], yaw rate [rad/s]`` in the body frame."""
    tab, path = recording.table(folder, 3, "odometry", "twist values")
    check_magnitude(tab, path, slice(0, 2), MAX_SPEED, "speed [m/s]")
    check_magnitude(tab, path, slice(2, 3), MAX_ANGULAR_RATE, "yaw rate [rad/s]")
    return TwistData(tab.t, tab.values[:, 0], tab.values[:, 1], tab.values[:, 2])


def _ticks_track(ticks: WheelData, config) -> PoseData:
    """The wheels' dead reckoning (``wheel.tum``): the arcs of their ticks chained from the initial pose."""
    return wheel_track(ticks_to_travel(ticks, config.wheel), config.initial_pose)


def _twist_track(twist: TwistData, config) -> PoseData:
    """The odometry twist's dead reckoning (``wheel.tum`` without ticks), as :func:`_ticks_track`."""
    return wheel_track(twist_to_travel(twist, max_speed=config.odom.max_speed), config.initial_pose)


def _arc_motion(iv, motion: np.ndarray) -> np.ndarray:
    """The wheels' :attr:`~fusion_vo.sensors.registry.Sensor.motion` step: their arc over each node interval where
    they measure it (an odometry twist's intervals are on the same grid)."""
    whl = wheel_grid(iv)
    if not iv.uses("wheel"):
        return motion
    out = motion.copy()
    out[whl.ok] = arc_increment(whl.dl, whl.dr, whl.base)[whl.ok]
    return out


def synchronise_twist(streams, config) -> tuple:
    """``streams`` with the odometry twist's timestamps moved back by its estimated delay behind the gyro.

    Returns the streams (:class:`~fusion_vo.sensors.streams.SensorStreams`) and the delay [s]: None when not
    corrected (no twist, no gyro, no turns, a delay shorter than the twist's sample period, or
    ``config.sync_odometry`` off). See :mod:`fusion_vo.sensors.sync`.
    """
    odom, imu = streams.odom, streams.imu
    if not config.sync_odometry or odom is None or imu is None or len(odom) < 3 or len(imu) < 3:
        return streams, None
    gyro = gyro_yaw(imu, config.imu)
    delay = odometry_delay(odom.t, odom.wz, gyro.t, gyro.rate, max_delay=config.max_odom_delay)
    if delay is None:
        return streams, None
    logger.info("odometry twist delayed by %.3f s behind the gyro; corrected", delay)
    return streams.replace(odom=dataclasses.replace(odom, t=np.asarray(odom.t) - delay)), delay


def _live_twist_clock(fusion):
    """The odometry twist's live clock (``Live.clock``): its delay behind the gyro, estimated as the samples come,
    when the run synchronises it and fuses an IMU."""
    if not fusion.config.sync_odometry or "imu" not in fusion.sensors:
        return None
    return TwistClock(fusion.config, lambda: fusion.imu_T_BS)


def _twist_clock(streams, config) -> tuple:
    """The odometry twist's :attr:`~fusion_vo.sensors.registry.Sensor.clock` step (:func:`synchronise_twist`)."""
    streams, delay = synchronise_twist(streams, config)
    if delay is None:
        return streams, None
    return streams, ClockOffset("odom_delay", float(delay),
                                f"odometry twist {delay * 1e3:.0f} ms behind the gyro: its timestamps corrected")


register(Sensor(
    name="wheel", where="wheel0/ or odom0/", field="wheel", min_samples=2, folder="wheel0", read=read_ticks,
    pick=_pick_ticks, config=("wheel", WheelNoise),
    grid=WheelGrid.empty, intervals=Step(20, add_intervals), readings=readings,
    coverage=lambda iv: ("wheel", wheel_grid(iv).ok),
    absolute_distance=True,
    states=(WHEEL_BASE_FACTOR, WHEEL_SCALE, CURVATURE), live=Live(_live_ticks, _live_ticks_data, samples=_live_ticks_samples, order=1),
    heading=(HEADING,), distance=(DISTANCE,), dead_reckoning=("wheel", _ticks_track),
    first_guesses=Step(30, first_wheel_base_factor), motion=Step(10, _arc_motion),
))
register(Sensor(
    name="odom", where="odom0/", field="odom", min_samples=2, folder="odom0", read=read_twist,
    wanted=lambda selected, present: (("wheel" in selected or "odom" in selected) and present.get("odom", False)
                                      and not ("wheel" in selected and present.get("wheel", False))),
    default=lambda present: not present.get("wheel", False), pick=_pick_twist, also_available_as=("wheel",),
    config=("odom", WheelNoise), intervals=Step(20, _add_twist_intervals), absolute_distance=True,
    live=Live(_live_twist, _live_twist_data, counted_as="wheel", samples=_live_twist_samples, message="twist", order=1,
              clock=_live_twist_clock),
    clock=Step(10, _twist_clock), dead_reckoning=("wheel", _twist_track),
))

__all__ = [
    "WheelNoise", "odom_twist_noise", "WheelTravel", "WheelConfig", "unwrap_ticks", "ticks_to_travel", "twist_to_travel",
    "arc_increment", "arc_covariance", "arc_twist", "travel_variances", "skid_variance", "standstill", "wheel_track",
    "WheelModel", "CurvedWheelModel", "StandstillModel", "WHEEL", "CURVED_WHEEL", "STANDSTILL",
    "wheel_model", "gyro_turn", "synchronise_twist",
]
