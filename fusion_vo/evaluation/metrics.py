"""Accuracy figures of a planar trajectory against ground truth.

All figures are computed on the floor plane: both trajectories are reduced to ``(x, y, yaw)`` of the
body frame B in the world W (z and roll/pitch dropped). Association, the alignment's fit, the absolute
pose error and the pose pairs of the relative one are evo's (:mod:`evo.core.sync`,
:func:`evo.core.geometry.umeyama_alignment`, :class:`evo.core.metrics.APE`,
:func:`evo.core.metrics.id_pairs_from_delta`); the relative errors over those pairs and the planar rigid moves
are computed here for all poses at once (equal to evo's per-pose SE(3) products to 1e-12, tested), and so are
the figures evo has no name for.

Model
-----
Poses are :math:`T_i = (R(\\psi_i), p_i) \\in SE(2)`, reference :math:`Q_i`, estimate :math:`P_i`,
associated by time (the denser trajectory is interpolated at the stamps of the sparser one).

* ATE (``ate_m``): :math:`\\sqrt{\\tfrac1n \\sum_i \\lVert p^Q_i - (R p^P_i + t)\\rVert^2}` with the
  rotation :math:`R \\in SO(2)` and translation :math:`t` of Umeyama's least-squares fit on the plane.
* Anchored ATE (``ate_anchored_m``): the same with :math:`(R, t)` chosen so that :math:`P_0 = Q_0`;
  this is what a robot that starts from a known pose sees.
* RPE over a distance :math:`d` (``rpe_1m_m``): RMSE of the translation of
  :math:`(Q_i^{-1} Q_j)^{-1} (P_i^{-1} P_j)` over all pairs whose reference path between :math:`i` and
  :math:`j` is :math:`d \\pm 10\\,\\%`; ``rpe_1m_pct`` is that figure as a percentage of :math:`d = 1` m.
  Per frame (``rpe_frame_m``, ``rpe_frame_deg``): consecutive poses.
* Drift (KITTI style, ``drift``): for segment lengths :math:`L` the path allows, the mean relative
  translation error over all segments of length :math:`L` divided by :math:`L` [%], and the mean relative
  rotation divided by :math:`L` [deg/m]; ``drift_pct`` is the mean over the lengths.
* End point (``end_m``, ``end_pct``): distance between the last positions with the estimate anchored at
  the start, and as a percentage of the reference path length.
* Heading (``heading_deg``): absolute difference of the unwrapped yaw at the end, anchored at the start;
  where the reference turns :math:`k` full revolutions (:math:`k \\ge 0.9`, a circle that ends a little
  short counts), ``heading_per_rev_deg`` is that divided by :math:`k` and ``heading_per_rev_pct`` its
  percentage of 360 degrees.
* Velocities (``vx_rmse_m_s``, ``vy_rmse_m_s``, ``yaw_rate_rmse_deg_s``): both trajectories are
  differentiated over the intervals between consecutive estimated poses,
  :math:`v_k = R(\\psi_{k-1})^\\top (p_k - p_{k-1}) / \\Delta t_k`,
  :math:`\\omega_k = \\mathrm{wrap}(\\psi_k - \\psi_{k-1}) / \\Delta t_k`.
* Legs (thesis table 5.2): the reference is cut at its turns (yaw rate above a threshold); per straight leg
  the actual and estimated straight-line length between its end points and the error in %.
"""

from __future__ import annotations

import copy
import logging
import math
from dataclasses import dataclass, field

import numpy as np
from evo.core import filters, geometry, sync
from evo.core.metrics import APE, RPE, PoseRelation, StatisticsType, Unit, id_pairs_from_delta
from evo.core.sync_method import SyncMethod
from evo.core.trajectory import PoseTrajectory3D
from scipy.spatial.transform import Rotation

from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.measurements import GpsData, PoseData

logger = logging.getLogger(__name__)

#: KITTI-style segment lengths [m]; those longer than the path are skipped
SEGMENT_LENGTHS = (0.5, 1.0, 2.0, 5.0)

#: largest time difference [s] for associating an estimated pose with a reference pose
MAX_TIME_DIFF = 0.02

#: a path that turns at least this many full revolutions gets a heading error per revolution
MIN_REVOLUTIONS = 0.9

#: relative tolerance on the reference path length of an RPE pair (evo's ``rel_delta_tol``)
REL_DELTA_TOL = 0.1

