"""The common result of the fusion backends and the per-sensor bookkeeping."""

from __future__ import annotations

from dataclasses import dataclass, field

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
    """

    trajectories: dict[str, PoseData] = field(default_factory=dict)
    covariances: dict[str, np.ndarray] = field(default_factory=dict)
    counts: dict[str, dict[str, SensorCount]] = field(default_factory=dict)
    calibration: dict[str, dict[str, float]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    timing: dict[str, float] = field(default_factory=dict)
    inconsistent: list[dict] = field(default_factory=list)

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
        }
