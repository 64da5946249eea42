"""A second robot base's odometry twist, defined outside the library in this one module: its samples, its
configuration section, its measurement model with a scale of its own that both backends estimate, and its
readings; no code of either backend.

A sample is the base's forward speed ``v`` [m/s] and yaw rate ``ω`` [rad/s]. Over a node interval the speeds are
integrated (held between samples) to the arc ``(d, 0, θ)``, whose increment ``exp(d, 0, θ)`` is the reading of
``h(δ, k) = (k d_x, k d_y, d_ψ)``: the base's distances are ``k`` times the true ones (``second_base_scale``, its wheel
radius error), its turn is not scaled. Noise: ``σ_d = k_d |d| + σ_0`` along, ``σ_0`` across, ``k_θ |θ| + σ_0``
in the turn, in the arc's own coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from fusion_vo.config.base import Section, Sigma
from fusion_vo.geometry import se2
from fusion_vo.measurements import SensorCount
from fusion_vo.sensors.model import MeasurementModel, scaled_motion
from fusion_vo.sensors.readings import Readings
from fusion_vo.sensors.registry import Sensor, State, Step


@dataclass
class TwistData:
    """Forward speed ``v`` [m/s] and yaw rate ``w`` [rad/s] at times ``t`` [s]."""

    t: np.ndarray
    v: np.ndarray
    w: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


class SecondOdometryNoise(Section):
    """The second base's odometry noise (the configuration section ``fusion: {second_base: ...}``)."""

    distance_sigma: Sigma = Field(0.02, description="Relative standard deviation of a distance.")
    turn_sigma: Sigma = Field(0.02, description="Relative standard deviation of a turn.")
    floor: Sigma = Field(1e-4, description="Floor of every standard deviation [m or rad].")


@dataclass(frozen=True)
class ScaledOdometryModel(MeasurementModel):
    """``h(δ, k) = (k d_x, k d_y, d_ψ)``: arguments ``motion``, ``second_base_scale``; the reading is a relative pose."""

    name: str = "second_base"
    args: tuple = ("motion", "second_base_scale")
    dim: int = 3
    turn_rows: tuple = (2,)
    increment: bool = True

    def evaluate(self, motion, second_base_scale):
        one = 1.0 if np.ndim(motion) == 1 else np.ones_like(np.asarray(second_base_scale, dtype=np.float64))
        h, j_d, j_k, _ = scaled_motion(motion, second_base_scale, one)
        return h, {"motion": j_d, "second_base_scale": j_k}


SECOND_BASE = ScaledOdometryModel()


def on_grid(iv, streams, config, counts):
    """Distance and turn over each node interval the samples cover: ``iv.sensors["second_base"] = (ok, d, θ)``."""
    data = streams["second_base"]
    t = np.asarray(data.t, dtype=np.float64)
    dt = np.diff(t)
    dist = np.concatenate([[0.0], np.cumsum(data.v[:-1] * dt)])
    turn = np.concatenate([[0.0], np.cumsum(data.w[:-1] * dt)])
    T = iv.t
    ok = (T[:-1] >= t[0]) & (T[1:] <= t[-1])
    iv.sensors["second_base"] = (ok, np.diff(np.interp(T, t, dist)), np.diff(np.interp(T, t, turn)))
    count = counts.setdefault("second_base", SensorCount())
    count.used += int(ok.sum())
    count.missing += int((~ok).sum())


def readings(iv, config):
    """The arcs as readings of the motion, their noise carried from the arc's coordinates to the increment's."""
    if "second_base" not in iv.sensors:
        return []
    ok, d, th = iv.sensors["second_base"]
    k = np.flatnonzero(ok)
    noise = config.section("second_base")
    xi = np.stack([d[k], np.zeros(len(k)), th[k]], axis=1)
    sigma = np.stack([noise.distance_sigma * np.abs(d[k]) + noise.floor, np.full(len(k), noise.floor),
                      noise.turn_sigma * np.abs(th[k]) + noise.floor], axis=1)
    J = se2.exp_jacobian(xi)
    cov = J @ (sigma[:, :, None] ** 2 * np.eye(3)) @ np.transpose(J, (0, 2, 1))
    return [Readings("second_base", SECOND_BASE, k, k + 1, se2.exp_many(xi), cov)]


SECOND_ODOMETRY = Sensor(name="second_base", where="second_base0/", config=("second_base", SecondOdometryNoise),
                         states=(State("second_base_scale", initial=1.0, sigma=0.1),),
                         intervals=Step(100, on_grid), readings=readings)
