"""The sensors' readings as factors: the one place the factor graph consumes a measurement model.

A reading becomes a factor on the variables of its model's arguments (:mod:`fusion_vo.backends.factors`):

* ``motion``: the two poses the reading relates, ``X_s`` and ``X_e`` (the frame poses ``F_s``, ``F_e`` when the
  reading states its frames' errors, :mod:`fusion_vo.sensors.visual`);
* ``heading``: the pose of its node;
* a state: that state's variable in the calibration segment of the reading's (last) node
  (:meth:`~fusion_vo.backends.graph_builder.GraphBuilder.state_variable`); a state the graph does not estimate is held at its
  initial value, as are the arguments the reading fixes.

Where GTSAM has the factor itself, it is used: a model that is its ``motion`` argument itself with the values held
(``MeasurementModel.identity``: a visual or wheel increment without calibration) is GTSAM's ``BetweenFactorPose2``,
one that is its ``heading`` a ``PriorFactorPose2`` on the heading; a node reading of one scalar state that the model
solves for it (``MeasurementModel.state_prior``: the range finder's height as a visual scale) is a linear prior on
that state. A reading none of whose arguments is a variable of the graph measures nothing it estimates and is left
out. Robust readings go inside the graph's robust kernel.

When the graph keeps only every ``keyframe_every``-th node, the interval readings of one sensor between two
keyframes are chained into one: relative poses composed (their covariances propagated to first order), other
readings (a turn) summed with their variances.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from fusion_vo.backends.factors import ModelFactor
from fusion_vo.geometry import se2
from fusion_vo.sensors.readings import Readings


@dataclass
class Span:
    """An interval reading between two of the graph's nodes (a chain of readings between keyframes)."""

    readings: Readings
    index: int  # the (last) reading of the chain, for its parameters
    start: int  # graph node
    z: np.ndarray
    cov: np.ndarray
    frame_cov: np.ndarray | None


def compose_with_covariance(a, cov_a, b, cov_b):
    """``a ⊕ b`` and its covariance ``J_a Σ_a J_aᵀ + J_b Σ_b J_bᵀ`` (first order, vector form)."""
    c, s = np.cos(a[2]), np.sin(a[2])
    ja = np.array([[1.0, 0.0, -s * b[0] - c * b[1]], [0.0, 1.0, c * b[0] - s * b[1]], [0.0, 0.0, 1.0]])
    jb = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return se2.compose(a, b), ja @ cov_a @ ja.T + jb @ cov_b @ jb.T


def _full(cov: np.ndarray, rows: tuple) -> np.ndarray:
    """The covariance ``cov`` of the rows ``rows`` of a relative pose as a 3 x 3 one, zero in the other rows."""
    out = np.zeros((3, 3))
    out[np.ix_(rows, rows)] = cov
    return out


def _chain(a: Span, r: Readings, j: int):
    """Chain the reading ``j`` of ``r`` onto the span ``a``. A relative pose that measures some of its rows
    (``Readings.rows``) holds the others at their reading (zero where the sensor leaves a component out) while
    composing; the chain keeps the covariance of its measured rows."""
    if r.model.increment and r.rows is not None:
        rows = list(r.rows)
        z, cov = compose_with_covariance(a.z, _full(a.cov, rows), r.z[j], _full(r.cov[j], rows))
        cov = cov[np.ix_(rows, rows)]
    elif r.model.increment:
        z, cov = compose_with_covariance(a.z, a.cov, r.z[j], r.cov[j])
    else:
        z, cov = a.z + r.z[j], a.cov + r.cov[j]
    return z, cov


