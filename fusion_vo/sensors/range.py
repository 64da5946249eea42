"""Downward range finder as a measurement of the camera height.

The range finder sits next to the camera and measures the distance ``z`` to the floor, i.e. the camera
height ``h``. The visual increments were computed with the configured height ``h_c``; their translations
scale as ``h_c / h``, so a range reading observes the visual scale ``s`` of the backends::

    z = h_c / s + n,   n ~ N(0, σ_r²)

Readings that are not finite, outside ``[min_range, max_range]`` or further than ``spike_threshold``
from the running median of their neighbours are gated and counted.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from pydantic import Field, model_validator

from fusion_vo.config.base import NonNegative, Positive, Section, Sigma
from fusion_vo.errors import InputError
from fusion_vo.measurements import MAX_RANGE_M, RangeData, RangeSample
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import ordered_fields
from fusion_vo.recording.csvio import check_magnitude
from fusion_vo.sensors.imu import running_median
from fusion_vo.sensors.model import MeasurementModel
from fusion_vo.sensors.readings import ORDER, Readings
from fusion_vo.sensors.registry import Live, Sensor, Step, register

logger = logging.getLogger(__name__)


class RangeNoise(Section):
    """Range-finder noise and gating (``min_range`` below ``max_range``)."""

    sigma: Sigma = Field(0.003, description="Standard deviation of one reading [m].")
    min_range: NonNegative = Field(0.01, description="Smallest plausible reading [m].")
    max_range: NonNegative = Field(2.0, description="Largest plausible reading [m].")
    spike_threshold: Positive = Field(0.02, description=(
        "Distance from the running median of 5 readings that marks a spike [m]."))

    @model_validator(mode="after")
    def _ordered(self) -> RangeNoise:
        if not self.min_range < self.max_range:
            raise ValueError(f"min_range must be below max_range ({self.max_range:g}), not {self.min_range:g}")
        return self


@dataclass
class CameraHeight:
    """Gated range readings: ``t`` (N,), ``height`` (N,) [m], ``valid`` (N,) bool, ``n_gated``."""

    t: np.ndarray
    height: np.ndarray
    valid: np.ndarray
    n_gated: int


def camera_height(data: RangeData, noise: RangeNoise | None = None) -> CameraHeight:
    """Camera heights from range readings, gated as described in the module docstring."""
    noise = noise or RangeNoise()
    d = np.asarray(data.distance, dtype=np.float64)
    ok = np.isfinite(d) & (d >= noise.min_range) & (d <= noise.max_range)
    med = running_median(np.where(ok, d, 0.0), 2, ok)
    ok &= np.abs(d - med) <= noise.spike_threshold
    n_gated = int(np.count_nonzero(~ok))
    if n_gated:
        logger.info("range: gated %d readings", n_gated)
    return CameraHeight(np.asarray(data.t, dtype=np.float64), np.where(ok, d, np.nan), ok, n_gated)


def reading_sigma(data: RangeData, noise: RangeNoise | None = None, gated: CameraHeight | None = None) -> float | None:
    """Standard deviation [m] of one reading, measured from the readings themselves.

    The second difference ``z_{i+1} - 2 z_i + z_{i-1}`` of white noise of standard deviation ``σ`` has
    variance ``6 σ²``, while a height that changes smoothly over a few samples (a slope, a vibration much
    slower than the sample rate) contributes little to it; so ``σ = rms(second differences) / √6`` (an upper
    bound when the height itself changes fast). Readings the gate of :func:`camera_height` rejects and second
    differences above ``spike_threshold`` are left out (``gated``: :func:`camera_height` of ``data`` with
    ``noise``, when at hand). None with fewer than 10 usable second differences.
    """
    noise = noise or RangeNoise()
    h = gated if gated is not None else camera_height(data, noise)
    z = h.height[h.valid]
    if len(z) < 12:
        return None
    d2 = np.diff(z, 2)
    d2 = d2[np.abs(d2) <= noise.spike_threshold]
    if len(d2) < 10:
        return None
    return float(np.sqrt(np.mean(d2**2) / 6.0))


@dataclass(frozen=True)
class RangeModel(MeasurementModel):
    """The range reading as a measurement of the visual scale (module docstring).

    ``h(k_v) = h_c / k_v``, ``∂h/∂k_v = -h_c / k_v²``; argument ``visual_scale``, parameter
    ``camera_height`` (``h_c``, the height the visual increments assume).
    """

    name: str = "range"
    args: tuple = ("visual_scale",)
    dim: int = 1

    def evaluate(self, visual_scale, camera_height=1.0):
        k = np.asarray(visual_scale, dtype=np.float64)
        return camera_height / k, {"visual_scale": (-camera_height / k**2)[..., None]}

    def state_prior(self, z, variance: float, params: dict) -> tuple[str, float, float]:
        """The reading solved for the visual scale (:meth:`scale_prior`)."""
        scale, sigma = self.scale_prior(np.asarray(z).reshape(-1)[0], float(np.sqrt(variance)), float(params["camera_height"]))
        return "visual_scale", scale, sigma

    @staticmethod
    def scale_prior(reading, sigma: float, camera_height: float) -> tuple[float, float]:
        """The reading solved for the scale: ``k_v = h_c / z`` with ``σ_k = h_c σ_r / z²`` (first order).

        The factor graph uses this as a linear prior on ``k_v``; it has the model's information
        ``(∂h/∂k_v)² / σ_r²`` at ``k_v = h_c / z``, where the model's residual is zero.
        """
        z = float(reading)
        return camera_height / z, camera_height * sigma / z**2


RANGE = RangeModel()


# --------------------------------------------------------------------------- on the node grid
@dataclass
class RangeGrid:
    """The range finder's camera heights at the nodes (``Intervals.sensors["range"]``, :func:`range_grid`):
    ``ok, height`` (K+1,) [m], NaN where ``ok`` is False."""

    ok: np.ndarray
    height: np.ndarray

    @classmethod
    def empty(cls, n_steps: int, config=None) -> "RangeGrid":
        return cls(np.zeros(n_steps + 1, bool), np.full(n_steps + 1, np.nan))


def range_grid(iv) -> RangeGrid:
    """The range finder's measurements on the node grid ``iv`` (an :class:`~fusion_vo.backends.timeline.Intervals`)."""
    return iv.sensors["range"]


