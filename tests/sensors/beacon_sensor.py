"""Ranges to beacons at known places, defined outside the library in this one module: its samples, its
configuration section, its measurement model and its readings; no code of either backend.

A sample is the distance [m] from the body origin to one beacon, ``z = |p - b| + n``, ``n ~ N(0, σ²)``; the beacons'
positions ``b`` (in the world frame) are in the configuration (``fusion: {beacon: {positions: [[x, y], ...]}}``).
Each reading is taken at the nearest node within ``max_gap`` of its sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from fusion_vo.config.base import Float, Section, Sigma
from fusion_vo.measurements import SensorCount
from fusion_vo.sensors.model import MeasurementModel
from fusion_vo.sensors.readings import Readings
from fusion_vo.sensors.registry import Sensor, Step


@dataclass
class BeaconData:
    """Distances ``distance`` [m] to beacon ``beacon`` (index) at times ``t`` [s]."""

    t: np.ndarray
    beacon: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


class BeaconNoise(Section):
    """Beacon ranges (the configuration section ``fusion: {beacon: ...}``)."""

    sigma: Sigma = Field(0.05, description="Standard deviation of one range [m].")
    positions: list[tuple[Float, Float]] = Field(default_factory=list, description=(
        "The beacons' positions ``[[x, y], ...]`` [m] in the world frame."))


@dataclass(frozen=True)
class BeaconModel(MeasurementModel):
    """``h = |p - b|``, ``∂h/∂(x, y, ψ) = ((p - b) / |p - b|, 0)``: argument ``pose``, parameter ``beacon`` (2,)."""

    name: str = "beacon"
    args: tuple = ("pose",)
    dim: int = 1

    def evaluate(self, pose, beacon):
        p = np.asarray(pose, dtype=np.float64)
        d = p[..., :2] - np.asarray(beacon, dtype=np.float64)
        r = np.linalg.norm(d, axis=-1)
        J = np.zeros(p.shape[:-1] + (1, 3))
        J[..., 0, :2] = d / r[..., None]
        return r[..., None], {"pose": J}


BEACON = BeaconModel()


def on_grid(iv, streams, config, counts):
    """Each range at the nearest node within ``max_gap``: ``iv.sensors["beacon"] = (node, beacon, distance)``."""
    data = streams["beacon"]
    T = iv.t
    n = np.clip(np.searchsorted(T, data.t), 1, len(T) - 1)
    n = np.where(np.abs(T[n - 1] - data.t) < np.abs(T[n] - data.t), n - 1, n)
    near = np.abs(T[n] - data.t) <= config.max_gap
    iv.sensors["beacon"] = (n[near], data.beacon[near], data.distance[near])
    count = counts.setdefault("beacon", SensorCount())
    count.used += int(near.sum())
    count.missing += int((~near).sum())


def readings(iv, config):
    """The ranges as readings of the pose at their nodes, each with its beacon's position."""
    if "beacon" not in iv.sensors:
        return []
    nodes, beacon, distance = iv.sensors["beacon"]
    section = config.section("beacon")
    positions = np.asarray(section.positions, dtype=np.float64).reshape(-1, 2)
    return [Readings("beacon", BEACON, nodes, nodes, distance, section.sigma**2,
                     params={"beacon": positions[beacon]})]


BEACON_SENSOR = Sensor(name="beacon", where="beacon0/", config=("beacon", BeaconNoise),
                       intervals=Step(100, on_grid), readings=readings)