#: above this many associated poses, RPE uses consecutive instead of all pairs (cost is quadratic)
ALL_PAIRS_LIMIT = 5000


@dataclass
class Velocities:
    """Body-frame velocities over consecutive intervals, stamped at the interval's end.

    Attributes
    ----------
    t : ndarray
        Time [s] at the end of each interval.
    vx, vy : ndarray
        Forward and leftward velocity [m/s] in the body frame at the interval's start.
    yaw_rate : ndarray
        Yaw rate [rad/s].
    """

    t: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    yaw_rate: np.ndarray


@dataclass
class Leg:
    """A straight stretch of the reference path between two turns.

    Attributes
    ----------
    t_start, t_end : float
        Time span [s].
    start_xy, end_xy : tuple of float
        Reference positions [m] at the start and end.
    length_m : float
        Straight-line distance between start and end [m].
    """

    t_start: float
    t_end: float
    start_xy: tuple[float, float]
    end_xy: tuple[float, float]
    length_m: float


@dataclass
class TrajectoryErrors:
    """Figures of one estimated trajectory plus the series the plots need.

    Attributes
    ----------
    figures : dict
        Named scalar figures (see the module docstring) and ``drift`` and ``legs`` tables.
    reference : PoseTrajectory3D
        Planar reference poses associated with the estimate.
    anchored : PoseTrajectory3D
        Planar estimate, transformed so that its first pose is the reference's.
    aligned : PoseTrajectory3D
        Planar estimate after the least-squares SE(2) alignment.
    distance : ndarray
        Reference distance travelled [m] at each associated pose.
    error_m : ndarray
        Position error [m] of the anchored estimate at each associated pose.
    velocities : Velocities
        Velocities of the estimate.
    reference_velocities : Velocities
        Reference velocities over the same intervals.
    """

    figures: dict
    reference: PoseTrajectory3D
    anchored: PoseTrajectory3D
    aligned: PoseTrajectory3D
    distance: np.ndarray
    error_m: np.ndarray
    velocities: Velocities
    reference_velocities: Velocities = field(repr=False)


def yaw_of(trajectory: PoseTrajectory3D) -> np.ndarray:
    """Yaw [rad] of each pose (rotation about the world z axis, ZYX convention), in (-pi, pi]."""
    return se2.yaw_of_quaternion(trajectory.orientations_quat_wxyz)


def planar_trajectory(t: np.ndarray, x: np.ndarray, y: np.ndarray, yaw: np.ndarray,
                      name: str | None = None) -> PoseTrajectory3D:
    """Build a trajectory with ``z = 0`` and rotations about z only."""
    t = np.asarray(t, dtype=float)
    xyz = np.column_stack([x, y, np.zeros_like(t)])
    quat = se2.quaternion_of_yaw(yaw)
    return PoseTrajectory3D(xyz, quat, t, name=name)


def to_planar(trajectory: PoseTrajectory3D) -> PoseTrajectory3D:
    """Project a trajectory onto the floor: keep x, y and yaw, drop z, roll and pitch."""
    xy = trajectory.positions_xyz[:, :2]
    return planar_trajectory(trajectory.timestamps, xy[:, 0], xy[:, 1], yaw_of(trajectory),
                             name=trajectory.name)


def associate(reference: PoseTrajectory3D, estimate: PoseTrajectory3D,
              max_diff: float = MAX_TIME_DIFF) -> tuple[PoseTrajectory3D, PoseTrajectory3D]:
    """Pair poses by time with evo (the denser trajectory is interpolated at the sparser one's stamps).

    Raises
    ------
    InputError
        If fewer than two poses can be paired.
    """
    try:
        ref, est = sync.associate_trajectories(reference, estimate, max_diff=max_diff,
                                               sync_method=SyncMethod.interpolation)
    except sync.SyncException:
        ref = None
    if ref is None or ref.num_poses < 2:
        raise InputError(f"fewer than two poses match the ground truth in time (max. difference "
                         f"{max_diff} s); do the timestamps share the recording's clock?")
    return ref, est


def transform_2d(trajectory: PoseTrajectory3D, rotation: np.ndarray,
                 translation: np.ndarray) -> PoseTrajectory3D:
    """Copy of the planar ``trajectory`` with the rigid transform ``p -> R p + t`` applied on the left
    (positions :math:`R p_k + t`, headings :math:`\\psi_k + \\angle R`)."""
    rotation = np.asarray(rotation, dtype=float)
    xy = trajectory.positions_xyz[:, :2] @ rotation.T + np.asarray(translation, dtype=float)
    yaw = yaw_of(trajectory) + math.atan2(rotation[1, 0], rotation[0, 0])
    return planar_trajectory(trajectory.timestamps, xy[:, 0], xy[:, 1], yaw, name=trajectory.name)


