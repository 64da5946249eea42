"""The camera's heading noise, measured against a reference drive: its size by turn and each frame's own share.

A frontend's stated covariance comes from its inlier residuals, which do not say how its heading errors
behave from one increment to the next. Measured against the ground truth of a calibration drive of the same
camera and frontend, they have two parts:

* each frame's own error ``e`` (image noise moves where the frame's points are found), which enters the
  increment that ends at the frame and, with the opposite sign, the one that starts there: consecutive
  increments' errors then correlate at ``-σ_e² / σ²``, about -0.5 when it is all there is;
* an increment's own error ``w``, whose size grows with the turn between the two frames (rotating patches
  deform and are resampled).

So the increment from frame ``a`` to frame ``b`` has the heading error::

    n_ψ = e_b - e_a + w,    e ~ N(0, σ_e²),    w ~ N(0, σ_w²(|Δψ|))

:func:`measure` fits ``σ_e`` and ``σ_w`` per band of the measured turn ``|Δψ|`` between the two frames
(:data:`EDGES`; a band with fewer than :data:`MIN_BAND` increments shares the nearest populated band's) to
how the heading errors of one or more calibration drives grow when summed over runs of 1 to 32 increments:
the model gives such a run the variance ``2 σ_e² + Σ_k σ_w²(band_k)``, since the frame errors inside it
cancel. So the frame error is what does not grow with the run's length (driving straight, consecutive errors
correlate at about -0.5), and an error that persists over many frames (turning) gets the increment variance
that its growth over seconds needs, not only its RMS from one frame to the next: that growth is what decides
how much the backends trust the camera's heading against the gyro's. ``heading_sigma`` states each band's
whole increment error, ``sqrt(σ_w² + 2 σ_e²)``.

:meth:`CameraNoise.apply` gives each increment of a run that heading variance (its heading row and column
scaled, so that the frontend's correlations with the translation stay) and the frame error as its
:attr:`~fusion_vo.measurements.VisualIncrement.frame_covariance`, which both backends model
(:mod:`fusion_vo.sensors.visual`). The translation keeps the frontend's covariance: camera and wheels are
its only sensors, so a calibration against the truth is the only way to tell their errors apart, and that
is left to the wheels' own calibration. The model is stated under ``camera_noise`` in ``cam0/sensor.yaml``
(``fusion-vo calibrate camera-noise``, ``datasets/README.md``) and used by runs of the same frontend.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fusion_vo.config.files import validate
from fusion_vo.config.sensor_files import CameraFile, CameraNoiseFile
from fusion_vo.errors import InputError

log = logging.getLogger(__name__)

#: band edges of the measured turn between two frames [rad]: 0.015 is the KLT frontend's warp tolerance
#: (patches of a turn below it are tracked without warping, with larger errors)
EDGES = (0.0, 0.002, 0.008, 0.015, 0.03)
#: fewest increments in a band for its own RMS (else the RMS of all)
MIN_BAND = 20
#: lengths [increments] of the runs whose summed heading errors :func:`measure` fits
HORIZONS = (1, 2, 4, 8, 16, 32)
#: the translation's share of each frame's error (the frame error is a heading error; the backends need a
#: positive definite covariance for it)
_TRANSLATION_SHARE = 1e-4


@dataclass(frozen=True)
class CameraNoise:
    """A camera's heading noise by turn and each frame's own error (module docstring).

    Attributes
    ----------
    frontend : str
        The frontend it was measured with; runs of another frontend do not use it.
    edges : tuple of float
        Lower edges of the turn bands [rad between two frames], ascending from 0.
    heading_sigma : tuple of float
        RMS heading error of an increment in each band [rad].
    frame_sigma : float
        Standard deviation of each frame's own heading error [rad].
    increments : int
        How many increments it was measured on.
    """

    frontend: str
    edges: tuple[float, ...]
    heading_sigma: tuple[float, ...]
    frame_sigma: float
    increments: int = 0

    def heading_variance(self, turn) -> np.ndarray:
        """The heading variance [rad²] of increments turning by ``turn`` [rad] (any sign)."""
        band = np.searchsorted(np.asarray(self.edges), np.abs(np.asarray(turn, dtype=np.float64)), side="right") - 1
        return np.square(np.asarray(self.heading_sigma))[np.clip(band, 0, len(self.edges) - 1)]

    def apply(self, increments: list) -> list:
        """``increments`` with this heading variance and frame error (usable ones only; module docstring)."""
        out = []
        frame_var = self.frame_sigma**2
        for inc in increments:
            if not inc.ok:
                out.append(inc)
                continue
            cov = np.array(inc.covariance, dtype=np.float64).reshape(3, 3)
            target = max(float(self.heading_variance(inc.delta[2])), 2.05 * frame_var)
            if not cov[2, 2] > 0:
                out.append(inc)
                continue
            s = np.sqrt(target / cov[2, 2])
            cov[2, :] *= s
            cov[:, 2] *= s
            frame = np.diag([_TRANSLATION_SHARE * cov[0, 0], _TRANSLATION_SHARE * cov[1, 1],
                             max(frame_var, _TRANSLATION_SHARE * target)])
            out.append(replace(inc, covariance=cov, frame_covariance=frame))
        return out

    def describe(self) -> str:
        """One line: what it states."""
        bands = ", ".join(f"{1e6 * s:.1f}" for s in self.heading_sigma)
        edges = ", ".join(f"{e:g}" for e in self.edges)
        return (f"camera heading noise of cam0/sensor.yaml ({self.frontend}, {self.increments} increments): "
                f"σ {bands} µrad from turns of {edges} rad, frame error {1e6 * self.frame_sigma:.1f} µrad")

    def to_dict(self) -> dict:
        return {"frontend": self.frontend, "edges": [float(e) for e in self.edges],
                "heading_sigma": [float(s) for s in self.heading_sigma], "frame_sigma": float(self.frame_sigma),
                "increments": int(self.increments)}

    @classmethod
    def from_file(cls, stated: CameraNoiseFile) -> CameraNoise:
        """The model ``camera_noise`` of a ``cam0/sensor.yaml`` states (checked when the file was read)."""
        return cls(stated.frontend, tuple(float(e) for e in stated.edges),
                   tuple(float(s) for s in stated.heading_sigma), float(stated.frame_sigma), int(stated.increments))

    @classmethod
    def stated(cls, recording) -> CameraNoise | None:
        """The model ``camera_noise`` of a recording's ``cam0/sensor.yaml``, or None when the file does not state
        it."""
        stated = recording.sensor_file("cam0", CameraFile, required=False).camera_noise
        return None if stated is None else cls.from_file(stated)

    @classmethod
    def from_dict(cls, data, path: str | Path | None = None) -> CameraNoise:
        """From the ``camera_noise`` mapping of a ``sensor.yaml`` read from ``path``
        (:class:`~fusion_vo.config.sensor_files.CameraNoiseFile`); a bad value is an :class:`InputError` naming
        its key."""
        return cls.from_file(validate(CameraNoiseFile, data, path, ("camera_noise",)))


def measure(errors: np.ndarray, turns: np.ndarray, chained: np.ndarray, frontend: str,
            edges: tuple[float, ...] = EDGES, horizons: tuple[int, ...] = HORIZONS) -> CameraNoise:
    """The noise model of heading ``errors`` [rad] of increments that turned by ``turns`` [rad, as measured]
    (module docstring); ``chained[k]``: increment ``k`` starts at the frame where ``k - 1`` ends.

    The model's heading error summed over ``n`` consecutive increments has the variance
    ``2 σ_e² + Σ_k σ_w²(band_k)`` (the frame errors within the run cancel). Over runs of each length in
    ``horizons`` (not overlapping; within chained stretches) its squared sums are fitted by that sum,
    non-negative least squares weighted by the inverse square of each run's predicted variance (twice
    reweighted), every horizon with the same total weight: the increments' own variances then describe how the heading error grows over seconds, not
    only from one frame to the next, and a band whose errors persist gets the variance that growth needs.
    """
    from scipy.optimize import nnls

    errors = np.asarray(errors, dtype=np.float64)
    size = np.abs(np.asarray(turns, dtype=np.float64))
    chained = np.asarray(chained, dtype=bool)
    if len(errors) < MIN_BAND:
        raise InputError(f"too few usable increments to measure the camera's noise ({len(errors)}, "
                         f"at least {MIN_BAND})")
    band = np.searchsorted(np.asarray(edges), size, side="right") - 1
    counts = np.bincount(band, minlength=len(edges))
    # bands with too few increments share the nearest populated band's variable
    populated = np.flatnonzero(counts >= MIN_BAND)
    if not len(populated):
        populated = np.array([int(np.argmax(counts))])
    owner = populated[np.argmin(np.abs(np.arange(len(edges))[:, None] - populated[None, :]), axis=1)]
    column = np.searchsorted(populated, owner[band])
    # chained stretches: start indices where a new stretch begins
    starts = np.flatnonzero(~np.concatenate([[False], chained[1:]]))
    stops = np.append(starts[1:], len(errors))
    rows, sums, share = [], [], []
    for n in horizons:
        first = len(rows)
        for a, b in zip(starts, stops):
            for k in range(a, b - n + 1, n):
                x = np.zeros(1 + len(populated))
                x[0] = 2.0
                np.add.at(x, 1 + column[k:k + n], 1.0)
                rows.append(x)
                sums.append(float(np.sum(errors[k:k + n])) ** 2)
        share.extend([1.0 / max(len(rows) - first, 1)] * (len(rows) - first))  # each horizon weighs the same
    A, y, share = np.array(rows), np.array(sums), np.array(share)
    weight = share / np.maximum(A[:, 1:].sum(axis=1), 1.0) ** 2
    theta = np.zeros(A.shape[1])
    for _ in range(3):
        w = np.sqrt(weight)
        theta, _ = nnls(A * w[:, None], y * w)
        predicted = A @ theta
        weight = share / np.maximum(predicted, 1e-3 * float(np.mean(y))) ** 2
    frame_var, band_var = float(theta[0]), theta[1:]
    floor = 1e-4 * float(np.mean(errors**2))
    sigma = [float(np.sqrt(max(band_var[np.searchsorted(populated, owner[b])], floor) + 2.0 * frame_var))
             for b in range(len(edges))]
    return CameraNoise(frontend, tuple(float(e) for e in edges), tuple(sigma), float(np.sqrt(frame_var)),
                       int(len(errors)))