# --------------------------------------------------------------------------- registration
def add_intervals(iv, streams, config, counts) -> None:
    """Camera heights at the nodes (:class:`RangeGrid`), within ``max_gap`` of a reading; nothing when the
    visual increments were already scaled with them (used once)."""

    if streams.visual is not None and streams.range_in_visual:
        iv.notes.append("range finder: already in the visual increments (their per-frame height), "
                        "not used again as a height measurement")
        return
    rng = streams.range
    count = counts.setdefault("range", SensorCount())
    if iv.facts.get("camera_height") is None:
        raise InputError("the range finder needs the configured camera height (camera T_BS or camera_height)")
    rng = ordered_fields(rng, ("distance",), count)
    h = camera_height(rng, config.range)
    count.gated += h.n_gated
    ht, hv = h.t[h.valid], h.height[h.valid]
    if len(ht) == 0:
        return
    T = iv.t
    j = np.clip(np.searchsorted(ht, T), 0, len(ht) - 1)
    jm = np.clip(j - 1, 0, len(ht) - 1)
    nearest = np.minimum(np.abs(ht[j] - T), np.abs(ht[jm] - T))
    ok = nearest <= config.max_gap
    grid = range_grid(iv)
    grid.ok = ok
    grid.height = np.where(ok, np.interp(T, ht, hv), np.nan)
    count.used += int(ok.sum())


def readings(iv, config) -> list[Readings]:
    """The camera heights at the nodes (``σ_r²``), measurements of the visual scale."""
    grid = range_grid(iv)
    if not grid.ok.any():
        return []
    n = np.flatnonzero(grid.ok)
    return [Readings("range", RANGE, n, n, grid.height[n], config.range.sigma**2,
                     params={"camera_height": iv.facts["camera_height"]}, order=ORDER["range"])]


def _live_sample(m) -> tuple:
    """A live :class:`~fusion_vo.measurements.RangeSample`: ``(t, distance)``."""
    return m.t, float(m.distance)


def _live_samples(data: RangeData) -> list:
    """Recorded distances as live samples."""
    return [(t, RangeSample(t, d)) for t, d in zip(data.t, data.distance)]


def read_range(recording, folder: str = "range0") -> RangeData:
    """``range0/data.csv`` of a recording: ``timestamp [ns], distance [m]`` to the floor, each positive and within
    the physical range."""
    tab, path = recording.table(folder, 1, "range finder", "distance")
    bad = np.flatnonzero(tab.values[:, 0] <= 0)
    if len(bad):
        raise InputError("distance must be positive", path, int(tab.lines[bad[0]]))
    check_magnitude(tab, path, slice(0, 1), MAX_RANGE_M, "distance [m]")
    return RangeData(tab.t, tab.values[:, 0])


register(Sensor(
    name="range", where="range0/", field="range", folder="range0", read=read_range, config=("range", RangeNoise), grid=RangeGrid.empty, intervals=Step(40, add_intervals),
    readings=readings, absolute_distance=lambda iv: bool(range_grid(iv).ok.any()),
    # the streaming buffers read as many neighbours around an interval as the gyro's spike check
    live=Live(_live_sample, lambda t, rows, fusion: RangeData(t, np.array(rows)), min_rows=1,
              neighbours=lambda config: int(config.imu.spike_window) + 1, samples=_live_samples, order=3),
))