def align_se2(reference: PoseTrajectory3D, estimate: PoseTrajectory3D) -> PoseTrajectory3D:
    """Least-squares SE(2) alignment of associated planar trajectories (Umeyama on x, y, via evo).

    Falls back to anchoring at the first pose when the positions do not determine a rotation (robot
    standing still).
    """
    try:
        rotation, translation, _ = geometry.umeyama_alignment(
            estimate.positions_xyz[:, :2].T, reference.positions_xyz[:, :2].T, with_scale=False)
    except geometry.GeometryException:
        logger.debug("degenerate positions, aligning %s at its first pose instead", estimate.name)
        return anchor(reference, estimate)
    return transform_2d(estimate, rotation, translation)


def anchor(reference: PoseTrajectory3D, estimate: PoseTrajectory3D) -> PoseTrajectory3D:
    """Copy of the planar ``estimate`` moved rigidly so that its first pose equals the reference's first pose:
    :func:`transform_2d` by :math:`Q_0 P_0^{-1}`."""
    first = [reference.orientations_quat_wxyz[0], estimate.orientations_quat_wxyz[0]]
    turn = float(np.subtract(*se2.yaw_of_quaternion(first)))
    c, s = math.cos(turn), math.sin(turn)
    rotation = np.array([[c, -s], [s, c]])
    return transform_2d(estimate, rotation, reference.positions_xyz[0, :2] - rotation @ estimate.positions_xyz[0, :2])


def gps_errors(track: PoseData, gps: GpsData) -> np.ndarray:
    """Horizontal distances [m] of a track to the GPS fixes within its time span, after the least-squares SE(2)
    alignment to them (the fixes' local east and north, :attr:`fusion_vo.measurements.GpsData.enu`)."""
    inside = (gps.t >= track.t[0]) & (gps.t <= track.t[-1])
    enu = gps.enu[inside]
    reference = planar_trajectory(gps.t[inside], enu[:, 0], enu[:, 1], np.zeros(len(enu)))
    estimate = planar_trajectory(track.t, track.xyyaw[:, 0], track.xyyaw[:, 1], track.xyyaw[:, 2])
    ref, est = associate(reference, estimate)
    aligned = align_se2(ref, est)
    return np.linalg.norm(aligned.positions_xyz[:, :2] - ref.positions_xyz[:, :2], axis=1)


def ape_rmse(reference: PoseTrajectory3D, estimate: PoseTrajectory3D) -> float:
    """RMSE [m] of evo's APE on the translation part."""
    ape = APE(PoseRelation.translation_part)
    ape.process_data((reference, estimate))
    return float(ape.get_statistic(StatisticsType.rmse))


def rpe_pairs(reference: PoseTrajectory3D, delta: float, unit: Unit) -> np.ndarray:
    """Index pairs ``(i, j)`` of the reference over which RPE is taken: evo's
    :func:`~evo.core.metrics.id_pairs_from_delta` (``delta`` frames, or metres of reference path within
    :data:`REL_DELTA_TOL`; all overlapping pairs unless the trajectory is very long). Shape ``(k, 2)``, empty
    when no pair has the requested spacing.

    evo reads only the positions of the poses it is given, so it gets 4x4 matrices holding those alone, not
    the trajectory's full poses (built one quaternion at a time).
    """
    positions = np.zeros((reference.num_poses, 4, 4))
    positions[:, :3, 3] = reference.positions_xyz
    try:
        return np.array(id_pairs_from_delta(positions, delta, unit, REL_DELTA_TOL, _all_pairs(reference, unit)),
                        dtype=int)
    except filters.FilterException:
        return np.zeros((0, 2), dtype=int)


def _all_pairs(reference: PoseTrajectory3D, unit: Unit) -> bool:
    """Whether RPE takes every overlapping pair: over path lengths, unless the trajectory is very long."""
    return unit != Unit.frames and reference.num_poses <= ALL_PAIRS_LIMIT


