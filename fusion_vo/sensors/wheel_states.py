"""The wheels' states: the wheel-base factor ``k_b``, the distance scale ``k_r`` and the curvature bias ``c``.

``k_b = b_true / b_configured`` scales the wheels' (or an odometry twist's) turn, ``k_r = r_configured / r_true``
their distance (the common radius error), ``c`` [rad/m] adds a turn per metre driven (unequal radii;
:class:`~fusion_vo.sensors.wheel.CurvedWheelModel`). ``k_b`` is estimated where another sensor measures the
heading, ``k_r`` where another sensor's distance scale is estimated too (the visual scale: camera and wheels
measure only the ratio of their scales), ``c`` by ``wheel.estimate_curvature`` (:func:`curvature_states`); each is a
:class:`~fusion_vo.sensors.registry.State` of the ``wheel`` sensor (:mod:`fusion_vo.backends.states`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fusion_vo.sensors import registry
from fusion_vo.sensors.registry import State
from fusion_vo.sensors.visual import FIRST_GUESS_INTERVALS, camera_heading_reference
from fusion_vo.sensors.wheel_arc import wheel_motion


#: the wheels' curvature bias ``c`` [rad/m] (:class:`CurvedWheelModel`), a state of encoder-tick wheels; its
#: prior standard deviation is set per recording from the radius uncertainty and the wheel base
#: (:func:`curvature_sigma`); 0.05 rad/m (1 % per wheel on a 0.28 m base) where no recording says it
CURVATURE = State("wheel_curvature", initial=0.0, sigma=0.05, random_walk=1e-4)


def _wheel_base_factor(state: State, context) -> State:
    """``k_b``: estimated under self-calibration where another sensor measures the heading (its observability,
    in ``context``), its prior the wheel base's (or the odometry twist's yaw-rate) σ."""
    config = context.config
    return dataclasses.replace(state, sigma=config.wheel_model("wheel" in context.stood_in)[1],
                               random_walk=config.ekf.scale_random_walk,
                               estimated=bool(config.self_calibration and context.observable.get(state.name, False)))


def _wheel_scale(state: State, context) -> State:
    """``k_r``: estimated with the wheel base and a distance scale of another sensor (a state that
    :attr:`~fusion_vo.sensors.state.State.needs` a distance: the camera's visual scale; only the ratio of the two
    scales is measured otherwise), its prior the run's radius uncertainty."""
    config = context.config
    scale = any(context.observable.get(st.name, False) for s in registry.sensors() for st in s.states
                if st.needs == "distance" and st.name != state.name)
    kb = context.observable.get(WHEEL_BASE_FACTOR.name, False)
    return dataclasses.replace(state, sigma=context.facts["wheel_scale_sigma"], random_walk=config.ekf.scale_random_walk,
                               estimated=bool(config.self_calibration and scale and kb))


def _wheel_base(value: float, sigma: float, iv) -> dict:
    """The wheel base ``b k_b`` (σ ``b σ_kb``) of encoder ticks; none for an odometry twist, whose factor scales
    its yaw rate."""
    grid = iv.sensors["wheel"]  # (a WheelGrid, fusion_vo.sensors.wheel)
    if grid.twist:
        return {}
    return {"wheel_base": (float(grid.base * value), float(grid.base * sigma))}


#: the wheel-base factor ``k_b = b_true / b_configured`` and the wheels' distance scale
#: ``k_r = r_configured / r_true`` (:class:`WheelModel`), states of every run
WHEEL_BASE_FACTOR = State("wheel_base_factor", initial=1.0, symbol="w", rule=_wheel_base_factor, derived=_wheel_base,
                          needs="heading")
WHEEL_SCALE = State("wheel_scale", initial=1.0, symbol="r", rule=_wheel_scale)


def curvature_sigma(radius_rel_sigma: float, wheel_base: float) -> float:
    """``σ_c = √2 σ_ε / b`` [rad/m] of independent relative radius errors ``σ_ε`` on a wheel base ``b`` [m]."""
    return float(math.sqrt(2.0) * radius_rel_sigma / wheel_base)


def curvature_observable(references) -> bool:
    """Whether the wheels' curvature bias is estimated under ``estimate_curvature: "auto"``: when a sensor
    besides the wheels and the gyro measures the heading or its change without a bias of its own
    (``references``: whether each sensor of the run is such a reference, its
    :attr:`~fusion_vo.sensors.registry.Sensor.heading_reference`: a camera, an AHRS heading, GPS, a compass).

    The wheels' turn carries ``c`` per metre driven, the gyro's its bias ``b`` per second; with nothing else,
    only their difference ``c v - b`` is measured, and the two separate only through changes of speed ``v``.
    The estimate of that split then leans on the two priors, and the heading drifts at the split's error
    (``docs/decisions/0013-no-curvature-without-a-heading-reference.md``).
    """
    return any(references)


def curvature_states(states, config, radius_rel_sigma: float, wheel_base: float,
                     observable: bool = True) -> tuple:
    """``states`` with the curvature bias only if ``config.wheel.estimate_curvature`` is true, or ``"auto"`` and
    ``observable`` (:func:`curvature_observable`); with it, its prior set from the wheels' relative radius
    uncertainty and base (:func:`curvature_sigma`), unless the configuration's ``states`` section sets it."""
    wanted = config.wheel.estimate_curvature
    if wanted is False or (wanted == "auto" and not observable):
        return tuple(st for st in states if st.name != CURVATURE.name)
    if CURVATURE.name in (getattr(config, "states", None) or {}):
        return tuple(states)
    sigma = curvature_sigma(radius_rel_sigma, wheel_base)
    return tuple(dataclasses.replace(st, sigma=sigma) if st.name == CURVATURE.name else st for st in states)


def first_wheel_base_factor(iv, guesses: dict) -> dict:
    """The wheel-base factor's first guess: ``k = Σ θ_wheels θ_ref / Σ θ_ref²`` over the intervals both cover (more
    than :data:`~fusion_vo.sensors.visual.FIRST_GUESS_INTERVALS`), the reference the camera's heading changes
    (:func:`~fusion_vo.sensors.visual.camera_heading_reference`), else the gyro's corrected by the first guess of
    its bias; kept within (0.5, 2)."""
    wheel_yaw, _ = wheel_motion(iv)
    if wheel_yaw is None:
        return {}
    heading = camera_heading_reference(iv)
    if heading is None and "gyro_bias" in guesses:
        imu = iv.sensors["imu"]
        heading = np.where(imu.gyro_ok, imu.gyro_angle - guesses["gyro_bias"] * iv.dt, np.nan)
    if heading is None:
        return {}
    ok = np.isfinite(heading) & np.isfinite(wheel_yaw)
    if ok.sum() <= FIRST_GUESS_INTERVALS or np.sum(heading[ok] ** 2) <= 1e-6:
        return {}
    factor = float(np.sum(wheel_yaw[ok] * heading[ok]) / np.sum(heading[ok] ** 2))
    return {"wheel_base_factor": factor} if 0.5 < factor < 2.0 else {}
