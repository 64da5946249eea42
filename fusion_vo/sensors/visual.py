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
:func:`readings`): each prediction shifts the current frame's error into the previous one's place
(which marginalises the older one) and starts the new frame's at zero with covariance ``f/2 Σ_vis``;
the update then has ``∓I/Δt`` in their columns. The factor graph gives each frame a pose ``F_k`` tied
to the node's pose by this model with a zero reading and ``f/2 Σ_vis`` (in the increments' units, through
the visual scale when it is estimated; else ``BetweenFactorPose2(X_k, F_k, identity, f/2 Σ_vis)``) and
puts the increment between the frame poses with ``(1 - f) Σ_vis`` (:func:`readings`).

An increment may instead state its frames' error itself
(:attr:`~fusion_vo.measurements.VisualIncrement.frame_covariance` ``Σ_e``, e.g. from a noise calibration
of the camera, :mod:`fusion_vo.calibration.camera_noise`): then ``e ~ N(0, Σ_e)`` and
``w ~ N(0, Σ_vis - 2 Σ_e)``, the same model with a frame error of its own size and axes rather than a fixed
share of every increment's covariance (:func:`frame_covariances`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from fusion_vo.config.sensor_files import CameraFile
from fusion_vo.measurements import SensorCount
from fusion_vo.measurements.grid import node_indices, outage_notes
from fusion_vo.sensors.model import MeasurementModel, scaled_motion
from fusion_vo.sensors.readings import ORDER, Readings
from fusion_vo.sensors import visual_noise
from fusion_vo.sensors.registry import DistanceSource, HeadingSource, Live, Sensor, State, Step, register
from fusion_vo.sensors.wheel_arc import wheel_motion


@dataclass(frozen=True)
class VisualModel(MeasurementModel):
    """The visual increment (module docstring); arguments ``motion``, ``visual_scale``."""

    name: str = "camera"
    args: tuple = ("motion", "visual_scale")
    dim: int = 3
    turn_rows: tuple = (2,)
    increment: bool = True
    guess_rank: tuple = (2, 2)

    def identity(self, fixed: dict) -> bool:
        return fixed.get("visual_scale") == 1.0

    def guess(self, z, estimate: dict, dt: float):
        """The translation in the running visual scale estimate's units, and the heading change."""
        return np.asarray(z[:2]) / estimate.get("visual_scale", 1.0), float(z[2])

    def evaluate(self, motion, visual_scale):
        one = 1.0 if np.ndim(motion) == 1 else np.ones_like(np.asarray(visual_scale, dtype=np.float64))
        h, j_d, j_k, _ = scaled_motion(motion, visual_scale, one)
        return h, {"motion": j_d, "visual_scale": j_k}


VISUAL = VisualModel()


# --------------------------------------------------------------------------- on the node grid
@dataclass
class CameraGrid:
    """The camera's measurements on the node grid (``Intervals.sensors["camera"]``, :func:`camera_grid`).

    Attributes
    ----------
    i0, i1 : ndarray (M,) int
        Node indices spanned by each usable increment.
    delta, cov : ndarray (M, 3), (M, 3, 3)
        The increments (slope-projected: ``d_x cx``, ``d_y cy`` over the intervals they span) and their
        covariances.
    frame_cov : ndarray (M, 3, 3) or None
        The covariance of each increment's frames' own errors when the increments state it
        (:attr:`~fusion_vo.measurements.VisualIncrement.frame_covariance`); it replaces ``frame_error``'s
        ``f/2 Σ`` (:func:`frame_covariances`).
    frame_error : float
        The frame-error share ``f`` both backends use (module docstring): ``FusionConfig.visual_frame_error``,
        or the estimate of :mod:`fusion_vo.sensors.visual_noise`.
    noise : VisualNoiseEstimate or None
        What that estimate found (``fusion.visual_noise.estimate``; None when off or in streaming use).
    """

    #: the per-increment arrays a windowed copy keeps (the live monitor's, which judges the increments' headings and
    #: distances); the others go back to their defaults there
    ROWS: ClassVar[tuple] = ("delta", "cov")

    i0: np.ndarray
    i1: np.ndarray
    delta: np.ndarray
    cov: np.ndarray
    frame_cov: np.ndarray | None = None
    frame_error: float = 0.0
    noise: object = None

    @classmethod
    def empty(cls, n_steps: int, config) -> "CameraGrid":
        """No increments; the configured frame-error share."""
        return cls(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 3)), np.zeros((0, 3, 3)),
                   frame_error=config.visual_frame_error)


