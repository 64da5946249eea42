"""Per-sensor normalised residuals of a factor-graph solution (the graph's NIS).

A filter tests each measurement against its prediction (its innovation). A smoother has no prediction, but
the same test exists at its solution: for a measurement ``z = h(x) + n``, ``n ~ N(0, R)``, of a linear(ised)
least-squares problem, the residual at the solution ``r = z - h(x̂)`` has covariance ``R - H P Hᵀ`` (``P`` the
posterior covariance of the variables it touches), and

    NIS = rᵀ (R - H P Hᵀ)⁻¹ r  =  ẽᵀ (I - A P Aᵀ)⁻¹ ẽ,      ẽ = W r,  A = W H,  WᵀW = R⁻¹

is chi-square with the measurement's size as degrees of freedom when the noise model is right. It equals
the leave-one-out statistic (the measurement against the solution without it, ``r₋ᵢᵀ (R + H P₋ᵢ Hᵀ)⁻¹ r₋ᵢ``),
which is what ``benchmarks/consistency.py`` computes for the EKF against the other sensors of a step.
Above its degrees of freedom the sensor's stated noise is too small; below, too large.

The factors are each sensor's measurement-model factors (:class:`~fusion_vo.backends.factors.ModelFactor`,
named by their model: ``camera``, ``wheel``, ``gyro``, ``standstill``, ``ahrs``, and those of registered
sensors); the ones that end at the same node and come from the same sensor are tested together (the wheels'
translation and heading factors are one 3-row measurement, like the EKF's wheel block). Their residuals are
the Gaussian ones (no robust kernel: the test is of the noise model), ``P`` comes from
``gtsam.Marginals`` at the solution. Rows the graph leaves free on purpose (a standard deviation of at least
:data:`FREE_SIGMA`: the wheels' heading row in their translation factor, a component the consistency
monitor dropped) are not counted. GTSAM's native factors (``BetweenFactorPose2`` without self-calibration,
GPS, the range prior) are not included.
"""

from __future__ import annotations

import dataclasses
import logging

import gtsam
import numpy as np

from fusion_vo.backends.factors import ModelFactor, ModelFactors

logger = logging.getLogger(__name__)

#: rows with a standard deviation of at least this [m or rad] are free on purpose and not tested
FREE_SIGMA = 1.0


def _end_key(f: ModelFactor) -> int:
    keys = f.keys.get("motion") or f.keys.get("heading") or next(iter(f.keys.values()))
    return int(keys[-1])


def _rows(f: ModelFactor, values: gtsam.Values) -> tuple[np.ndarray, dict[int, np.ndarray], np.ndarray]:
    """Whitened Gaussian residual (m,) at ``values``, whitened Jacobian blocks per key and the rows kept (not free)."""
    g = ModelFactors([dataclasses.replace(f, robust=None)])
    e, blocks = g.evaluate(values)
    W = g.whiten[0]
    keys = [int(g.keys[n][0, i]) for n in g.names for i in range(g.keys[n].shape[1])]
    jac: dict[int, np.ndarray] = {}
    for key, J in zip(keys, blocks):
        A = W @ J[0]
        jac[key] = jac[key] + A if key in jac else A
    keep = np.sqrt(np.diag(np.atleast_2d(f.covariance))) < FREE_SIGMA
    return W @ e[0], jac, keep


def sensor_nis(factors: list[ModelFactor], values: gtsam.Values, marginals: gtsam.Marginals, node_of,
               stride: int = 1) -> dict[str, tuple[int, np.ndarray]]:
    """Per sensor, the NIS of its measurements at the solution ``values`` (module docstring).

    Parameters
    ----------
    factors : list of ModelFactor
        The graph's sensor-model factors.
    values : gtsam.Values
        The solution.
    marginals : gtsam.Marginals
        Of the graph linearised at (or next to) ``values``.
    node_of : callable
        ``node_of(pose key) -> (node index, time)``.
    stride : int
        Test only the measurements ending at every ``stride``-th node (the joint marginals cost).

    Returns
    -------
    dict
        Sensor -> ``(dof, rows)`` with rows ``(t, NIS)`` (M, 2) in time order; measurements with fewer rows
        than the sensor's usual size (a dropped component) are under ``"<sensor> (<dof> rows)"``.
    """
    groups: dict[tuple[str, int], list[ModelFactor]] = {}
    for f in factors:
        groups.setdefault((f.model.name, _end_key(f)), []).append(f)
    out: dict[str, list] = {}
    fallback = 0
    for (name, end), fs in groups.items():
        n, t = node_of(end)
        if n % stride:
            continue
        es, jacs = [], []
        for f in fs:
            e, jac, keep = _rows(f, values)
            es.append(e[keep])
            jacs.append({k: a[keep] for k, a in jac.items()})
        e = np.concatenate(es)
        if not len(e):
            continue
        keys = sorted({k for jac in jacs for k in jac})
        dims = [jacs[[k in j for j in jacs].index(True)][k].shape[1] for k in keys]
        offsets = np.concatenate([[0], np.cumsum(dims)])
        A = np.zeros((len(e), offsets[-1]))
        row = 0
        for jac, ei in zip(jacs, es):
            for k, a in jac.items():
                i = keys.index(k)
                A[row:row + len(ei), offsets[i]:offsets[i + 1]] = a
            row += len(ei)
        joint = marginals.jointMarginalCovariance(gtsam.KeyVector(keys))
        P = np.zeros((offsets[-1], offsets[-1]))
        for i, ki in enumerate(keys):
            for j, kj in enumerate(keys):
                P[offsets[i]:offsets[i + 1], offsets[j]:offsets[j + 1]] = joint.at(ki, kj)
        S = np.eye(len(e)) - A @ P @ A.T
        S = 0.5 * (S + S.T)
        if np.all(np.isfinite(S)) and np.linalg.eigvalsh(S)[0] > 0.0:
            value = float(e @ np.linalg.solve(S, e))
        else:
            # the residual's covariance came out indefinite: the marginals weigh this measurement less than
            # its stated noise (the robust kernel down-weighted it; it is then far outside its noise) or are
            # of another linearisation (iSAM2's frozen factors). Its residual against the stated noise
            # alone, ẽᵀẽ, is taken instead: never above the NIS, never negative
            fallback += 1
            value = float(e @ e)
        out.setdefault((name, len(e)), []).append((t, value))
    if fallback:
        logger.debug("%d measurements' residual covariance was not positive definite: NIS against their noise alone",
                     fallback)
    usual = {}
    for (name, dof), rows in out.items():
        if len(rows) > len(out.get((name, usual.get(name, -1)), ())):
            usual[name] = dof
    result = {}
    for (name, dof), rows in out.items():
        label = name if usual[name] == dof else f"{name} ({dof} rows)"
        result[label] = (dof, np.array(sorted(rows)))
    return result

