"""The sensors' readings as EKF updates: the one place the filter consumes a measurement model.

The filter's state holds the twist ``u = (v_x, v_y, ω)`` of the interval that ends at the current node
(:mod:`fusion_vo.backends.ekf`), so an interval reading is evaluated per unit time on it:

* a reading over one interval ``[T_k, T_{k+1}]`` of length ``Δt``: ``z / Δt`` with covariance ``R / Δt²``;
  the model's ``dt`` parameter is 1. A relative pose (``MeasurementModel.increment``) is read as its
  logarithm, the exact constant twist of the interval, ``log(z) / Δt``, with the covariance carried into
  those coordinates, ``J R Jᵀ / Δt²``, ``J = ∂ log(z) / ∂z`` (:func:`fusion_vo.geometry.se2.log_jacobian`);
* a reading over ``n`` intervals (frames dropped between two frames) is applied as its mean twist to each of
  them with ``n`` times that covariance (the same total information); intervals its own sensor's single-interval
  readings cover keep those;
* a node reading applies at its node: at node ``k + 1`` with the readings of interval ``k``, at node 0 before
  the first prediction.

Each reading becomes one block of :meth:`PlanarEkf.block <fusion_vo.backends.ekf.PlanarEkf.block>`: the model's
prediction and Jacobians at the state, its arguments read from the state's columns. The blocks of one
interval are gated one by one and applied together, in the readings' order.

A sensor whose readings state their frames' own errors (``Readings.frame_cov``, the camera) has those errors in
the filter's state: each prediction moves the current frame's error into the previous one's place and starts
the new frame's with that covariance (in twist coordinates, per unit time as above), and a single-interval
reading becomes ``h + (e_this - e_prev) / Δt`` with the rest of its covariance, ``R - 2 Σ_e``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fusion_vo.geometry import se2
from fusion_vo.sensors.readings import Readings


@dataclass
class _Table:
    """One :class:`Readings` on the filter's grid: per interval (or node) whether it applies, its reading and
    covariance in the filter's units, and the index of the reading it came from (for its parameters)."""

    readings: Readings
    ok: np.ndarray
    z: np.ndarray
    R: np.ndarray
    index: np.ndarray
    frame_cov: np.ndarray | None = None  # (K, 3, 3): the frame error of single-interval readings
    frame_ok: np.ndarray | None = None
    rest_R: np.ndarray | None = None  # (K, m, m): R without the two frames' errors
    frame_dt: np.ndarray | None = None