def translation_errors(reference: PoseTrajectory3D, estimate: PoseTrajectory3D, pairs: np.ndarray) -> np.ndarray:
    """Norm of the translation of evo's RPE error pose :math:`E = (Q_i^{-1} Q_j)^{-1} (P_i^{-1} P_j)` per pair.

    The translation of :math:`E` is :math:`R(Q_i^{-1} Q_j)^\\top (t^P_{ij} - t^Q_{ij})` with
    :math:`t^P_{ij} = R_{P_i}^\\top (p_j - p_i)`, so its norm is :math:`\\lVert t^P_{ij} - t^Q_{ij} \\rVert`:
    computed for all pairs at once instead of evo's three SE(3) inversions per pair."""
    if len(pairs) == 0:
        return np.zeros(0)
    i, j = pairs.T

    def relative(trajectory: PoseTrajectory3D) -> np.ndarray:
        rot = Rotation.from_quat(trajectory.orientations_quat_wxyz[i], scalar_first=True).as_matrix()
        xyz = trajectory.positions_xyz
        return np.einsum("nki,nk->ni", rot, xyz[j] - xyz[i])

    return np.linalg.norm(relative(estimate) - relative(reference), axis=1)


def rpe_errors(reference: PoseTrajectory3D, estimate: PoseTrajectory3D, delta: float, unit: Unit,
               relation: PoseRelation = PoseRelation.translation_part) -> np.ndarray:
    """Errors of evo's RPE over ``delta`` (frames or metres of reference path) on the pairs of
    :func:`rpe_pairs`: the translation part by :func:`translation_errors`, any other ``relation`` by evo.
    Returns an empty array when no pair has the requested spacing.
    """
    if relation == PoseRelation.translation_part:
        return translation_errors(reference, estimate, rpe_pairs(reference, delta, unit))
    rpe = RPE(relation, delta=delta, delta_unit=unit, rel_delta_tol=REL_DELTA_TOL,
              all_pairs=_all_pairs(reference, unit), pairs_from_reference=True)
    try:
        rpe.process_data((reference, estimate))
    except filters.FilterException:
        return np.array([])
    return np.asarray(rpe.error, dtype=float)


def relative_yaw_errors(reference: PoseTrajectory3D, estimate: PoseTrajectory3D, delta: float,
                        unit: Unit, pairs: np.ndarray | None = None) -> np.ndarray:
    """Absolute errors [deg] of the heading change over the pose pairs :func:`rpe_pairs` gives (or ``pairs``).

    On the plane the rotation angle of the RPE is the difference of the yaw increments; computing it from
    yaw is much faster than evo's SO(3) logarithm per pair, with the same result.
    """
    pairs = rpe_pairs(reference, delta, unit) if pairs is None else pairs
    if len(pairs) == 0:
        return np.array([])
    i, j = pairs.T
    ref_yaw, est_yaw = yaw_of(reference), yaw_of(estimate)
    return np.degrees(np.abs(se2.wrap_angle((est_yaw[j] - est_yaw[i]) - (ref_yaw[j] - ref_yaw[i]))))


def _rmse(values: np.ndarray) -> float:
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(values**2))) if values.size else math.nan


def body_velocities(trajectory: PoseTrajectory3D) -> Velocities:
    """Differentiate a planar trajectory over consecutive poses (see the module docstring)."""
    t = trajectory.timestamps
    xy = trajectory.positions_xyz[:, :2]
    yaw = yaw_of(trajectory)
    dt = np.diff(t)
    dx, dy = np.diff(xy, axis=0).T
    c, s = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    with np.errstate(divide="ignore", invalid="ignore"):
        vx = (c * dx + s * dy) / dt
        vy = (-s * dx + c * dy) / dt
        yaw_rate = se2.wrap_angle(np.diff(yaw)) / dt
    return Velocities(t[1:], vx, vy, yaw_rate)


def reference_velocities(reference: PoseTrajectory3D, stamps: np.ndarray) -> Velocities:
    """Differentiate the reference over the intervals between ``stamps`` (inside its time span)."""
    stamps = np.asarray(stamps, dtype=float)
    stamps = stamps[(stamps >= reference.timestamps[0]) & (stamps <= reference.timestamps[-1])]
    if stamps.size < 2:
        empty = np.array([])
        return Velocities(empty, empty, empty, empty)
    return body_velocities(reference.interpolate(stamps))


