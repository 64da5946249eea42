"""What StreamingFusion keeps per node and the small pieces its parts share (:mod:`fusion_vo.backends.streaming`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from fusion_vo.backends.config import FusionConfig
from fusion_vo.backends.live_monitor import MonitorState
from fusion_vo.backends.result import SensorCount
from fusion_vo.measurements.grid import outage_notes
from fusion_vo.sensors import registry

logger = logging.getLogger(__name__)


@dataclass
class Estimate:
    """The current estimate: time [s], pose ``(x, y, yaw)`` of B in W, its 3x3 covariance.

    ``predicted`` is how far [s] the pose was predicted beyond the last processed node (0 for a
    processed node). ``twist`` is the body twist ``(v_x, v_y, ω)`` at ``t`` with its 3x3 covariance, for the
    newest node and predictions from it (None for an older node): the EKF's twist state (the mean twist of
    the node's interval, its covariance grown by the prediction); iSAM2, which has no twist variable, the
    twist between the last two nodes with the constant-twist model's process noise over that interval
    (``diag(σ_a², σ_lat², σ_α²) Δt``, a lower bound: it leaves out the nodes' own errors).
    """

    t: float
    pose: np.ndarray
    covariance: np.ndarray
    frame: str = "start"
    predicted: float = 0.0
    twist: np.ndarray | None = None
    twist_covariance: np.ndarray | None = None


@dataclass
class Started:
    """A node whose processing is under way across calls (see ``StreamingFusion._process``)."""

    t0: float
    t1: float
    iv: object  # Intervals
    step: dict  # sensor -> SensorCount of the node's step
    consumed: list  # visual increments taken from the buffer
    monitor: MonitorState  # the heading monitor before the node was added to it
    reach: dict  # stream -> time of the last sample the interval read
    covered: dict  # sensor -> whether its data cover the interval (interval_coverage)
    dropped: frozenset | None = None  # the monitor's decisions, once applied to ``iv``
    factors: list | None = None  # iSAM2: [builder, node factors, linearised factors] (background: None)
    stage: int = 0  # iSAM2: 1 once the factors are built, 2 once linearised


@dataclass
class NodeRecord:
    """What processing one node changed, kept while the node is within the history (EKF rewind)."""

    state: tuple | None  # EKF (x, P) after the node's update
    carry: dict  # sensor -> the value its intervals carry (Intervals.carry) after this node
    counts: dict = field(default_factory=dict)  # sensor -> SensorCount of this node's step
    visual: list = field(default_factory=list)  # increments this node's step consumed
    monitor: MonitorState | None = None  # the heading monitor after this node
    fixes: list = field(default_factory=list)  # GPS fixes this node's step consumed
    gps: tuple | None = None  # GPS bookkeeping after this node (_gps_state)
    dropped: frozenset = frozenset()  # heading components the monitor dropped in this node's interval
    offered: int = 0  # iSAM2: fixes offered to the gate at this node (those without a factor were gated)
    slope: tuple | None = None  # the slope projection factors (cx, cy) of the interval ending at this node
    reach: dict = field(default_factory=dict)  # stream -> time of the last sample its interval read (Started.reach)


def interval_coverage(iv) -> dict[str, bool]:
    """Whether each sensor's data cover the one node interval of ``iv``: ``"camera"`` when a visual increment (or its
    share) is on it, and each registered sensor's coverage label (``"gyro"``, ``"wheel"``, ...) as it reports it."""
    covered = {}
    cam = iv.sensors.get("camera")
    if cam is not None:
        covered["camera"] = bool(len(cam.i0))
    for sensor in registry.sensors():
        if sensor.coverage is not None and sensor.name in iv.sensors:
            label, ok = sensor.coverage(iv)
            covered[label] = bool(len(ok) and ok[-1])
    return covered


def node_outage_notes(t_nodes: list[float], covered: list[dict[str, bool]]) -> list[str]:
    """The notes a batch run gives for the coverage of the intervals between the node times ``t_nodes`` (``covered[k]``
    that of the interval ending at node ``k + 1``, :func:`interval_coverage`), for each sensor that covered at least
    one interval (one that never did is said by its counts): :func:`~fusion_vo.measurements.grid.outage_notes`."""
    T = np.asarray(t_nodes, dtype=np.float64)
    notes = []
    for label in dict.fromkeys(label for c in covered for label in c):  # (the camera's first, then the registry's order)
        ok = np.array([c.get(label, False) for c in covered], dtype=bool)
        if ok.any():
            notes.extend(outage_notes(label, T, ok))
    return notes


def payload_values(payload):
    """The numbers of a live sample's payload that must be finite: its entries that are not None."""
    return [x for x in payload if x is not None] if isinstance(payload, tuple) else payload


def merge_counts(total: dict, part: dict) -> None:
    for sensor, c in part.items():
        own = total.setdefault(sensor, SensorCount())
        for key, value in c.as_dict().items():
            setattr(own, key, getattr(own, key) + value)


def extrapolate(t_nodes, poses, covs, dt: float, config: FusionConfig) -> tuple[np.ndarray, np.ndarray]:
    """Constant-twist prediction of the last pose by ``dt`` from the twist between the last two nodes.

    The covariance is propagated through the motion (a world-frame pose error rotates the
    displacement) and grown by the EKF's acceleration noise integrated over ``dt``.
    """
    pose = poses[-1]
    if len(t_nodes) < 2 or t_nodes[-1] - t_nodes[-2] <= 0:
        twist = np.zeros(3)
    else:
        prev = poses[-2]
        c, s = np.cos(prev[2]), np.sin(prev[2])
        d = pose[:2] - prev[:2]
        dyaw = np.arctan2(np.sin(pose[2] - prev[2]), np.cos(pose[2] - prev[2]))
        twist = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], dyaw]) / (t_nodes[-1] - t_nodes[-2])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    step = twist * dt  # small steps: the body-frame displacement is the twist times dt to first order
    dx = c * step[0] - s * step[1]
    dy = s * step[0] + c * step[1]
    out = np.array([pose[0] + dx, pose[1] + dy, np.arctan2(np.sin(pose[2] + step[2]), np.cos(pose[2] + step[2]))])
    J = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
    q = np.array([config.ekf.accel_sigma, config.ekf.lateral_accel_sigma, config.ekf.yaw_accel_sigma]) ** 2
    rot = np.array([[c, -s], [s, c]])
    Q = np.zeros((3, 3))
    Q[:2, :2] = rot @ np.diag(q[:2]) @ rot.T * dt**3 / 3.0
    Q[2, 2] = q[2] * dt**3 / 3.0
    return out, J @ covs[-1] @ J.T + Q