def camera_grid(iv) -> CameraGrid:
    """The camera's measurements on the node grid ``iv`` (an :class:`~fusion_vo.backends.timeline.Intervals`)."""
    return iv.sensors["camera"]


#: node intervals a first guess of a calibration state compares over, at least (:attr:`Sensor.first_guesses`)
FIRST_GUESS_INTERVALS = 10


def camera_motion(iv) -> tuple[np.ndarray, np.ndarray]:
    """The camera's heading change and distance per node interval of ``iv`` from its increments over a single
    interval (NaN elsewhere)."""
    cam = camera_grid(iv)
    single = cam.i1 == cam.i0 + 1
    yaw = np.full(iv.n_steps, np.nan)
    xy = np.full(iv.n_steps, np.nan)
    yaw[cam.i0[single]] = cam.delta[single, 2]
    xy[cam.i0[single]] = np.hypot(cam.delta[single, 0], cam.delta[single, 1])
    return yaw, xy


def camera_heading_reference(iv) -> np.ndarray | None:
    """The camera's heading changes per node interval (:func:`camera_motion`), independent of every calibration,
    where it measured more than :data:`FIRST_GUESS_INTERVALS` intervals; else None. The first guesses of the gyro
    bias and the wheel base read them."""
    yaw, _ = camera_motion(iv)
    return yaw if np.isfinite(yaw).sum() > FIRST_GUESS_INTERVALS else None


def _first_visual_scale(iv, guesses: dict) -> dict:
    """The visual scale's first guess: ``s = Σ d_camera / Σ d_wheels`` over the intervals both measure (more than
    :data:`FIRST_GUESS_INTERVALS`), kept within (0.8, 1.25)."""
    _, wheel_xy = wheel_motion(iv)
    if wheel_xy is None:
        return {}
    _, camera_xy = camera_motion(iv)
    ok = np.isfinite(camera_xy) & np.isfinite(wheel_xy)
    if ok.sum() <= FIRST_GUESS_INTERVALS or np.sum(wheel_xy[ok]) <= 0:
        return {}
    scale = float(np.sum(camera_xy[ok]) / np.sum(wheel_xy[ok]))
    return {"visual_scale": scale} if 0.8 < scale < 1.25 else {}