class GraphReadings:
    """Every reading of a run placed on the graph's nodes (module docstring).

    Parameters
    ----------
    readings : list of Readings
    grid : ndarray (N,)
        Grid index of each graph node.

    An interval reading whose first node is before the grid (``i0 < 0``, where graph node 0 is grid node 0) starts
    ``-i0`` graph nodes before node 0: a stream built one interval at a time gives its camera increment over several
    intervals so (:meth:`~fusion_vo.backends.streaming.StreamingFusion._span_reading`).
    """

    def __init__(self, readings: list[Readings], grid: np.ndarray):
        pos = {int(g): n for n, g in enumerate(grid)}
        self.spans: dict[int, list[Span]] = {}
        self.nodes: dict[int, list[tuple[Readings, int]]] = {}
        #: absolute readings of the pose, gated and added on their own (:mod:`fusion_vo.backends.fixes`)
        self.absolute: list[Readings] = []
        for r in sorted(readings, key=lambda r: r.order):
            if r.absolute is not None:
                self.absolute.append(r)
                continue
            if r.at_nodes:
                for j, g in enumerate(r.i0):
                    n = pos.get(int(g))
                    if n is not None:
                        self.nodes.setdefault(n, []).append((r, j))
                continue
            chain = None  # (span, end grid index)
            for j in np.argsort(r.i1, kind="stable"):
                i0, i1 = int(r.i0[j]), int(r.i1[j])
                fc = None if r.frame_cov is None else r.frame_cov[j]
                if chain is not None and chain[1] == i0:
                    z, cov = _chain(chain[0], r, j)
                    span = Span(r, int(j), chain[0].start, z, cov, fc)
                elif i0 in pos:
                    span = Span(r, int(j), pos[i0], r.z[j].copy(), r.cov[j].copy(), fc)
                elif i0 < 0 and pos.get(0) == 0:  # from before the grid (class docstring)
                    span = Span(r, int(j), i0, r.z[j].copy(), r.cov[j].copy(), fc)
                else:
                    chain = None
                    continue
                if i1 in pos:
                    self.spans.setdefault(pos[i1], []).append(span)
                    chain = None
                else:
                    chain = (span, i1)

    def ending_at(self, n: int) -> list[Span]:
        """The interval readings that end at node ``n``, in the readings' order."""
        return self.spans.get(n, [])

    def at(self, n: int) -> list[tuple[Readings, int]]:
        """The node readings at node ``n`` (readings, index), in the readings' order."""
        return self.nodes.get(n, [])


def guess(spans: list[Span], n: int, estimate: dict, dt: float) -> tuple[tuple, tuple]:
    """``((translation, rank), (heading change, rank))`` of the interval ending at node ``n`` from the readings over
    exactly that interval, each from the model of the lowest
    :attr:`~fusion_vo.sensors.model.MeasurementModel.guess_rank` (None, None where none gives one)."""
    best_t = best_h = None
    translation = heading = None
    for span in spans:
        if span.start != n - 1:
            continue
        rank_t, rank_h = span.readings.model.guess_rank
        if rank_t is None and rank_h is None:
            continue
        t, h = span.readings.model.guess(span.z, estimate, dt)
        if "speed" in span.readings.dropped:
            t = None
        if t is not None and rank_t is not None and (best_t is None or rank_t < best_t):
            translation, best_t = t, rank_t
        if h is not None and rank_h is not None and (best_h is None or rank_h < best_h):
            heading, best_h = h, rank_h
    return (translation, best_t), (heading, best_h)


def arguments(builder, r: Readings, segment: int) -> tuple[dict, dict]:
    """The state arguments of ``r``'s model as graph keys (``{name: (key,)}``) and the arguments held at a value."""
    keys, fixed = {}, dict(r.fixed)
    for name in r.model.args:
        if name in ("motion", "heading", "pose") or name in fixed:
            continue
        key = builder.state_variable(name, segment)
        if key is None:
            fixed[name] = builder.state_initial(name)
        else:
            keys[name] = (key,)
    return keys, fixed


def _params(r: Readings, j: int) -> dict:
    return {name: r.param(name, j) for name in r.params}


#: standard deviation [m] of the translation of a motion reading whose speed the consistency monitor dropped
FREE_TRANSLATION_SIGMA = 100.0


def _without_dropped(r: Readings, z: np.ndarray, cov: np.ndarray):
    """A motion reading's ``(z, cov, rows)`` with its dropped components left out (``Readings.dropped``)."""
    rows = r.rows
    if "speed" in r.dropped:  # a free translation
        cov = cov.copy()
        cov[:2, :] = cov[:, :2] = 0.0
        cov[0, 0] = cov[1, 1] = FREE_TRANSLATION_SIGMA**2
    if "yaw" in r.dropped:  # the translation alone; the chord of a wrongly curved arc would drift sideways
        z = z.copy()
        z[1] = 0.0
        rows, cov = (0, 1), cov[:2, :2]
    return z, cov, rows


