"""The common result of the fusion backends and the per-sensor bookkeeping."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fusion_vo.measurements import PoseData, SensorCount
from fusion_vo.outputs import write_atomic

__all__ = ["FusionResult", "SensorCount", "write_pose_covariances", "read_pose_covariances"]


#: what a backend did with a measurement block, as :class:`Innovations` records it
INNOVATION_STATUSES = ("used", "down-weighted", "rejected")


@dataclass
class Innovations:
    """Each measurement block a filter tested against its prediction: when, which sensor, its normalised
    innovation squared and what the gate did with it.

    For a block with innovation ``y = z - h(x⁻)`` and innovation covariance ``S = H P⁻ Hᵀ + R``, the NIS is
    ``d² = yᵀ S⁻¹ y``; with a right noise model it is chi-square distributed with ``dof`` (the block's rows)
    degrees of freedom.

    Attributes
    ----------
    t : ndarray (M,)
        Time of the node the block was applied at [s, recording clock].
    sensor : ndarray (M,) of str
        The measurement model's name (``camera``, ``wheel``, ``gyro``, ``ahrs``, ``still``, ``range``,
        ``gps``, or a registered sensor's).
    d2 : ndarray (M,)
        NIS ``d²`` before any down-weighting.
    dof : ndarray (M,) of int
        Rows of the block.
    status : ndarray (M,) of str
        ``used``, ``down-weighted`` (outside the gate, applied with its covariance inflated onto the gate) or
        ``rejected`` (:data:`INNOVATION_STATUSES`).
    """

    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    sensor: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))
    d2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dof: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def concatenate(cls, tables: list["Innovations"]) -> "Innovations":
        """The rows of several tables (e.g. the pieces of a recording split at pauses), in time order."""
        tables = [tb for tb in tables if len(tb)]
        if not tables:
            return cls()
        out = cls(*(np.concatenate([getattr(tb, name) for tb in tables])
                    for name in ("t", "sensor", "d2", "dof", "status")))
        order = np.argsort(out.t, kind="stable")
        return cls(out.t[order], out.sensor[order], out.d2[order], out.dof[order], out.status[order])


class InnovationLog:
    """Rows of :class:`Innovations` appended one at a time (plain list appends: cheap enough for every
    block of a filter run); :meth:`table` turns them into arrays."""

    def __init__(self) -> None:
        self._rows: list[tuple[float, str, float, int, str]] = []

    def add(self, t: float, sensor: str, d2: float, dof: int, status: str) -> None:
        self._rows.append((t, sensor, d2, dof, status))

    def table(self) -> Innovations:
        if not self._rows:
            return Innovations()
        t, sensor, d2, dof, status = zip(*self._rows)
        return Innovations(np.array(t, dtype=np.float64), np.array(sensor, dtype=object),
                           np.array(d2, dtype=np.float64), np.array(dof, dtype=np.int64),
                           np.array(status, dtype=object))


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
    innovations : dict[str, Innovations]
        Backend -> every measurement block it tested, with its NIS and what the gate did (the EKF's filter
        pass: ``"ekf"``; the smoother and the graph do not test innovations).
    priors : dict[str, dict]
        Calibration state (the keys of ``calibration``) -> ``{"mean": m, "sigma": s}``, the prior the
        backends start from (:func:`fusion_vo.backends.states.calibration_priors`).
    time_offsets : dict[str, float]
        Clock offsets the run estimated and corrected [s]: ``odom_delay``, the odometry twist's delay behind
        the gyro (:func:`fusion_vo.sensors.wheel.synchronise_twist`).
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
    innovations: dict[str, Innovations] = field(default_factory=dict)
    priors: dict[str, dict] = field(default_factory=dict)
    time_offsets: dict[str, float] = field(default_factory=dict)
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
        self.innovations.update(other.innovations)
        self.priors.update(other.priors)
        self.time_offsets.update(other.time_offsets)
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
            "priors": dict(self.priors),
            "time_offsets": dict(self.time_offsets),
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