# --------------------------------------------------------------------------- registration
def add_intervals(iv, streams, config, counts) -> None:
    """The usable increments onto the node grid (:class:`CameraGrid`), projected to the horizontal; camera
    outages become notes.

    Every check is one array operation over all increments (the increments' times, readings and
    covariances stacked once), not a loop of small numpy calls per increment: a 60 s drive at 20 Hz
    has 1200 of them.
    """

    visual, notes, cam = streams.visual, iv.notes, camera_grid(iv)
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
        cam.i0, cam.i1 = i0[keep], i1[keep]
        cam.delta, cam.cov = delta[keep], cov[keep]
        # slope: mean projection factors over the spanned intervals (a single interval's is its own)
        cx, cy = iv.cx[cam.i0], iv.cy[cam.i0]
        for m in np.flatnonzero(cam.i1 - cam.i0 > 1):
            a, b = cam.i0[m], cam.i1[m]
            cx[m], cy[m] = iv.cx[a:b].mean(), iv.cy[a:b].mean()
        cam.delta[:, 0] *= cx
        cam.delta[:, 1] *= cy
    count.used += len(keep)
    stated = [visual[i].frame_covariance for i in keep]
    if any(c is not None for c in stated):
        cam.frame_cov = _stated_frame_cov(stated, cam.cov)
    edges = np.zeros(len(T), dtype=np.int64)  # covered intervals: +1 where an increment starts, -1 where it ends
    np.add.at(edges, cam.i0, 1)
    np.add.at(edges, cam.i1, -1)
    covered = np.cumsum(edges)[:-1] > 0
    notes.extend(outage_notes("camera", T, covered))


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
    (:attr:`CameraGrid.frame_cov`), else ``f/2`` of their covariance with ``frame_error = f > 0``;
    None: independent increments."""
    cam = camera_grid(iv)
    if cam.frame_cov is not None:
        return cam.frame_cov
    f = cam.frame_error
    return 0.5 * f * cam.cov if f > 0 else None


def readings(iv, config) -> list[Readings]:
    """The usable increments between their frames' nodes, with their frames' own errors when modelled
    (:func:`frame_covariances`)."""
    cam = camera_grid(iv)
    if not len(cam.i0):
        return []
    return [Readings("camera", VISUAL, cam.i0, cam.i1, cam.delta, cam.cov, frame_cov=frame_covariances(iv),
                     order=ORDER["camera"])]


# --------------------------------------------------------------------------- its heading, for the monitor
def heading_rows(iv, with_variance: bool = False):
    """The visual increments' heading spread over the node intervals they span: ``(ok, angle, variance)``
    per interval (``variance`` None unless asked). An increment over ``n`` intervals gives each ``1/n``
    of its heading change and of its variance; where increments overlap, the later one wins."""
    cam = camera_grid(iv)
    K = len(iv.t) - 1
    ok = np.zeros(K, bool)
    ang = np.zeros(K)
    var = np.zeros(K) if with_variance else None
    i0 = np.asarray(cam.i0, dtype=np.int64)
    n = np.asarray(cam.i1, dtype=np.int64) - i0
    if not len(i0):
        return ok, ang, var
    rows = np.repeat(np.arange(len(i0)), n)
    idx = i0[rows] + (np.arange(len(rows)) - np.repeat(np.cumsum(n) - n, n))
    ok[idx] = True
    delta = np.asarray(cam.delta).reshape(-1, 3)
    ang[idx] = (delta[:, 2] / n)[rows]
    if with_variance:
        var[idx] = (np.asarray(cam.cov).reshape(-1, 3, 3)[:, 2, 2] / n)[rows]
    return ok, ang, var


def drop_increments(iv, keep: np.ndarray) -> None:
    """Remove the visual increments where ``keep`` is False (counted as gated): an increment is one
    estimate of the frontend, and one whose heading is wrong has its translation expressed in a wrong
    frame too. The other sensors carry the estimate there."""
    if keep.all():
        return
    cam = camera_grid(iv)
    cam.i0, cam.i1 = cam.i0[keep], cam.i1[keep]
    cam.delta, cam.cov = cam.delta[keep], cam.cov[keep]
    if iv.counts.get("camera") is not None:  # the live monitor's window has no counts
        iv.counts["camera"].gated += int(np.count_nonzero(~keep))


def _heading_change(iv, config):
    """The heading monitor's camera rows (:func:`heading_rows`); None without increments."""
    if not len(camera_grid(iv).i0):
        return None
    return heading_rows(iv, with_variance=True)


def _heading_drop(iv, bad: np.ndarray, agrees) -> None:
    """Within the intervals the monitor flagged, each increment tested on its own against the other sources."""
    if not bad.any():
        return
    cam = camera_grid(iv)
    keep = np.ones(len(cam.i0), bool)
    for m, (a, b) in enumerate(zip(cam.i0, cam.i1)):
        if bad[a:b].any():
            keep[m] = agrees(a, b)
    drop_increments(iv, keep)


