"""The common result of the fusion backends and the per-sensor bookkeeping."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fusion_vo.measurements import PoseData


@dataclass
class SensorCount:
    """What happened to one sensor's measurements.

    Attributes
    ----------
    used : int
        Measurements (or node intervals) that entered the estimate.
    gated : int
        Rejected: non-finite, physically impossible (spikes, tick jumps) or outside the Mahalanobis gate.
    late : int
        Arrived after the reorder window had passed their time (streaming) and could not be applied.
    reordered : int
        Arrived out of order but within the window, and were applied in time order.
    missing : int
        Node intervals the sensor did not cover (stream stopped, gaps, failed frames).
    """

    used: int = 0
    gated: int = 0
    late: int = 0
    reordered: int = 0
    missing: int = 0

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class FusionResult:
    """Trajectories and diagnostics of one fusion run.

    Attributes
    ----------
    trajectories : dict[str, PoseData]
        Name (``"ekf"``, ``"ekf_smoothed"``, ``"gtsam"``, ``"gtsam_online"``, ``"gtsam_fixed_lag"``,
        ``"wheel"``) -> poses of B in W at the node times.
    covariances : dict[str, ndarray]
        Name -> (N, 3, 3) covariances of ``(x, y, yaw)`` matching the trajectory's poses.
    counts : dict[str, dict[str, SensorCount]]
        Backend name -> sensor name -> :class:`SensorCount`.
    calibration : dict[str, dict[str, float]]
        Backend name -> self-calibration estimates (``visual_scale``, ``camera_height``,
        ``wheel_base``, ``wheel_base_factor``, ``gyro_bias``).
    notes : list[str]
        Plain-language remarks (camera lost from t=.. to .., streams that stopped, late data).
    timing : dict[str, float]
        CPU seconds per backend (``gtsam_online_per_node_ms``: iSAM2 milliseconds per node).
    inconsistent : list[dict]
        Spans in which a stream's component contradicted the others and was dropped (sensor,
        component, start, end [s on the recording clock], max_nis, against); see
        :mod:`fusion_vo.backends.monitor`.
    pauses : list[dict]
        Pauses in every stream at which the estimate was split (``start``, ``end``, ``seconds`` on the
        recording clock, and ``joined``: ``camera``, ``held`` or ``gps``); see
        :mod:`fusion_vo.backends.pauses`.
    visual_noise : dict
        The camera's heading noise estimated from the gyro's (``fusion.visual_noise.estimate``,
        :class:`~fusion_vo.sensors.visual_noise.VisualNoiseEstimate`); empty when not estimated.
    consistency : list[dict]
        What the pre-fusion consistency checks found (:class:`fusion_vo.consistency.finding.Finding`: check,
        sensor, decision, sentence, estimate), in the order they ran.
    residuals : dict
        Backend -> sensor -> ``(dof, rows)``: the factor graph's per-sensor NIS at its solution, rows
        ``(t, NIS)`` (only with ``GraphConfig.residuals``; :mod:`fusion_vo.backends.residuals`).
    """

    trajectories: dict[str, PoseData] = field(default_factory=dict)
    covariances: dict[str, np.ndarray] = field(default_factory=dict)
    counts: dict[str, dict[str, SensorCount]] = field(default_factory=dict)
    calibration: dict[str, dict[str, float]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)
    inconsistent: list[dict] = field(default_factory=list)
    pauses: list[dict] = field(default_factory=list)
    visual_noise: dict = field(default_factory=dict)
    residuals: dict = field(default_factory=dict)
    consistency: list[dict] = field(default_factory=list)

    @property
    def seconds(self) -> dict[str, float]:
        """CPU seconds per backend (same as ``timing``)."""
        return self.timing

    def merge(self, other: "FusionResult") -> "FusionResult":
        """Add the entries of ``other`` (notes are not repeated)."""
        self.trajectories.update(other.trajectories)
        self.covariances.update(other.covariances)
        self.counts.update(other.counts)
        self.calibration.update(other.calibration)
        self.notes.extend(n for n in other.notes if n not in self.notes)
        self.timing.update(other.timing)
        self.residuals.update(other.residuals)
        return self

    def summary(self) -> dict:
        """A JSON-friendly summary (no arrays)."""
        return {
            "trajectories": {k: len(v) for k, v in self.trajectories.items()},
            "counts": {b: {s: c.as_dict() for s, c in d.items()} for b, d in self.counts.items()},
            "calibration": self.calibration,
            "notes": list(self.notes),
            "timing_s": self.timing,
            "inconsistent": list(self.inconsistent),
            "pauses": list(self.pauses),
            "visual_noise": dict(self.visual_noise),
            "consistency": list(self.consistency),
        }


COV_HEADER = "# timestamp [s],xx,xy,xyaw,yy,yyaw,yawyaw"


def write_pose_covariances(path: str | Path, t: np.ndarray, cov: np.ndarray) -> None:
    """Write ``NAME.cov.csv``: per pose, the upper triangle of the ``(x, y, yaw)`` covariance.

    One comma-separated row per pose of ``NAME.tum`` (same timestamps) after the header
    ``# timestamp [s],xx,xy,xyaw,yy,yyaw,yawyaw``; units m², m², m·rad, m², m·rad, rad². Written
    atomically (a temporary file renamed into place).
    """
    path = Path(path)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    cov = np.asarray(cov, dtype=np.float64).reshape(-1, 3, 3)
    if len(t) != len(cov):
        raise ValueError(f"{len(t)} timestamps but {len(cov)} covariances")
    iu = np.triu_indices(3)
    data = np.column_stack([t, cov[:, iu[0], iu[1]]])
    import io

    from fusion_vo.outputs import write_atomic

    buf = io.StringIO()
    buf.write(COV_HEADER + "\n")
    np.savetxt(buf, data, fmt=["%.9f"] + ["%.9e"] * 6, delimiter=",")
    write_atomic(path, buf.getvalue())  # renamed into place; the mode follows the umask


def read_pose_covariances(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read ``NAME.cov.csv`` back: timestamps (N,) and covariances (N, 3, 3)."""
    data = np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    t = data[:, 0]
    cov = np.zeros((len(data), 3, 3))
    iu = np.triu_indices(3)
    cov[:, iu[0], iu[1]] = data[:, 1:7]
    cov[:, iu[1], iu[0]] = data[:, 1:7]
    return t, cov