def _cumulative_distance(trajectory: PoseTrajectory3D) -> np.ndarray:
    steps = np.linalg.norm(np.diff(trajectory.positions_xyz[:, :2], axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def detect_legs(reference: PoseTrajectory3D, turn_rate: float = 0.35, smoothing_s: float = 0.25,
                min_length: float = 0.1, max_leg_turn_deg: float = 30.0) -> list[Leg]:
    """Cut the reference path into straight legs at its turns.

    A sample belongs to a turn where the yaw rate, averaged over ``smoothing_s``, exceeds ``turn_rate``
    [rad/s]. The stretches in between are legs if their end points are at least ``min_length`` [m] apart
    and the heading changes by less than ``max_leg_turn_deg`` along them (a slow arc is not a leg).

    Parameters
    ----------
    reference : PoseTrajectory3D
        Ground truth (any pose rate; it is reduced to the plane here).

    Returns
    -------
    list of Leg
        In time order; empty for a path without straight stretches (e.g. a circle).
    """
    ref = to_planar(reference)
    t = ref.timestamps
    if t.size < 3:
        return []
    yaw = np.unwrap(yaw_of(ref))
    rate = np.gradient(yaw, t)
    width = max(1, int(round(smoothing_s / max(float(np.median(np.diff(t))), 1e-6))))
    rate = np.convolve(rate, np.ones(width) / width, mode="same")
    straight = np.abs(rate) <= turn_rate
    edges = np.diff(np.concatenate([[0], straight.astype(int), [0]]))
    starts, ends = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    xy = ref.positions_xyz[:, :2]
    legs = []
    for i, j in zip(starts, ends):
        length = float(np.linalg.norm(xy[j] - xy[i]))
        turned = math.degrees(float(np.ptp(yaw[i:j + 1])))
        if j <= i or length < min_length or turned > max_leg_turn_deg:
            continue
        legs.append(Leg(float(t[i]), float(t[j]), (float(xy[i, 0]), float(xy[i, 1])),
                        (float(xy[j, 0]), float(xy[j, 1])), length))
    return legs


def _pose_at(trajectory: PoseTrajectory3D, stamp: float) -> tuple[np.ndarray, float]:
    pose = trajectory.interpolate(np.array([stamp]))
    return pose.positions_xyz[0, :2], float(yaw_of(pose)[0])


def leg_errors(reference: PoseTrajectory3D, estimate: PoseTrajectory3D, legs: list[Leg],
               max_diff: float = MAX_TIME_DIFF) -> list[dict]:
    """Per-leg table (thesis table 5.2) for the legs inside the estimate's time span.

    ``error_pct`` compares the straight-line lengths, ``relative_error_pct`` the whole displacement
    expressed in the body frame at the leg's start (so it also counts a wrong direction). Legs that
    start or end more than ``max_diff`` outside the estimate's time span are left out.
    """
    rows = []
    t0, t1 = estimate.timestamps[0], estimate.timestamps[-1]
    for number, leg in enumerate(legs, start=1):
        if leg.t_start < t0 - max_diff or leg.t_end > t1 + max_diff:
            continue
        q0, qyaw = _pose_at(reference, leg.t_start)
        q1, _ = _pose_at(reference, leg.t_end)
        p0, pyaw = _pose_at(estimate, leg.t_start)
        p1, _ = _pose_at(estimate, leg.t_end)
        actual = float(np.linalg.norm(q1 - q0))
        estimated = float(np.linalg.norm(p1 - p0))
        rq = np.array([[math.cos(qyaw), math.sin(qyaw)], [-math.sin(qyaw), math.cos(qyaw)]])
        rp = np.array([[math.cos(pyaw), math.sin(pyaw)], [-math.sin(pyaw), math.cos(pyaw)]])
        relative = float(np.linalg.norm(rp @ (p1 - p0) - rq @ (q1 - q0)))
        rows.append({
            "leg": number,
            "t_start": leg.t_start,
            "t_end": leg.t_end,
            "start": list(leg.start_xy),
            "end": list(leg.end_xy),
            "actual_m": actual,
            "estimated_m": estimated,
            "error_pct": 100.0 * abs(estimated - actual) / actual if actual > 0 else math.nan,
            "relative_error_pct": 100.0 * relative / actual if actual > 0 else math.nan,
        })
    return rows


def evaluate_trajectory(reference: PoseTrajectory3D, estimate: PoseTrajectory3D,
                        legs: list[Leg] | None = None,
                        segment_lengths: tuple[float, ...] = SEGMENT_LENGTHS,
                        max_diff: float = MAX_TIME_DIFF) -> TrajectoryErrors:
    """Compute all figures of one estimate against the ground truth.

    Parameters
    ----------
    reference : PoseTrajectory3D
        Ground truth, any rate; only the part overlapping the estimate in time is used.
    estimate : PoseTrajectory3D
        Estimated poses of the body frame.
    legs : list of Leg, optional
        Legs of the reference (see :func:`detect_legs`); no leg table if omitted.
    segment_lengths : tuple of float
        Segment lengths [m] for the drift figures.
    max_diff : float
        Largest time difference [s] for associating poses.

    Returns
    -------
    TrajectoryErrors

    Raises
    ------
    InputError
        If fewer than two poses overlap the reference in time.
    """
    ref_full = to_planar(reference)
    est_full = to_planar(estimate)
    ref, est = associate(ref_full, est_full, max_diff)
    aligned = align_se2(ref, est)
    anchored = anchor(ref, est)

    span = copy.deepcopy(ref_full)
    span.reduce_to_time_range(ref.timestamps[0], ref.timestamps[-1])
    if span.num_poses >= 2:
        distance = np.interp(ref.timestamps, span.timestamps, _cumulative_distance(span))
    else:
        distance = _cumulative_distance(ref)
    path_length = float(distance[-1])

    error = np.linalg.norm(anchored.positions_xyz[:, :2] - ref.positions_xyz[:, :2], axis=1)
    end_m = float(error[-1])
    ref_yaw = np.unwrap(yaw_of(ref))
    est_yaw = np.unwrap(yaw_of(anchored))
    heading = math.degrees(abs((est_yaw[-1] - est_yaw[0]) - (ref_yaw[-1] - ref_yaw[0])))
    revolutions = abs(ref_yaw[-1] - ref_yaw[0]) / (2.0 * math.pi)

    rpe_1m = rpe_errors(ref, est, 1.0, Unit.meters)
    frame_pairs = rpe_pairs(ref, 1, Unit.frames)
    drift = []
    for length in segment_lengths:
        if length > path_length:
            continue
        pairs = rpe_pairs(ref, length, Unit.meters)
        if len(pairs) == 0:
            continue
        trans = translation_errors(ref, est, pairs)
        rot = relative_yaw_errors(ref, est, length, Unit.meters, pairs)
        drift.append({"length_m": length, "segments": int(trans.size),
                      "trans_pct": 100.0 * float(np.mean(trans)) / length,
                      "rot_deg_per_m": float(np.mean(rot)) / length})

    est_vel = body_velocities(est_full)
    ref_vel = reference_velocities(ref_full, est_full.timestamps)
    inside = np.isin(est_vel.t, ref_vel.t)
    vel_err = {k: getattr(est_vel, k)[inside] - getattr(ref_vel, k) for k in ("vx", "vy", "yaw_rate")}

    figures = {
        "poses": int(ref.num_poses),
        "duration_s": float(ref.timestamps[-1] - ref.timestamps[0]),
        "path_length_m": path_length,
        "ate_m": ape_rmse(ref, aligned),
        "ate_anchored_m": ape_rmse(ref, anchored),
        "ate_anchored_max_m": float(np.max(error)),
        "rpe_1m_m": _rmse(rpe_1m),
        "rpe_1m_pct": 100.0 * _rmse(rpe_1m),
        "rpe_frame_m": _rmse(translation_errors(ref, est, frame_pairs)),
        "rpe_frame_deg": _rmse(relative_yaw_errors(ref, est, 1, Unit.frames, frame_pairs)),
        "drift_pct": float(np.mean([d["trans_pct"] for d in drift])) if drift else math.nan,
        "drift": drift,
        "end_m": end_m,
        "end_pct": 100.0 * end_m / path_length if path_length > 1e-9 else math.nan,
        "heading_deg": heading,
        "revolutions": revolutions,
        "heading_per_rev_deg": heading / revolutions if revolutions >= MIN_REVOLUTIONS else math.nan,
        "heading_per_rev_pct": (100.0 * heading / revolutions / 360.0 if revolutions >= MIN_REVOLUTIONS
                                else math.nan),
        "vx_rmse_m_s": _rmse(vel_err["vx"]),
        "vy_rmse_m_s": _rmse(vel_err["vy"]),
        "yaw_rate_rmse_deg_s": math.degrees(_rmse(vel_err["yaw_rate"])),
        "legs": leg_errors(ref_full, est_full, legs or [], max_diff),
    }
    return TrajectoryErrors(figures, ref, anchored, aligned, distance, error, est_vel, ref_vel)

