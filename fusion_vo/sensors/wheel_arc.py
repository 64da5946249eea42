"""The wheels' arc model and its noise: left and right travel -> a planar increment with its covariance.

Arc model
---------
With left/right travels ``d_l, d_r`` and wheel base ``b`` the axle centre moves on a circular arc::

    d = (d_r + d_l) / 2,   θ = (d_r - d_l) / b
    Δ = (d · sin θ / θ,  d · (1 - cos θ) / θ,  θ)      (pose of B(t1) in B(t0))

so the constant body twist over the interval is exactly ``(d, 0, θ) / Δt``.

Noise model
-----------
Each wheel's travel has variance growing with the distance it rolled, plus a skid term growing with
the turn, plus a lateral slip (the arc model assumes none)::

    σ_l² = k² |d_l| + σ_0²,   σ_r² = k² |d_r| + σ_0²
    Σ_Δ  = J diag(σ_l², σ_r²) Jᵀ + diag(0, k_lat² |d|, k_yaw² |θ| + (s_ψ θ)² max(1, τ_ψ/Δt))

where ``J = ∂Δ/∂(d_l, d_r)``. The last term is the skid of a skid-steered (or tracked) robot: its
wheels slide sideways whenever it turns, the instantaneous centres of rotation of the tracks move
with the ground and the load, and the heading change the wheels report is off by a fraction
``s_ψ`` of itself (tens of percent, varying from turn to turn). Its systematic part is the
wheel-base factor that the backends can estimate; ``s_ψ`` is the part that varies. The twist form used by the filter has
``Σ_u = J_u diag(σ_l², σ_r²) J_uᵀ / Δt²`` with ``J_u = [[½, ½], [-1/b, 1/b]]`` on ``(v_x, ω)`` and the slip
term on ``v_y``.

Odometry twist
--------------
A robot's own odometry (``odom0``, e.g. ``nav_msgs/Odometry`` of a skid-steer controller) is a twist
``(v_x, ω)`` sampled at a few Hz and held between samples. It has no tick quantisation but a
velocity error: ``σ_v`` [m/s] held over a sample period ``τ`` gives a travel floor ``σ_v τ``; its
heading comes from wheel speeds through a nominal track width, so on a skid-steered base it is
only known to a scale (:func:`odom_twist_noise` documents the defaults).

Correlated heading error of skid steering
-----------------------------------------
The skid error of the reported heading change is not white: the effective track width is set by
the ground and the load and stays much the same for a whole turn, so consecutive samples share
the same relative error (a Gauss–Markov error of correlation time ``τ_ψ``). Treated as independent
per interval, a turn of ``N`` intervals would pin the heading change to ``s_ψ / √N`` and the wheels
would outweigh a gyro and drag its bias. A correlated error sampled every ``Δt < τ_ψ`` carries about
one independent sample per ``τ_ψ``, so each interval's skid variance is inflated by ``τ_ψ / Δt``::

    σ_ψ,skid² = (s_ψ θ)² · max(1, τ_ψ / Δt) = s_ψ² ω² τ_ψ Δt      (Δt < τ_ψ)

i.e. white yaw-rate noise of density ``s_ψ |ω| √τ_ψ``: over a turn lasting ``τ_ψ`` the summed
variance is ``(s_ψ θ_turn)²``, the stated relative error of one turn, whatever the sample rate.
The ``θ`` in that variance should not be the wheels' own reading: a variance proportional to the
measurement weights the samples that happen to read low more and biases every estimate that
uses them (the yaw-rate scale, and through it the gyro bias) towards small turns. The backends pass
the gyro's heading change of the interval when there is one (its noise is independent of the wheels').
The inflation matters only where the wheels are fused with such an independent measure of the
turn; where they are the only one (no gyro, or a gap in it), nothing can tell their correlated
error apart and the inflation would only make the estimate lag behind the wheels, so it is left out.

Standstill
----------
An interval in which both wheels move slower than ``standstill_speed`` is a standstill: the robot
does not rotate, so its yaw rate is measured as ``0`` with standard deviation ``standstill_yaw_rate``
(zero-velocity update). With a gyro, this is what fixes its bias: at rest the gyro reads ``b_g``.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from fusion_vo.config.base import NonNegative, Positive, Section, Sigma
from fusion_vo.geometry import se2


class WheelNoise(Section):
    """Wheel-odometry noise and gating parameters (``fusion: {wheel: ...}`` for encoder ticks, ``odom`` for an
    odometry twist, :func:`odom_twist_noise`)."""

    k: Positive = Field(0.01, description=(
        "Per-wheel travel noise [m^½]: variance ``k² |d|`` per metre rolled (0.01: 1 cm standard deviation after "
        "1 m)."))
    sigma_floor: Sigma = Field(1e-4, description="Standard deviation added to every travel [m] (quantisation).")
    k_lateral: NonNegative = Field(0.005, description=(
        "Lateral slip [m^½]: variance ``k_lateral² |d|`` on the sideways motion."))
    k_yaw: NonNegative = Field(0.01, description="Skid on turning [rad^½]: variance ``k_yaw² |θ|`` on the heading "
                                                 "change.")
    yaw_scale: NonNegative = Field(0.0, description=(
        "``s_ψ``: relative standard deviation of the reported heading change (skid steering; 0: an ideal "
        "differential drive)."))
    max_speed: Positive = Field(5.0, description="Wheel speeds above this [m/s] are encoder glitches and gated.")
    yaw_scale_time: NonNegative = Field(0.0, description=(
        "``τ_ψ``: correlation time [s] of the ``s_ψ`` heading error (0: white)."))
    standstill_speed: NonNegative = Field(1e-3, description=(
        "Both wheels slower than this [m/s] over an interval is a standstill (0 disables the zero-velocity "
        "update)."))
    standstill_yaw_rate: NonNegative = Field(1e-2, description=(
        "Standard deviation [rad/s] of the zero yaw rate at a standstill (vibration of a robot at rest)."))
    estimate_curvature: bool | Literal["auto"] = Field("auto", description=(
        "Estimate the curvature bias of unequal left and right radius errors (:class:`CurvedWheelModel`; encoder "
        "ticks only, an odometry twist has no radii). ``auto``: when a camera, an AHRS heading, GPS or a "
        "registered heading reference (a compass) is fused "
        "(:func:`~fusion_vo.sensors.wheel_states.curvature_observable`); on the generated drives, which all have "
        "a camera, it improves ``hard``, "
        "``height_error``, ``tilted`` and ``gps_outage`` and costs ``random60``'s EKF and iSAM2 4 %. With the "
        "wheels and a gyro alone the curvature's turn and the gyro's bias are told apart only by changes of speed, "
        "and the heading then follows the two priors' split."))

    @field_validator("estimate_curvature", mode="before")
    @classmethod
    def _true_false_or_auto(cls, value: Any) -> Any:
        if value is True or value is False or value == "auto":
            return value
        raise ValueError(f"must be true, false or 'auto', not {value!r}")


def odom_twist_noise() -> WheelNoise:
    """Noise of an odometry twist stream (``odom0``) of a wheeled base that may be skid-steered.

    * ``k = 0.02`` m^½: 2 % of the distance after one metre — a rolling radius that changes with tyre
      pressure and load, which a twist from someone else's controller does not calibrate;
    * ``sigma_floor = 1e-3`` m: a velocity error of about 0.01 m/s held over a 0.1 s sample (the
      twist is a rate, not a count; an exactly zero twist does not pin the robot to 0.1 mm);
    * ``k_lateral = 0.02`` m^½: sideways sliding of skid-steered wheels;
    * ``k_yaw = 0.02`` rad^½ and ``yaw_scale = 0.3``: the heading change computed from the wheel
      speeds with a nominal track width is off by tens of percent on a skid-steered base (the
      effective track width of skid steering is typically 1.2 to 2 times the geometric one and
      changes with the ground), so a gyro, when present, must dominate the heading;
    * ``yaw_scale_time = 5`` s: that error persists for a turn (the time a slow base takes for a
      quarter turn) and changes from turn to turn; it is not white at the sample rate.
    """
    return WheelNoise(k=0.02, sigma_floor=1e-3, k_lateral=0.02, k_yaw=0.02, yaw_scale=0.3, yaw_scale_time=5.0)


# --------------------------------------------------------------------------- arc model
def arc_increment(d_left, d_right, wheel_base: float) -> np.ndarray:
    """Pose increments ``(dx, dy, dyaw)`` (N x 3) of the arc model for travels ``d_left, d_right`` (N,)."""
    dl = np.atleast_1d(np.asarray(d_left, dtype=np.float64))
    dr = np.atleast_1d(np.asarray(d_right, dtype=np.float64))
    d = 0.5 * (dr + dl)
    th = (dr - dl) / wheel_base
    a, b = se2.sinc_terms(th)
    return np.stack([d * a, d * b, th], axis=1)


def travel_variances(d_left, d_right, noise: WheelNoise) -> tuple[np.ndarray, np.ndarray]:
    """Per-wheel travel variances ``k² |d| + σ_0²``."""
    f2 = noise.sigma_floor**2
    return noise.k**2 * np.abs(d_left) + f2, noise.k**2 * np.abs(d_right) + f2


def skid_variance(theta, dt, noise: WheelNoise, theta_ref=None) -> np.ndarray:
    """Variance of the reported heading change ``θ`` over intervals ``dt`` from skid: ``k_yaw² |θ|`` plus
    the scale error ``(s_ψ θ)²``; where ``theta_ref`` (an independent measure of the same turn, e.g. the
    gyro's) is finite, ``θ`` is replaced by it and the scale error, correlated over ``τ_ψ``, is
    inflated by ``max(1, τ_ψ / Δt)`` (see the module docstring)."""
    th = np.asarray(theta, dtype=np.float64)
    if theta_ref is None:
        return noise.k_yaw**2 * np.abs(th) + (noise.yaw_scale * th) ** 2
    ref = np.broadcast_to(np.asarray(theta_ref, dtype=np.float64), th.shape)
    fused = np.isfinite(ref)
    th = np.where(fused, ref, th)
    inflation = np.ones_like(th)
    if noise.yaw_scale_time > 0 and dt is not None:
        ratio = noise.yaw_scale_time / np.maximum(np.asarray(dt, dtype=np.float64), 1e-6)
        inflation = np.where(fused, np.maximum(1.0, ratio), 1.0)
    return noise.k_yaw**2 * np.abs(th) + (noise.yaw_scale * th) ** 2 * inflation


def arc_covariance(d_left, d_right, wheel_base: float, noise: WheelNoise, dt=None, theta_ref=None) -> np.ndarray:
    """Covariances (N x 3 x 3) of :func:`arc_increment` over intervals of length ``dt`` [s] (needed by a
    correlated skid error, ``noise.yaw_scale_time > 0``), see the module docstring and
    :func:`skid_variance` for ``theta_ref``."""
    dl = np.atleast_1d(np.asarray(d_left, dtype=np.float64))
    dr = np.atleast_1d(np.asarray(d_right, dtype=np.float64))
    d = 0.5 * (dr + dl)
    th = (dr - dl) / wheel_base
    a, b = se2.sinc_terms(th)
    da, db = se2.sinc_derivatives(th)
    # ∂Δ/∂(d, θ), then ∂(d, θ)/∂(d_l, d_r)
    j_d = np.stack([a, b, np.zeros_like(a)], axis=1)
    j_th = np.stack([d * da, d * db, np.ones_like(a)], axis=1)
    jl = 0.5 * j_d - j_th / wheel_base
    jr = 0.5 * j_d + j_th / wheel_base
    vl, vr = travel_variances(dl, dr, noise)
    cov = vl[:, None, None] * jl[:, :, None] * jl[:, None, :] + vr[:, None, None] * jr[:, :, None] * jr[:, None, :]
    cov[:, 1, 1] += noise.k_lateral**2 * np.abs(d) + noise.sigma_floor**2
    cov[:, 2, 2] += skid_variance(th, dt, noise, theta_ref)
    return cov


def arc_twist(d_left, d_right, dt, wheel_base: float, noise: WheelNoise,
              theta_ref=None) -> tuple[np.ndarray, np.ndarray]:
    """Mean body twists ``(v_x, v_y, ω)`` (N x 3) over intervals of length ``dt`` and their covariances
    (``theta_ref``: see :func:`skid_variance`).

    The arc model's twist is exact: ``(d, 0, θ) / Δt`` (see the module docstring).
    """
    dl = np.atleast_1d(np.asarray(d_left, dtype=np.float64))
    dr = np.atleast_1d(np.asarray(d_right, dtype=np.float64))
    dt = np.atleast_1d(np.asarray(dt, dtype=np.float64))
    d = 0.5 * (dr + dl)
    th = (dr - dl) / wheel_base
    u = np.stack([d, np.zeros_like(d), th], axis=1) / dt[:, None]
    vl, vr = travel_variances(dl, dr, noise)
    cov = np.zeros((len(d), 3, 3))
    cov[:, 0, 0] = 0.25 * (vl + vr)
    cov[:, 2, 2] = (vl + vr) / wheel_base**2 + skid_variance(th, dt, noise, theta_ref)
    cov[:, 0, 2] = cov[:, 2, 0] = 0.5 * (vr - vl) / wheel_base
    cov[:, 1, 1] = noise.k_lateral**2 * np.abs(d) + noise.sigma_floor**2
    return u, cov / (dt**2)[:, None, None]


def standstill(d_left, d_right, dt, noise: WheelNoise) -> np.ndarray:
    """True for the intervals in which both wheels moved slower than ``noise.standstill_speed``."""
    dl = np.abs(np.atleast_1d(np.asarray(d_left, dtype=np.float64)))
    dr = np.abs(np.atleast_1d(np.asarray(d_right, dtype=np.float64)))
    dt = np.atleast_1d(np.asarray(dt, dtype=np.float64))
    if noise.standstill_speed <= 0:
        return np.zeros(np.broadcast(dl, dr, dt).shape, bool)
    limit = noise.standstill_speed * dt
    return (dl < limit) & (dr < limit)


def wheel_motion(iv) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """The wheels' heading change and distance per node interval of ``iv`` (NaN where the consistency monitor does
    not keep them), or None, None where the wheels are not used (the first guesses of the calibration states)."""
    if not iv.uses("wheel"):
        return None, None
    whl = iv.sensors["wheel"]
    inc = arc_increment(whl.dl, whl.dr, whl.base)
    return (np.where(whl.ok & whl.yaw_ok, inc[:, 2], np.nan),
            np.where(whl.ok, np.hypot(inc[:, 0], inc[:, 1]), np.nan))


__all__ = ["WheelNoise", "odom_twist_noise", "arc_increment", "travel_variances", "skid_variance", "arc_covariance",
           "arc_twist", "standstill", "wheel_motion"]
