"""Visual increment as a measurement of the body motion, up to the visual scale.

A frontend's similarity between two frames, projected to the ground (:mod:`fusion_vo.geometry.ground`),
is the body motion between the frames with its translation in units of the configured camera height::

    z = h(δ, k_v) + n,     h = (k_v d_x, k_v d_y, d_ψ),     n ~ N(0, Σ_vis)

with ``k_v = h_configured / h_true`` (the visual scale) and ``Σ_vis`` the frontend's covariance.
Jacobians: ``∂h/∂δ = diag(k_v, k_v, 1)``, ``∂h/∂k_v = (d_x, d_y, 0)ᵀ``.

Frame errors. A frontend that measures each frame against the previous one (KLT tracks the points from
where it found them in the previous frame) puts a frame's own measurement error into both increments
that frame belongs to, with opposite signs: consecutive increments' errors are negatively correlated and
the sum of many increments is better than independent increments with the stated covariance say. With
``visual_frame_error = f > 0`` (:class:`~fusion_vo.backends.config.FusionConfig`) the noise of the
increment from frame ``a`` to frame ``b`` is modelled as moving-average::

    n = e_b - e_a + w,     e ~ N(0, f/2 Σ_vis),     w ~ N(0, (1 - f) Σ_vis)

so one increment's total covariance stays ``Σ_vis`` and consecutive ones correlate at ``-f/2``. The EKF
carries the errors of the previous and the current frame in its state (:func:`frame_error_cov`,
:func:`ekf_blocks`): each prediction shifts the current frame's error into the previous one's place
(which marginalises the older one) and starts the new frame's at zero with covariance ``f/2 Σ_vis``;
the update then has ``∓I/Δt`` in their columns. The factor graph gives each frame a pose ``F_k`` tied
to the node's pose by this model with a zero reading and ``f/2 Σ_vis`` (in the increments' units, through
the visual scale when it is estimated; else ``BetweenFactorPose2(X_k, F_k, identity, f/2 Σ_vis)``) and
puts the increment between the frame poses with ``(1 - f) Σ_vis`` (:func:`graph_factors`).

An increment may instead state its frames' error itself
(:attr:`~fusion_vo.measurements.VisualIncrement.frame_covariance` ``Σ_e``, e.g. from a noise calibration
of the camera, :mod:`fusion_vo.calibration.camera_noise`): then ``e ~ N(0, Σ_e)`` and
``w ~ N(0, Σ_vis - 2 Σ_e)``, the same model with a frame error of its own size and axes rather than a fixed
share of every increment's covariance (:func:`frame_covariances`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion_vo.geometry import se2
from fusion_vo.sensors.model import MeasurementModel, scaled_motion
from fusion_vo.sensors.registry import Live, Sensor, Step, register
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import node_indices, uncovered_runs, when


@dataclass(frozen=True)
class VisualModel(MeasurementModel):
    """The visual increment (module docstring); arguments ``motion``, ``visual_scale``."""

    name: str = "camera"
    args: tuple = ("motion", "visual_scale")
    dim: int = 3
    turn_rows: tuple = (2,)

    def evaluate(self, motion, visual_scale):
        one = 1.0 if np.ndim(motion) == 1 else np.ones_like(np.asarray(visual_scale, dtype=np.float64))
        h, j_d, j_k, _ = scaled_motion(motion, visual_scale, one)
        return h, {"motion": j_d, "visual_scale": j_k}


VISUAL = VisualModel()


# --------------------------------------------------------------------------- registration
def add_intervals(iv, streams, config, counts) -> None:
    """The usable increments onto the node grid (``Intervals.vis_*``), projected to the horizontal; camera
    outages become notes.

    Every check is one array operation over all increments (the increments' times, readings and
    covariances stacked once), not a loop of small numpy calls per increment: a 60 s drive at 20 Hz
    has 1200 of them.
    """

    visual, notes = streams.visual, iv.notes
    count = counts.setdefault("camera", SensorCount())
    T = iv.t
    n = len(visual)
    t0 = np.array([inc.t0 for inc in visual], dtype=np.float64)
    t1 = np.array([inc.t1 for inc in visual], dtype=np.float64)
    ok = np.array([inc.ok for inc in visual], dtype=bool)
    # out of order: an increment ending before an earlier one ended
    before = np.fmax.accumulate(np.concatenate([[-np.inf], t1]))[:-1]  # (fmax: a NaN time moves nothing)
    count.reordered += int(np.count_nonzero(t1 < before))
    count.missing += int(np.count_nonzero(~ok))
    delta, cov = np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan)
    for i in np.flatnonzero(ok):  # (only the usable ones are read: a failed frame's may be anything)
        delta[i] = np.asarray(visual[i].delta, dtype=np.float64).reshape(3)
        cov[i] = np.asarray(visual[i].covariance, dtype=np.float64).reshape(3, 3)
    good = ok & np.isfinite(delta).all(axis=1) & np.isfinite(cov).all(axis=(1, 2)) & (t1 > t0)
    if good.any():  # positive definite
        sym = 0.5 * (cov[good] + np.transpose(cov[good], (0, 2, 1)))
        good[np.flatnonzero(good)] = np.all(np.linalg.eigvalsh(sym) > 0, axis=1)
    i0, i1 = node_indices(T, t0), node_indices(T, t1)
    good &= (i0 >= 0) & (i1 > i0)
    count.gated += int(np.count_nonzero(ok & ~good))
    keep = np.flatnonzero(good)
    keep = keep[np.argsort(t1[keep], kind="stable")]
    if len(keep):
        iv.vis_i0, iv.vis_i1 = i0[keep], i1[keep]
        iv.vis_delta, iv.vis_cov = delta[keep], cov[keep]
        # slope: mean projection factors over the spanned intervals (a single interval's is its own)
        cx, cy = iv.cx[iv.vis_i0], iv.cy[iv.vis_i0]
        for m in np.flatnonzero(iv.vis_i1 - iv.vis_i0 > 1):
            a, b = iv.vis_i0[m], iv.vis_i1[m]
            cx[m], cy[m] = iv.cx[a:b].mean(), iv.cy[a:b].mean()
        iv.vis_delta[:, 0] *= cx
        iv.vis_delta[:, 1] *= cy
    count.used += len(keep)
    stated = [visual[i].frame_covariance for i in keep]
    if any(c is not None for c in stated):
        iv.vis_frame_cov = _stated_frame_cov(stated, iv.vis_cov)
    edges = np.zeros(len(T), dtype=np.int64)  # covered intervals: +1 where an increment starts, -1 where it ends
    np.add.at(edges, iv.vis_i0, 1)
    np.add.at(edges, iv.vis_i1, -1)
    covered = np.cumsum(edges)[:-1] > 0
    for a, b in uncovered_runs(T, covered, 0.2):
        notes.append(f"camera lost from {when(a, T)} to {when(b, T)}; the other sensors carried the estimate")


def _stated_frame_cov(stated: list, cov: np.ndarray) -> np.ndarray:
    """The increments' own ``frame_covariance`` s (M, 3, 3), kept below half of their covariance so that ``w`` keeps a positive definite covariance (at most 0.49 of it along every
    direction); an increment that states none gets a negligible one (1e-6 of its covariance: its frames'
    errors remain states of the backends)."""
    out = np.empty_like(cov)
    for m, c in enumerate(stated):
        if c is None:
            out[m] = 1e-6 * cov[m]
            continue
        c = np.asarray(c, dtype=np.float64).reshape(3, 3)
        # largest share of cov[m] that c takes in any direction: eigenvalues of L⁻¹ c L⁻ᵀ
        L = np.linalg.cholesky(cov[m])
        Li = np.linalg.inv(L)
        share = float(np.max(np.linalg.eigvalsh(Li @ (0.5 * (c + c.T)) @ Li.T)))
        out[m] = c * min(1.0, 0.49 / share) if share > 0 else 1e-6 * cov[m]
    return out


def frame_covariances(iv) -> np.ndarray | None:
    """Covariance of each increment's frames' own errors (M, 3, 3): the increments' own
    (:attr:`Intervals.vis_frame_cov`), else ``f/2`` of their covariance with ``visual_frame_error = f > 0``;
    None: independent increments."""
    if iv.vis_frame_cov is not None:
        return iv.vis_frame_cov
    f = iv.visual_frame_error
    return 0.5 * f * iv.vis_cov if f > 0 else None


def ekf_measurements(iv, config) -> dict:
    """The increments as twists per node interval: ``visual`` -> (ok, u, R) (EKF module docstring); an increment
    spanning ``n`` intervals is applied as its mean twist to each with covariance ``n R``."""
    if not len(iv.vis_i0):
        return {}
    K = iv.n_steps
    vis_u = np.zeros((K, 3))
    vis_R = np.zeros((K, 3, 3))
    vis_ok = np.zeros(K, bool)
    span = iv.t[iv.vis_i1] - iv.t[iv.vis_i0]
    n = iv.vis_i1 - iv.vis_i0
    for m in np.argsort(n, kind="stable"):  # single-interval increments first
        steps = np.arange(iv.vis_i0[m], iv.vis_i1[m])
        free = steps[~vis_ok[steps]]
        if len(free) == 0:
            continue
        vis_u[free] = se2.log(iv.vis_delta[m]) / span[m]
        vis_R[free] = iv.vis_cov[m] * (n[m] / span[m] ** 2)
        vis_ok[free] = True
    out = {"visual": (vis_ok, vis_u, vis_R)}
    fc = frame_covariances(iv)
    if fc is not None:  # single-interval increments: their frames' errors and the rest (module docstring)
        single = np.zeros(K, bool)
        frame_cov = np.full((K, 3, 3), np.nan)
        rest_R = np.full((K, 3, 3), np.nan)
        one = iv.vis_i1 - iv.vis_i0 == 1
        k = iv.vis_i0[one]
        single[k] = True
        frame_cov[k] = fc[one]
        rest_R[k] = (iv.vis_cov[one] - 2.0 * fc[one]) / (span[one] ** 2)[:, None, None]
        out["visual_frames"] = (single, frame_cov, iv.dt.copy(), rest_R)
    return out


def frame_error_cov(meas: dict, k: int) -> np.ndarray | None:
    """Covariance of the camera's error at the frame that ends interval ``k`` (``f/2 Σ_vis`` of the increment
    over that interval), or None where no single-interval increment ends there (the EKF keeps the last)."""
    m = meas.get("visual_frames")
    return m[1][k] if m is not None and m[0][k] else None


def ekf_blocks(ekf, meas: dict, k: int) -> list:
    """The increment of interval ``k`` as a block; with frame errors in the state (module docstring) its noise
    is ``(1 - f) R`` (``R - 2 Σ_e / Δt²`` with the increments' own frame covariances) and the two frames'
    errors enter as ``(e_this - e_prev) / Δt``."""
    m = meas.get("visual")
    if m is None or not m[0][k]:
        return []
    frames = meas.get("visual_frames")
    if ekf.frame_errors is None or frames is None or not frames[0][k]:
        return [ekf.block(VISUAL, m[1][k], m[2][k])]
    name, z, h, H, R, angle = ekf.block(VISUAL, m[1][k], frames[3][k])
    e0, e1 = ekf.frame_errors
    x = ekf.x
    inv_dt = 1.0 / frames[2][k]
    H[:, e0] -= np.eye(3) * inv_dt
    H[:, e1] += np.eye(3) * inv_dt
    return [(name, z, h + (x[e1] - x[e0]) * inv_dt, H, R, angle)]


def graph_factors(builder, nf, node) -> None:
    """The increments ending at this node (re-expressed between keyframes): the model with the visual scale
    when it is estimated, else GTSAM's ``BetweenFactorPose2``."""
    import gtsam

    est = node.estimate
    for start, d, cov, fc in builder.visual_spans.get(node.n, []):
        xs, xj = builder.X(builder.offset + start), node.xj
        if fc is not None:
            frames = _frame_poses(builder, nf, node, start, fc)
            if frames is not None:
                (xs, xj), cov = frames, cov - 2.0 * fc
        if builder.kv_on:
            nf.factors.append(builder.model_factor(VISUAL, d, cov, {"motion": (xs, xj),
                                                                     "visual_scale": (builder.S(node.segment),)}))
        else:
            nf.factors.append(gtsam.BetweenFactorPose2(xs, xj, gtsam.Pose2(*d), builder.noise(cov)))
        nf.sensors.append("camera")
        if start == node.n - 1:
            if node.translation is None:
                node.translation = d[:2] / est.get("visual_scale", 1.0)
            if node.heading is None:
                node.heading = d[2]


def _frame_poses(builder, nf, node, start: int, frame_cov) -> tuple[int, int] | None:
    """The frame poses ``F`` of an increment's first and last node (module docstring), each made with its
    tie ``X⁻¹ F ~ N(0, frame_cov)`` the first time an increment touches it; None when the first node's
    frame pose does not exist and that node is not the previous one (whose current estimate starts it)."""
    import gtsam

    a, b = builder.offset + start, builder.offset + node.n
    if a not in builder.frames:
        if start != node.n - 1 or node.previous_pose is None:
            return None
        nf.values[builder.F(a)] = node.previous_pose
    new = [g for g in (a, b) if g not in builder.frames]
    frame_cov = np.asarray(frame_cov, dtype=np.float64)
    for g in new:
        # the frame's error is in the increments' units: with the visual scale estimated the tie is the same
        # model (a tie in metres would shrink with the whole track, and pull the common scale of camera and
        # wheels, which only the priors fix, away from them)
        if builder.kv_on:
            nf.factors.append(builder.model_factor(VISUAL, np.zeros(3), frame_cov,
                                                   {"motion": (builder.X(g), builder.F(g)),
                                                    "visual_scale": (builder.S(node.segment),)}, robust=False))
        else:
            nf.factors.append(gtsam.BetweenFactorPose2(builder.X(g), builder.F(g), gtsam.Pose2(),
                                                       builder.noise(frame_cov, robust=False)))
        builder.frames.add(g)
    if b in new:  # starts at this node's initial pose (GraphBuilder.node)
        node.scratch.setdefault("new_frames", []).append(builder.F(b))
    return builder.F(a), builder.F(b)


def _live_sample(inc) -> tuple:
    """A live :class:`~fusion_vo.measurements.VisualIncrement`: its time (``t1``) and itself."""
    return inc.t1, inc


def _live_values(inc) -> list:
    """The numbers of an increment that must be finite (the delta and covariance of a usable one)."""
    return [inc.t0] + ([] if not inc.ok else [inc.delta, inc.covariance])


def _live_take(fusion, inc) -> None:
    """Streaming: an increment makes its node (:meth:`~fusion_vo.backends.streaming.StreamingFusion.take_increment`)."""
    fusion.take_increment(inc)


register(Sensor(
    name="camera", where="cam0/ frames or visual increments", field="visual",
    intervals=Step(30, add_intervals), ekf_measurements=ekf_measurements, ekf_blocks=(Step(10, ekf_blocks),),
    graph_factors=(Step(20, graph_factors),),
    live=Live(_live_sample, values=_live_values, take=_live_take),
))
