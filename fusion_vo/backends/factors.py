"""GTSAM factors from the sensors' measurement models (:mod:`fusion_vo.sensors.model`).

A :class:`ModelFactor` is one measurement of a sensor model between graph variables: the model, its
reading ``z``, the variable keys of each model argument (``motion``: the two poses ``X_i, X_j`` whose
relative pose ``X_i⁻¹ X_j`` is the motion; ``heading``: one pose; ``pose``: one pose ``X``, or a frame transform
and a pose ``(T, X)`` whose composition ``T X`` is the argument, the pose of B in T's target frame; the others: one
scalar variable), arguments held fixed, and the noise covariance (optionally inside the graph's robust kernel).

The graph does not wrap these in Python factors that GTSAM calls back: :class:`ModelFactors`
evaluates all factors of one kind at once with the model's vectorised prediction and Jacobians, and
turns them into GTSAM's native linear factors (``JacobianFactor``, whitened and robustly reweighted as
GTSAM's own ``noiseModel.Robust`` does) at each iteration of the solver; the incremental solvers
receive each one linearised at its current estimate (:meth:`ModelFactor.linearized`). The same
factor as a :class:`gtsam.CustomFactor` (:meth:`ModelFactor.custom_factor`, for GTSAM's own
optimizers) gives the same error and linearisation (tests compare them).

Jacobians of the relative pose ``δ = X_i⁻¹ X_j = (d_x, d_y, d_ψ)`` in GTSAM's tangent spaces (right
perturbations ``X · Exp(ξ)``)::

    ∂δ/∂ξ_i = [[-1, 0, d_y], [0, -1, -d_x], [0, 0, -1]],     ∂δ/∂ξ_j = [[cos d_ψ, -sin d_ψ, 0], [sin d_ψ, cos d_ψ, 0], [0, 0, 1]]

of a pose's heading ``∂ψ/∂ξ = (0, 0, 1)``, and of a pose itself ``∂(x, y, ψ)/∂ξ = [[R(ψ), 0], [0, 1]]``.
Of a composition ``Y = T X``: ``T Exp(ξ_T) X Exp(ξ_X) = Y Exp(Ad(X⁻¹) ξ_T + ξ_X)``, so the pose's Jacobians are
``[[R(ψ_Y), 0], [0, 1]] Ad(X⁻¹)`` and ``[[R(ψ_Y), 0], [0, 1]]``, with GTSAM's adjoint of a Pose2 ``(x, y, ψ)``
``Ad = [[cos ψ, -sin ψ, y], [sin ψ, cos ψ, -x], [0, 0, 1]]`` (:func:`_composed`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import gtsam
import numpy as np

from fusion_vo.geometry import se2
from fusion_vo.robust import mestimator, robust_loss, robust_weight
from fusion_vo.sensors.model import MeasurementModel


def gaussian_factor(items: list, b, unit, values: gtsam.Values | None = None):
    """GTSAM's ``JacobianFactor(k_1, A_1, ..., b, unit)`` of whitened blocks ``items = [k_1, A_1, ...]``.

    GTSAM's Python interface builds a ``JacobianFactor`` of at most three variables. One of more (a wheel
    factor with its radius factor, wheel-base factor and curvature bias: two poses and up to three
    scalars) is built by GTSAM itself, as the linearisation at ``values`` (which must hold every key) of a
    :class:`gtsam.CustomFactor` whose error and Jacobians are ``-b`` and the blocks, under the unit noise
    model: the same ``Σ A_i δ_i - b``, of as many rows as the measurement has. (Summing two-variable
    ``HessianFactor`` pieces and factoring the sum back into rows, as this did before, fails in GTSAM's
    Cholesky whenever the quadratic of a two-row factor over nine dimensions comes out a rounding error
    short of positive semi-definite.)
    """
    if len(items) <= 6:
        return gtsam.JacobianFactor(*items, b, unit)
    if values is None:
        raise ValueError("a factor of more than three variables needs the values it is linearised at")
    keys = [int(k) for k in items[0::2]]
    blocks = [np.atleast_2d(np.asarray(a, dtype=np.float64)) for a in items[1::2]]
    error = -np.asarray(b, dtype=np.float64).reshape(-1)

    def fixed(this, v, jacobians):
        if jacobians is not None:
            for i, a in enumerate(blocks):
                jacobians[i] = a
        return error

    return gtsam.CustomFactor(unit, keys, fixed).linearize(values)


@dataclass
class ModelFactor:
    """One measurement of ``model`` in the graph.

    Attributes
    ----------
    model : MeasurementModel
    z : ndarray (dim,)
        The reading (all of the model's rows, ``rows`` selects).
    keys : dict
        Argument name -> variable keys: ``motion`` -> ``(X_i, X_j)``, any other -> ``(key,)``.
    covariance : ndarray (m, m)
        Noise of the selected rows.
    fixed : dict
        Arguments held at a value (e.g. a wheel-base factor that is not estimated).
    params : dict
        Extra parameters of :meth:`MeasurementModel.evaluate` (e.g. the gyro's ``dt``).
    rows : tuple or None
        The model's rows this factor uses (None: all).
    robust : tuple or None
        ``(kernel, k)`` of GTSAM's ``mEstimator`` (``"huber"`` or ``"cauchy"``; :mod:`fusion_vo.robust`), or None.
    """

    model: MeasurementModel
    z: np.ndarray
    keys: dict
    covariance: np.ndarray
    fixed: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    rows: tuple | None = None
    robust: tuple | None = None

    def all_keys(self) -> list[int]:
        return [k for name in self.model.args if name in self.keys for k in self.keys[name]]

    def signature(self) -> tuple:
        """Factors with the same signature are evaluated together."""
        return (self.model, tuple(n for n in self.model.args if n in self.keys), tuple(sorted(self.fixed)),
                tuple(sorted(self.params)), self.rows, self.robust)

    def _residual(self, lookup) -> tuple:
        """The residual ``h - z`` of the selected rows at ``lookup(key)`` values (angles wrapped), with what
        the linearisation needs: ``(e, jac, links, current, rows, sub)``."""
        model = self.model
        rows = list(range(model.dim)) if self.rows is None else list(self.rows)
        args, links, current = {}, [], {}
        for name in model.args:
            if name not in self.keys:
                continue
            keys = self.keys[name]
            for key in keys:
                current[key] = lookup(key)
            if name == "motion":
                args[name], d_i, d_j = _relative_one(current[keys[0]], current[keys[1]])
                links += [(name, d_i, keys[0]), (name, d_j, keys[1])]
            elif name == "heading":
                args[name] = np.array([current[keys[0]].theta()])
                links.append((name, _HEADING[0], keys[0]))
            elif name == "pose" and len(keys) == 2:  # (T, X): the pose T X
                p = current[keys[0]].compose(current[keys[1]])
                args[name] = np.array([p.x(), p.y(), p.theta()])
                body = _body(np.array([p.theta()]))[0]
                links += [(name, body @ current[keys[1]].inverse().AdjointMap(), keys[0]), (name, body, keys[1])]
            elif name == "pose":
                p = current[keys[0]]
                args[name] = np.array([p.x(), p.y(), p.theta()])
                links.append((name, _body(np.array([p.theta()]))[0], keys[0]))
            else:
                args[name] = np.array([float(current[keys[0]])])
                links.append((name, None, keys[0]))
        for name, value in self.fixed.items():
            args[name] = np.array([float(value)])
        h, jac = model.evaluate(**args, **self.params)
        sub = self.rows is not None
        e = h[rows] - self.z[rows] if sub else h - self.z
        for i in self._wrapped_rows(rows):
            e[i] = (e[i] + math.pi) % (2.0 * math.pi) - math.pi
        return e, jac, links, current, rows, sub

    def _whitening(self, rows: list):
        """The whitening of the covariance: ``1/σ`` for one row, else GTSAM's square-root information ``R``."""
        cov = np.atleast_2d(self.covariance)
        if len(rows) == 1:
            return 1.0 / math.sqrt(float(cov[0, 0]))
        return covariance_noise(cov).R()

    def weight(self, lookup) -> float:
        """The robust kernel's weight of the factor at ``lookup(key)`` values (1 without a kernel): the
        weight :meth:`linearized` gives it there."""
        if self.robust is None:
            return 1.0
        e, _, _, _, rows, _ = self._residual(lookup)
        W = self._whitening(rows)
        distance = abs(W * float(e[0])) if len(rows) == 1 else math.sqrt(float((W @ e) @ (W @ e)))
        return float(robust_weight(distance, *self.robust))

    def linearized(self, lookup, point: gtsam.Values | None = None,
                   weights: list | None = None) -> gtsam.LinearContainerFactor:
        """The factor linearised at ``lookup(key)`` values (Pose2 or float), for the incremental solvers:
        the same linearisation as :meth:`ModelFactors.linearize`, for one factor. ``point`` may hold these
        values already (:class:`ValuesMaker`; it may hold others too). ``weights``: the robust kernel's
        weight at these values is appended to it (1 without a kernel)."""
        e, jac, links, current, rows, sub = self._residual(lookup)
        W = self._whitening(rows)
        weight = 1.0
        items = []
        if len(rows) == 1:  # one row: scalars instead of 1x1 matrices
            w = W
            ew = w * float(e[0])
            if self.robust is not None:
                weight = float(robust_weight(abs(ew), *self.robust))
                w *= math.sqrt(weight)
                ew = w * float(e[0])
            for name, link, key in links:
                J = jac[name][rows] if sub else jac[name]
                items += [int(key), w * (J if link is None else J @ link)]
            b = np.array([-ew])
        else:  # GTSAM's own whitening of this covariance (as a CustomFactor's linearisation)
            ew = W @ e
            if self.robust is not None:
                weight = float(robust_weight(math.sqrt(float(ew @ ew)), *self.robust))
                scale = math.sqrt(weight)
                W = W * scale
                ew = ew * scale
            for name, link, key in links:
                WJ = W @ (jac[name][rows] if sub else jac[name])
                items += [int(key), WJ if link is None else WJ @ link]
            b = -ew
        if weights is not None:
            weights.append(weight)
        if point is None:
            point = ValuesMaker().make(current)
        factor = gaussian_factor(items, b, _UNIT[len(rows)], point)
        return gtsam.LinearContainerFactor(factor, point)

    def _wrapped_rows(self, rows: list) -> list:
        wrapped = self.model.angle_rows + self.model.turn_rows
        return [i for i, r in enumerate(rows) if r in wrapped]

    def noise_model(self):
        base = covariance_noise(self.covariance)
        robust = None if self.robust is None else mestimator(*self.robust)
        return base if robust is None else gtsam.noiseModel.Robust.Create(robust, base)

    def custom_factor(self) -> gtsam.CustomFactor:
        """The same factor as a :class:`gtsam.CustomFactor` around the model's residual and Jacobians."""
        one = ModelFactor(self.model, self.z, self.keys, np.eye(len(self.covariance)), self.fixed, self.params,
                          self.rows, None)

        def error(this, values, jacobians):
            e, blocks = ModelFactors([one]).evaluate(values)
            if jacobians is not None:
                for i, J in enumerate(blocks):
                    jacobians[i] = J[0]
            return e[0]

        return gtsam.CustomFactor(self.noise_model(), self.all_keys(), error)


def _relative(pi: np.ndarray, pj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``X_i⁻¹ X_j`` (N, 3) of poses (N, 3) and its Jacobians (N, 3, 3) in GTSAM's tangent spaces."""
    c, s = np.cos(pi[:, 2]), np.sin(pi[:, 2])
    tx, ty = pj[:, 0] - pi[:, 0], pj[:, 1] - pi[:, 1]
    d = np.stack([c * tx + s * ty, -s * tx + c * ty, se2.wrap_angle(pj[:, 2] - pi[:, 2])], axis=1)
    n = len(d)
    d_i = np.zeros((n, 3, 3))
    d_i[:, 0, 0] = d_i[:, 1, 1] = d_i[:, 2, 2] = -1.0
    d_i[:, 0, 2], d_i[:, 1, 2] = d[:, 1], -d[:, 0]
    cp, sp = np.cos(d[:, 2]), np.sin(d[:, 2])
    d_j = np.zeros((n, 3, 3))
    d_j[:, 0, 0], d_j[:, 0, 1], d_j[:, 1, 0], d_j[:, 1, 1], d_j[:, 2, 2] = cp, -sp, sp, cp, 1.0
    return d, d_i, d_j


def _body(yaw: np.ndarray) -> np.ndarray:
    """``∂x/∂ξ`` (N, 3, 3) of poses ``x = (x, y, ψ)`` (world frame) perturbed in GTSAM's tangent space
    (``X · Exp(ξ)``, ``ξ`` in the body frame): ``[[R(ψ), 0], [0, 1]]``."""
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros((len(yaw), 3, 3))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1], out[:, 2, 2] = c, -s, s, c, 1.0
    return out


def _composed(pt: np.ndarray, px: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Y = T X`` (N, 3) of poses ``T``, ``X`` (N, 3) and the Jacobians (N, 3, 3) of ``Y``'s ``(x, y, ψ)`` in the world
    frame with respect to ``ξ_T`` and ``ξ_X`` (module docstring)."""
    c, s = np.cos(pt[:, 2]), np.sin(pt[:, 2])
    y = np.stack([pt[:, 0] + c * px[:, 0] - s * px[:, 1], pt[:, 1] + s * px[:, 0] + c * px[:, 1],
                  se2.wrap_angle(pt[:, 2] + px[:, 2])], axis=1)
    d_x = _body(y[:, 2])
    # Ad(X⁻¹): X⁻¹ = (-R(ψ)ᵀ t, -ψ)
    cx, sx = np.cos(px[:, 2]), np.sin(px[:, 2])
    ix, iy = -(cx * px[:, 0] + sx * px[:, 1]), sx * px[:, 0] - cx * px[:, 1]
    ad = np.zeros((len(px), 3, 3))
    ad[:, 0, 0], ad[:, 0, 1], ad[:, 0, 2] = cx, sx, iy
    ad[:, 1, 0], ad[:, 1, 1], ad[:, 1, 2] = -sx, cx, -ix
    ad[:, 2, 2] = 1.0
    return y, d_x @ ad, d_x


class ModelFactors:
    """Factors of one signature (:meth:`ModelFactor.signature`), evaluated and linearised together."""

    def __init__(self, factors: list[ModelFactor]):
        f0 = factors[0]
        self.factors = factors
        self.model = f0.model
        self.names = [n for n in f0.model.args if n in f0.keys]
        self.rows = list(range(f0.model.dim)) if f0.rows is None else list(f0.rows)
        self.keys = {n: np.array([f.keys[n] for f in factors], dtype=np.int64) for n in self.names}
        self.fixed = {n: _stacked([f.fixed[n] for f in factors], (-1,)) for n in f0.fixed}
        self.params = {n: np.array([f.params[n] for f in factors], dtype=np.float64) for n in f0.params}
        self.z = _stacked([f.z for f in factors], (-1,))
        m = len(self.rows)  # the covariance is that of the selected rows
        self.whiten = whitening(_stacked([f.covariance for f in factors], (m, m)))
        self.robust = f0.robust
        #: exact as a linear factor: a linear model without a robust kernel
        self.linear = f0.model.linear and f0.robust is None
        self.wrap = [i for i, r in enumerate(self.rows) if r in f0.model.angle_rows + f0.model.turn_rows]

    def __len__(self) -> int:
        return len(self.factors)

    def evaluate(self, values: gtsam.Values, poses: dict | None = None, scalars: dict | None = None):
        """Residuals ``h - z`` (N, m) of the selected rows and the Jacobian blocks, one (N, m, d) per key.

        ``poses`` (:func:`pose_table`) and ``scalars`` (:func:`scalar_table`) hold the values already
        (one lookup per variable instead of one per factor)."""
        args, chains = {}, []
        for name in self.names:
            keys = self.keys[name]
            if name == "motion":
                pi, pj = _poses(values, keys[:, 0], poses), _poses(values, keys[:, 1], poses)
                args[name], d_i, d_j = _relative(pi, pj)
                chains.append((name, [d_i, d_j]))
            elif name == "heading":
                args[name] = _poses(values, keys[:, 0], poses)[:, 2:3]
                chains.append((name, [_HEADING]))
            elif name == "pose" and keys.shape[1] == 2:  # (T, X): the pose T X
                args[name], d_t, d_x = _composed(_poses(values, keys[:, 0], poses), _poses(values, keys[:, 1], poses))
                chains.append((name, [d_t, d_x]))
            elif name == "pose":
                args[name] = _poses(values, keys[:, 0], poses)
                chains.append((name, [_body(args[name][:, 2])]))
            else:
                args[name] = _scalars(values, keys[:, 0], scalars)
                chains.append((name, [None]))
        args.update(self.fixed)
        h, jac = self.model.evaluate(**args, **self.params)
        e = h[:, self.rows] - self.z[:, self.rows]
        for i in self.wrap:
            e[:, i] = se2.wrap_angle(e[:, i])
        blocks = []
        for name, links in chains:
            J = jac[name][:, self.rows, :]
            for link in links:
                blocks.append(J if link is None else J @ link)
        return e, blocks

    def _whitened(self, values, poses=None, scalars=None):
        e, blocks = self.evaluate(values, poses, scalars)
        ew = np.einsum("nij,nj->ni", self.whiten, e)
        dist = np.linalg.norm(ew, axis=1)
        return ew, blocks, dist

    def error(self, values: gtsam.Values, poses: dict | None = None, scalars: dict | None = None) -> float:
        """Sum of the factors' errors as GTSAM computes them (``ρ(‖W e‖)``, ``½‖W e‖²`` without a kernel)."""
        _, _, dist = self._whitened(values, poses, scalars)
        kernel, k = self.robust if self.robust is not None else (None, 0.0)
        return float(np.sum(robust_loss(dist, kernel, k)))

    def jacobian(self, values: gtsam.Values, poses: dict | None = None, scalars: dict | None = None):
        """GTSAM's linearisation of every factor as arrays: ``(keys, A, b)`` with ``keys[i]`` (N,) the
        variable of Jacobian block ``A[i]`` (N, m, d) and ``b`` (N, m), so that each factor is
        ``Σ_i A[i] δ_key[i] - b``: ``W J`` and ``-W e``, scaled by ``√w(‖W e‖)`` in a robust kernel."""
        ew, blocks, dist = self._whitened(values, poses, scalars)
        scale = np.ones(len(ew))
        if self.robust is not None:
            scale = np.sqrt(robust_weight(dist, *self.robust))
        b = -ew * scale[:, None]
        A = [np.einsum("nij,njk->nik", self.whiten, J) * scale[:, None, None] for J in blocks]
        keys = [self.keys[n][:, i] for n in self.names for i in range(self.keys[n].shape[1])]
        return keys, A, b

    def linearize(self, values: gtsam.Values, poses: dict | None = None) -> list[gtsam.JacobianFactor]:
        """:meth:`jacobian` as one GTSAM ``JacobianFactor`` per factor (:func:`gaussian_factor`)."""
        keys, A, b = self.jacobian(values, poses)
        unit = gtsam.noiseModel.Unit.Create(len(self.rows))
        out = []
        for r in range(len(b)):
            items = []
            for key, a in zip(keys, A):
                items += [int(key[r]), a[r]]
            out.append(gaussian_factor(items, b[r], unit, values))
        return out


def _stacked(items: list, shape: tuple) -> np.ndarray:
    """``items`` (numbers or arrays, all of one size) as one float array (N, *shape); one conversion of
    the whole list, per item only when they differ in shape."""
    try:
        out = np.asarray(items, dtype=np.float64)
    except ValueError:  # arrays of different shapes (but one size)
        out = np.array([np.asarray(x, dtype=np.float64).reshape(-1) for x in items])
    return out.reshape((len(items),) + shape)


_HEADING = np.array([[[0.0, 0.0, 1.0]]])
_UNIT = {m: gtsam.noiseModel.Unit.Create(m) for m in (1, 2, 3)}


def covariance_noise(cov) -> gtsam.noiseModel.Gaussian:
    """GTSAM's Gaussian noise model of the covariance ``cov``, with all its correlations.

    ``noiseModel.Gaussian.Covariance`` by default ("smart") makes a diagonal model of a covariance whose
    off-diagonal entries are all within 1e-9 of zero in absolute terms, whatever the diagonal: that drops
    the correlations of every covariance of small entries, e.g. a visual increment's (σ of 20 µm and
    20 µrad, variances 4e-10, correlation of its lateral and heading errors -0.15), which the EKF keeps.
    Without them the graph solves another problem than the filter: where the gyro corrects the camera's
    heading change, the translation does not move with it (``tests/backends/test_models.py``,
    ``docs/decisions/0009-graph-keeps-correlations-and-reweights.md``). Here the model is always the full
    Gaussian (for a diagonal covariance the same whitening).
    """
    return gtsam.noiseModel.Gaussian.Covariance(np.atleast_2d(np.asarray(cov, dtype=np.float64)), False)


def whitening(cov: np.ndarray) -> np.ndarray:
    """Whitening matrices ``W`` (N, m, m) with ``Wᵀ W = Σ⁻¹`` of covariances ``Σ`` (N, m, m), with all their
    correlations (as :func:`covariance_noise`)."""
    cov = np.array(cov, dtype=np.float64)
    m = cov.shape[1]
    if m == 1:
        return 1.0 / np.sqrt(cov)
    return np.linalg.inv(np.linalg.cholesky(cov))  # W = C⁻¹ for Σ = C Cᵀ


def _relative_one(pi: gtsam.Pose2, pj: gtsam.Pose2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_relative` of one pair of poses, without array overhead."""
    ti = pi.theta()
    c, s = math.cos(ti), math.sin(ti)
    tx, ty = pj.x() - pi.x(), pj.y() - pi.y()
    dx, dy = c * tx + s * ty, -s * tx + c * ty
    dpsi = (pj.theta() - ti + math.pi) % (2.0 * math.pi) - math.pi
    cp, sp = math.cos(dpsi), math.sin(dpsi)
    d_i = np.array([[-1.0, 0.0, dy], [0.0, -1.0, -dx], [0.0, 0.0, -1.0]])
    d_j = np.array([[cp, -sp, 0.0], [sp, cp, 0.0], [0.0, 0.0, 1.0]])
    return np.array([dx, dy, dpsi]), d_i, d_j


class ValuesMaker:
    """Small ``gtsam.Values`` of Pose2 and scalar values, made quickly.

    Inserting a Python float into ``gtsam.Values`` costs tens of microseconds (the binding tries its
    many ``insert`` overloads first); retracting a Values of zeros for the same keys by a
    ``VectorValues`` costs a few. The zero templates are kept per set of scalar keys (a node's
    segment variables change once per segment).
    """

    def __init__(self, capacity: int = 64):
        self._templates: dict[tuple, gtsam.Values] = {}
        self._capacity = capacity

    def make(self, items: dict) -> gtsam.Values:
        """``gtsam.Values`` holding ``key -> Pose2 or float`` items."""
        scalars = tuple(sorted(k for k, v in items.items() if not isinstance(v, gtsam.Pose2)))
        if scalars:
            base = self._templates.get(scalars)
            if base is None:
                if len(self._templates) >= self._capacity:
                    self._templates.clear()
                base = gtsam.Values()
                for key in scalars:
                    base.insert(key, 0.0)
                self._templates[scalars] = base
            delta = gtsam.VectorValues()
            for key in scalars:
                delta.insert(key, np.array([float(items[key])]))
            out = base.retract(delta)
        else:
            out = gtsam.Values()
        for key, v in items.items():
            if isinstance(v, gtsam.Pose2):
                out.insert(key, v)
        return out


def _poses(values: gtsam.Values, keys: np.ndarray, poses: dict | None) -> np.ndarray:
    """Poses (N, 3) of ``keys``; ``poses`` (from :func:`pose_table`) avoids one lookup per key."""
    if poses is not None:
        return poses["xyyaw"][np.searchsorted(poses["keys"], keys)]
    out = np.empty((len(keys), 3))
    for i, k in enumerate(keys):
        p = values.atPose2(int(k))
        out[i] = (p.x(), p.y(), p.theta())
    return out


def _scalars(values: gtsam.Values, keys: np.ndarray, table: dict | None) -> np.ndarray:
    """Scalar values (N, 1) of ``keys``; ``table`` (from :func:`scalar_table`) avoids one lookup per key."""
    if table is not None:
        return table["values"][np.searchsorted(table["keys"], keys)][:, None]
    return np.array([[values.atDouble(int(k))] for k in keys])


def scalar_table(keys: np.ndarray, values: np.ndarray) -> dict:
    """``{"keys": sorted keys, "values": their values}`` of scalar variables (``keys`` sorted)."""
    return {"keys": np.asarray(keys, dtype=np.int64), "values": np.asarray(values, dtype=np.float64)}


#: GTSAM symbol letters of the Pose2 variables: the poses, the camera's frame poses and the world frame of a stream
#: aligned to GPS fixes (:func:`fusion_vo.backends.graph_builder.X`, :func:`~fusion_vo.backends.graph_builder.F`,
#: :func:`~fusion_vo.backends.graph_builder.T_WS`)
POSE_LETTERS = ("x", "F", "E")


def pose_table(values: gtsam.Values, keys: np.ndarray | None = None) -> dict:
    """All Pose2 values at once: ``{"keys": sorted keys, "xyyaw": (N, 3)}`` (``keys``: those of an
    earlier table of values with the same variables)."""
    xyyaw = gtsam.utilities.extractPose2(values)
    if keys is None:
        keys = np.array([k for k in values.keys() if chr(gtsam.Symbol(k).chr()) in POSE_LETTERS], dtype=np.int64)
    return {"keys": keys, "xyyaw": np.asarray(xyyaw, dtype=np.float64).reshape(-1, 3)}


def group(factors: list[ModelFactor]) -> list[ModelFactors]:
    """The factors sorted into :class:`ModelFactors` by signature."""
    by: dict = {}
    for f in factors:  # the signature's parts, without sorting (the builder makes each kind alike)
        by.setdefault((id(f.model), tuple(f.keys), tuple(f.fixed), tuple(f.params), f.rows, f.robust), []).append(f)
    return [ModelFactors(fs) for fs in by.values()]