def _distance_change(iv, config):
    """The increments' forward distance spread over the intervals they span (``1/n`` of it and of its variance
    each)."""
    cam = camera_grid(iv)
    if not len(cam.i0):
        return None
    K = len(iv.t) - 1
    ok, d, v = np.zeros(K, bool), np.zeros(K), np.zeros(K)
    for a, b, delta, cov in zip(cam.i0, cam.i1, cam.delta, cam.cov):
        n = b - a
        ok[a:b] = True
        d[a:b] = delta[0] / n
        v[a:b] = cov[0, 0] / n
    return ok, d, v


#: the camera's distance, what the wheels' is checked against
DISTANCE = DistanceSource("camera", "distance", rank=40, change=_distance_change)

#: the summed heading increments: the camera's heading, for the monitor
HEADING = HeadingSource("camera", "visual heading", rank=40, change=_heading_change, drop=_heading_drop, reference=1,
                        reference_error=lambda iv, config, ok, var: float(np.sum(var[ok])))


def _live_sample(inc) -> tuple:
    """A live :class:`~fusion_vo.measurements.VisualIncrement`: its time (``t1``) and itself."""
    return inc.t1, inc


def _live_values(inc) -> list:
    """The numbers of an increment that must be finite (the delta and covariance of a usable one)."""
    return [inc.t0] + ([] if not inc.ok else [inc.delta, inc.covariance])


def _live_samples(increments) -> list:
    """Recorded increments as live samples: each arrives at its second frame's time."""
    return [(inc.t1, inc) for inc in increments]


def _live_take(fusion, inc) -> None:
    """Streaming: an increment makes its node (:meth:`~fusion_vo.backends.streaming.StreamingFusion.take_increment`)."""
    fusion.take_increment(inc)


def _visual_scale(state: State, context) -> State:
    """``k_v``: estimated under self-calibration where another sensor measures distance (its observability, in
    ``context``), with the prior the run's files give and the configured random walk."""
    config = context.config
    return dataclasses.replace(state, sigma=context.facts["visual_scale_sigma"],
                               random_walk=config.ekf.visual_scale_random_walk,
                               estimated=bool(config.self_calibration and context.observable.get(state.name, False)))


def _camera_height(value: float, sigma: float, iv) -> dict:
    """The camera height ``h / k_v`` a visual scale ``k_v`` gives (σ ``h σ_kv``), ``h`` the configured one."""
    height = iv.facts.get("camera_height")
    if not height:
        return {}
    return {"camera_height": (float(height / value), float(height * sigma))}


def stated_height_sigma(recording) -> float | None:
    """``height_sigma`` of a recording's ``cam0/sensor.yaml``: the standard deviation [m] of the camera height its
    ``T_BS`` states, or None when the file does not state it."""
    return recording.sensor_file("cam0", CameraFile, required=False).height_sigma


def _placed(iv) -> bool:
    """Whether an increment is placed on the node grid ``iv``: the camera measures there."""
    return len(camera_grid(iv).i0) > 0


#: the visual scale ``k_v = h_configured / h_true`` (:class:`VisualModel`), a state of every run
VISUAL_SCALE = State("visual_scale", initial=1.0, symbol="s", rule=_visual_scale, derived=_camera_height,
                     needs="distance")

register(Sensor(
    name="camera", where="cam0/ frames or visual increments", field="visual", folder="cam0",
    grid=CameraGrid.empty, intervals=Step(30, add_intervals), readings=readings, states=(VISUAL_SCALE,),
    absolute_heading=_placed, on_grid=_placed,
    heading_reference=lambda increments: increments is None or any(v.ok for v in increments),
    live=Live(_live_sample, values=_live_values, take=_live_take, samples=_live_samples, message="visual", order=0),
    heading=(HEADING,), distance=(DISTANCE,), first_guesses=Step(20, _first_visual_scale),
    whole_recording=Step(10, visual_noise.apply),
))