def interval_factor(builder, span: Span, xs: int, xe: int, segment: int, dt: float, robust: bool | None = None,
                    cov: np.ndarray | None = None):
    """The factor of an interval reading between the poses ``xs`` and ``xe`` (``cov`` replaces its covariance;
    ``robust`` its robust flag)."""
    r = span.readings
    robust = r.robust if robust is None else robust
    z, cov, rows = _without_dropped(r, span.z, span.cov if cov is None else cov)
    keys, fixed = arguments(builder, r, segment)
    if rows is None and r.model.identity(fixed):
        return gtsam.BetweenFactorPose2(xs, xe, gtsam.Pose2(*z), builder.noise(cov, robust=robust))
    params = _params(r, span.index)
    if r.model.uses_dt:
        params["dt"] = dt
    keys["motion"] = (xs, xe)
    return builder.model_factor(r.model, z, cov, keys, fixed=fixed, params=params, rows=rows, robust=robust)


def frame_poses(builder, nf, span: Span, n: int, segment: int, previous_pose) -> tuple[int, int] | None:
    """The frame poses ``F`` of a span's first and last node for a reading that states its frames' errors, each made
    with its tie, the reading's own model between ``X`` and ``F`` with a zero reading and the frame error's
    covariance, the first time a reading touches it (a frame's error is in the readings' units: with a scale
    estimated the tie goes through it). None when the first node's frame pose does not exist and that node is not
    the previous one (whose current estimate ``previous_pose`` starts it): the span then relates the poses ``X``.
    A frame pose made at node ``n`` starts at its initial pose (listed in ``nf.new_frames``)."""
    r = span.readings
    a, b = builder.offset + span.start, builder.offset + n
    if a not in builder.frames:
        if span.start != n - 1 or previous_pose is None:
            return None
        nf.values[builder.F(a)] = previous_pose
    new = [g for g in (a, b) if g not in builder.frames]
    for g in new:
        tie = Span(r, span.index, 0, np.zeros(3), span.frame_cov, None)
        nf.factors.append(interval_factor(builder, tie, builder.X(g), builder.F(g), segment, 0.0, robust=False))
        builder.frames.add(g)
    if b in new:
        nf.new_frames.append(builder.F(b))
    return builder.F(a), builder.F(b)


def pose_factor(model, z, covariance, keys: tuple, params: dict, noise) -> ModelFactor:
    """An absolute reading ``z`` of ``model``'s ``pose`` argument: on the pose ``keys = (X,)``, or on ``T X`` for
    ``keys = (T, X)`` (a frame transform and the pose, :mod:`fusion_vo.backends.factors`), inside ``noise``'s own
    robust kernel (``noise.kernel`` of width ``noise.kernel_width``; ``"none"``: Gaussian)."""
    robust = None if noise.kernel == "none" else (noise.kernel, float(noise.kernel_width))
    return ModelFactor(model, np.asarray(z, dtype=np.float64), {"pose": tuple(keys)},
                       np.asarray(covariance, dtype=np.float64), {}, params, None, robust)


def absolute_factor(r: Readings):
    """``factor(key, z, covariance)``: an absolute reading of ``r`` on the pose at ``key``, inside its own robust
    kernel, as the model's :class:`gtsam.CustomFactor` (its residual and body-frame Jacobian; :func:`pose_factor`)."""
    params = {name: np.asarray(value, dtype=np.float64) for name, value in r.params.items()}

    def factor(key: int, z, covariance):
        return pose_factor(r.model, z, covariance, (key,), params, r.absolute.noise).custom_factor()

    return factor


def node_factor(builder, r: Readings, j: int, xn: int, segment: int):
    """The factor of node reading ``j`` of ``r`` at the pose ``xn``, or None when it measures nothing the graph
    estimates."""
    keys, fixed = arguments(builder, r, segment)
    pose_args = [a for a in r.model.args if a in ("heading", "pose")]
    z, cov = r.z[j], r.cov[j]
    params = _params(r, j)
    if r.rows is None and "heading" in pose_args and r.model.identity(fixed):
        nm = builder.noise(np.diag([1e6, 1e6, float(cov[0, 0])]), robust=r.robust, dof=1)
        return gtsam.PriorFactorPose2(xn, gtsam.Pose2(0.0, 0.0, float(z[0])), nm)
    if not pose_args:
        if not keys:
            return None
        prior = r.model.state_prior(z, float(cov[0, 0]), params) if len(keys) == 1 and r.model.dim == 1 else None
        if prior is not None and prior[0] in keys:
            _, value, sigma = prior
            return gtsam.PriorFactorDouble(keys[prior[0]][0], value, gtsam.noiseModel.Isotropic.Sigma(1, sigma))
    for name in pose_args:
        keys[name] = (xn,)
    return builder.model_factor(r.model, z, cov, keys, fixed=fixed, params=params, rows=r.rows, robust=r.robust)