def _as_rates(r: Readings, span: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """The readings per unit time over their spans: rates (M, dim), covariances (M, m, m) and, for readings with
    frame errors, those in the same units (M, 3, 3) (not yet divided by the span)."""
    cov = r.cov
    frame = r.frame_cov
    if r.model.increment:
        rate, Jf = se2.log_with_jacobian(r.z)
        J = Jf if r.rows is None else Jf[:, list(r.rows)][:, :, list(r.rows)]
        cov = J @ cov @ np.transpose(J, (0, 2, 1))
        if frame is not None:
            frame = Jf @ frame @ np.transpose(Jf, (0, 2, 1))
    else:
        rate = r.z.copy()
    return rate / span[:, None], cov, frame


#: variance [per unit time] of a component the consistency monitor dropped (a block's rows above it are not counted)
DROPPED_VAR = 1e8


def _dropped(R: np.ndarray, dropped: tuple, ok: np.ndarray) -> np.ndarray:
    """``R`` (K, 3, 3) of motion readings with the dropped components' rows and columns vague where ``ok``."""
    R = R.copy()
    rows = {"yaw": [2], "speed": [0, 1]}
    for component in dropped:
        for i in rows[component]:
            R[ok, i, :] = R[ok, :, i] = 0.0
        for i in rows[component]:
            R[ok, i, i] = DROPPED_VAR
    return R


def spread_covariance(cov: np.ndarray, n, span):
    """The covariance per unit time with which a reading over ``n`` node intervals of total length ``span`` is
    applied to each of them: ``n`` times that of its mean rate, ``cov n / span²`` (``cov`` that of the reading in
    rate coordinates times ``span``, :func:`_as_rates`), the same information over the span (module docstring).
    The one rule: the batch filter's tables and the streaming engine's share of an increment
    (:func:`fusion_vo.backends.stream_nodes.increment_part`) use it."""
    return cov * (n / span**2)


def interval_table(r: Readings, t: np.ndarray) -> _Table:
    """The interval readings ``r`` spread over the grid ``t`` (module docstring)."""
    K = len(t) - 1
    span = t[r.i1] - t[r.i0]
    n = r.i1 - r.i0
    rate, cov, frame = _as_rates(r, span)
    m = cov.shape[-1]
    ok = np.zeros(K, bool)
    z = np.zeros((K, r.model.dim))
    R = np.zeros((K, m, m))
    index = np.full(K, -1, dtype=np.int64)
    # single-interval readings first (the first of several over one interval), all at once; then the longer ones in
    # their order, each over the intervals no reading has taken
    single = np.flatnonzero(n == 1)
    k, first = np.unique(r.i0[single], return_index=True)
    j = single[first]
    z[k] = rate[j]
    R[k] = spread_covariance(cov[j], n[j][:, None, None], span[j][:, None, None])
    ok[k] = True
    index[k] = j
    for j in np.flatnonzero(n > 1)[np.argsort(n[n > 1], kind="stable")]:
        steps = np.arange(r.i0[j], r.i1[j])
        free = steps[~ok[steps]]
        if not len(free):
            continue
        z[free] = rate[j]
        R[free] = spread_covariance(cov[j], n[j], span[j])
        ok[free] = True
        index[free] = j
    if r.dropped:
        R = _dropped(R, r.dropped, ok)
    table = _Table(r, ok, z, R, index)
    if frame is not None:
        one = n == 1
        k = r.i0[one]
        table.frame_ok = np.zeros(K, bool)
        table.frame_ok[k] = True
        table.frame_cov = np.full((K, 3, 3), np.nan)
        table.frame_cov[k] = frame[one]
        table.rest_R = np.full((K, m, m), np.nan)
        table.rest_R[k] = (cov[one] - 2.0 * frame[one]) / (span[one] ** 2)[:, None, None]
        table.frame_dt = np.diff(t)
    return table


def node_table(r: Readings, t: np.ndarray) -> _Table:
    """The node readings ``r`` on the grid ``t``: one per node at most (the last one given)."""
    N = len(t)
    ok = np.zeros(N, bool)
    z = np.zeros((N, r.model.dim))
    m = r.cov.shape[-1]
    R = np.zeros((N, m, m))
    index = np.full(N, -1, dtype=np.int64)
    ok[r.i0] = True
    z[r.i0] = r.z
    R[r.i0] = r.cov
    index[r.i0] = np.arange(len(r))
    return _Table(r, ok, z, R, index)


class EkfReadings:
    """Every reading of a run on the filter's grid (module docstring).

    Parameters
    ----------
    readings : list of Readings
    t : ndarray (K+1,)
        The node times.
    """

    def __init__(self, readings: list[Readings], t: np.ndarray):
        t = np.asarray(t, dtype=np.float64)
        self.t = t
        self.intervals: list[_Table] = []
        self.nodes: list[_Table] = []
        #: absolute readings of the pose, applied on their own (:mod:`fusion_vo.backends.fixes`)
        self.absolute: list[Readings] = []
        for r in sorted(readings, key=lambda r: r.order):
            if not len(r):
                continue
            if r.absolute is not None:
                self.absolute.append(r)
            elif r.at_nodes:
                self.nodes.append(node_table(r, t))
            else:
                self.intervals.append(interval_table(r, t))
        framed = [tb for tb in self.intervals if tb.frame_cov is not None]
        if len(framed) > 1:
            raise ValueError("only one sensor's readings may state frame errors (the filter carries one camera's)")
        self.framed = framed[0] if framed else None

    @property
    def frame_errors(self) -> bool:
        """Whether the filter carries a sensor's frame errors."""
        return self.framed is not None

    def frame_cov(self, k: int) -> np.ndarray | None:
        """The frame error of the reading over interval ``k`` (for the prediction into node ``k + 1``), or None
        where no single-interval reading states one (the filter keeps the last)."""
        tb = self.framed
        return tb.frame_cov[k] if tb is not None and tb.frame_ok[k] else None

    def orders(self) -> list[float]:
        """The orders of the readings' blocks (to interleave them with other blocks)."""
        return [tb.readings.order for tb in self.intervals + self.nodes]

    def start(self, ekf) -> list:
        """Blocks of the node readings at node 0."""
        return [self._block(ekf, tb, 0) for tb in self.nodes if tb.ok[0]]

    def blocks(self, ekf, k: int) -> list[tuple[float, tuple]]:
        """``(order, block)`` of interval ``k``'s readings and of the node readings at node ``k + 1``."""
        out = []
        for tb in self.intervals:
            if tb.ok[k]:
                out.append((tb.readings.order, self._interval_block(ekf, tb, k)))
        for tb in self.nodes:
            if tb.ok[k + 1]:
                out.append((tb.readings.order, self._block(ekf, tb, k + 1)))
        return out

    @staticmethod
    def _params(tb: _Table, i: int) -> dict:
        r = tb.readings
        j = int(tb.index[i])
        params = {name: r.param(name, j) for name in r.params}
        params.update(r.fixed)
        return params

    def _block(self, ekf, tb: _Table, i: int):
        r = tb.readings
        return ekf.block(r.model, tb.z[i], tb.R[i], rows=r.rows, name=r.sensor, **self._params(tb, i))

    def _interval_block(self, ekf, tb: _Table, k: int):
        r = tb.readings
        if tb is not self.framed or ekf.frame_errors is None or not tb.frame_ok[k]:
            return self._block(ekf, tb, k)
        name, z, h, H, R, angle = ekf.block(r.model, tb.z[k], tb.rest_R[k], rows=r.rows, name=r.sensor,
                                            **self._params(tb, k))
        e0, e1 = ekf.frame_errors
        x = ekf.x
        inv_dt = 1.0 / tb.frame_dt[k]
        H[:, e0] -= np.eye(3) * inv_dt
        H[:, e1] += np.eye(3) * inv_dt
        return name, z, h + (x[e1] - x[e0]) * inv_dt, H, R, angle
