"""The batch Levenberg–Marquardt of a chain-shaped graph and its marginal covariances, in one sweep each.

The batch graph of :mod:`fusion_vo.backends.graph` is a chain: every factor ties variables that are
close in time (consecutive poses, a visual span of a few frames, a segment's bias and calibration
variables with the poses of that segment and the next segment's). With the variables ordered by time,
its normal equations ``H δ = g`` (``H = AᵀA``, ``g = Aᵀb`` of the whitened, robustly reweighted
linearisation, exactly the system GTSAM eliminates) are *block tridiagonal*: the variables split into
consecutive blocks of a few dozen columns and each block couples only to its two neighbours.

Such a system is solved by a block Cholesky sweep forwards and backwards, and the marginal covariances
of all variables come from one more backward sweep (the block-tridiagonal inverse, as a
Rauch–Tung–Striebel smoother computes it)::

    L_0 L_0ᵀ = D_0,   C_k = E_k L_k⁻ᵀ,   L_{k+1} L_{k+1}ᵀ = D_{k+1} - C_k C_kᵀ
    Σ_K = L_K⁻ᵀ L_K⁻¹,   G_k = L_k⁻ᵀ C_kᵀ,   Σ_k = L_k⁻ᵀ L_k⁻¹ + G_k Σ_{k+1} G_kᵀ

(``D_k`` the diagonal blocks of ``H``, ``E_k`` the block below ``D_k``.) Each step is a dense LAPACK
call on blocks of a few dozen columns, so the cost is linear in the length of the drive.

The Levenberg–Marquardt iteration (:func:`levenberg_marquardt`) is the standard one, as in GTSAM's
``LevenbergMarquardtOptimizer`` but with a schedule of its own for the damping λ: solve the damped Gauss–Newton
system ``(H + λ I) δ = g`` and keep ``x ⊕ δ`` if it lowers the cost; otherwise λ grows tenfold (from 1e-4) and
the step is tried again, and above 1e8 the iteration stops where it is. After a kept step λ shrinks tenfold (to
0 below 1e-3, a plain Gauss–Newton step; GTSAM's starts at 1e-5 and stops above 1e5). The iteration ends when a
kept step lowers the cost by less than ``relative_tolerance`` of it, or after ``max_iterations`` linearisations.
``tests/backends/test_solver_equals_gtsam.py`` holds it to GTSAM's optimizer on a small drive's graph, with and
without a robust kernel at work: the same steps and solution where every Gauss–Newton step lowers the cost, and
the same minimum from a start far off; on Rosenbrock's function, whose first Gauss–Newton step raises the cost,
it holds the damping's growth.

Why not GTSAM's own optimizers: they need each sensor-model factor as a ``gtsam.CustomFactor`` that calls back
into Python at every linearisation; here the sensor-model factors are linearised in numpy, all factors of a
kind at once (:meth:`fusion_vo.backends.factors.ModelFactors.jacobian`), and the marginal covariances come
from the same factorisation instead of one ``Marginals.marginalCovariance`` call per pose. GTSAM still
linearises its own factors (priors, random walks, ``BetweenFactorPose2``:
``NonlinearFactorGraph.linearize`` and ``GaussianFactorGraph.sparseJacobian_``), evaluates their
error and retracts the values (``Values.retract``). A graph that is not block tridiagonal in time order
with blocks of at most :data:`MAX_BLOCK` columns (a long loop closure, calibration segments of many
seconds) raises :class:`NotAChain` and the caller solves it with GTSAM's own optimizer
(:func:`fusion_vo.backends.graph.gtsam_levenberg_marquardt`).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any, Callable

import gtsam
import numpy as np
import scipy.sparse
from scipy.linalg import lapack

from fusion_vo.backends.factors import ModelFactors, pose_table, scalar_table

logger = logging.getLogger(__name__)

# LAPACK's Cholesky and triangular solves called directly: scipy.linalg's wrappers check and copy
# their arguments at tens of microseconds a call, more than the arithmetic on these small blocks
_potrf, _trtrs, _trtri = lapack.dpotrf, lapack.dtrtrs, lapack.dtrtri

# The sweeps are meant to run with a single-threaded BLAS (the caller wraps them in
# ``threadpoolctl.threadpool_limits(1, "blas")``): on blocks of about 60 columns OpenBLAS's threads
# cost more than they save, and on a busy machine far more (docs/decisions/0007-ekf-single-threaded-blas.md).

#: the largest block (columns) of the block-tridiagonal system; beyond it GTSAM's elimination is used
MAX_BLOCK = 400
#: the smallest block: fewer, larger blocks mean fewer Python steps per sweep
MIN_BLOCK = 48


class NotAChain(RuntimeError):
    """The normal equations are not block tridiagonal with small blocks in the given order."""


class Indeterminate(RuntimeError):
    """The normal equations are not positive definite (GTSAM: an indeterminant linear system)."""


@dataclass
class Layout:
    """Columns of the variables in time order and the blocks of the block-tridiagonal system."""

    keys: np.ndarray  # (V,) variable keys in time order
    dims: np.ndarray  # (V,) their dimensions
    offset: np.ndarray  # (V,) first column of each
    n: int  # columns
    starts: np.ndarray  # (K + 1,) first column of each block, and n
    size: int  # columns of the largest block (all blocks padded to it)

    @property
    def n_blocks(self) -> int:
        return len(self.starts) - 1

    @cached_property
    def padded_index(self) -> np.ndarray:
        """Position of each column in the padded block storage (K, size)."""
        block = np.searchsorted(self.starts, np.arange(self.n), side="right") - 1
        return np.arange(self.n) - self.starts[block] + block * self.size

    @cached_property
    def padding(self) -> np.ndarray:
        """Flat positions, in the diagonal blocks (K, size, size), of the padding columns' diagonal entries."""
        pad = np.setdiff1d(np.arange(self.n_blocks * self.size), self.padded_index)
        block, i = pad // self.size, pad % self.size
        return block * self.size * self.size + i * (self.size + 1)

    def columns(self, keys: np.ndarray) -> np.ndarray:
        """First column of each of ``keys``."""
        if "_order" not in self.__dict__:
            self._order = np.argsort(self.keys)
            self._sorted = self.keys[self._order]
        keys = np.asarray(keys, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self._sorted, keys), len(self._sorted) - 1)
        if np.any(self._sorted[pos] != keys):
            raise NotAChain("a factor's variable is not in the layout")
        return self.offset[self._order[pos]]

    def slots(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Flat positions in the block storage (diagonal blocks, then the blocks below them) of the
        entries ``H[rows, cols]``; -1 for entries above the block diagonal (mirrored elsewhere)."""
        K, M = self.n_blocks, self.size
        block = self.padded_index // M  # the block of each column, and the column within it
        br, bc = block[rows], block[cols]
        lr, lc = rows - self.starts[br], cols - self.starts[bc]
        if np.any(np.abs(br - bc) > 1):
            raise NotAChain("a factor couples blocks that are not neighbours")
        out = np.full(len(rows), -1, dtype=np.int64)
        diag = br == bc
        out[diag] = (br[diag] * M + lr[diag]) * M + lc[diag]
        below = br == bc + 1
        out[below] = K * M * M + (bc[below] * M + lr[below]) * M + lc[below]
        return out


def layout(keys: np.ndarray, dims: np.ndarray, rank: np.ndarray, pairs: list[tuple[np.ndarray, np.ndarray]]) -> Layout:
    """Order the variables by ``rank`` (time) and cut the columns into blocks so that every coupling
    in ``pairs`` (arrays of coupled keys) lies within a block or between neighbouring blocks."""
    order = np.lexsort((keys, rank))
    keys, dims = np.asarray(keys, dtype=np.int64)[order], np.asarray(dims, dtype=np.int64)[order]
    offset = np.concatenate([[0], np.cumsum(dims)[:-1]])
    n = int(dims.sum())
    lay = Layout(keys, dims, offset, n, np.array([0, n]), n)
    # reach[c]: the last column any column <= c is coupled to (a variable's columns are coupled)
    reach = np.repeat(offset + dims - 1, dims)
    for a, b in pairs:
        ca, cb = lay.columns(np.asarray(a, dtype=np.int64)), lay.columns(np.asarray(b, dtype=np.int64))
        da = dims[np.searchsorted(offset, ca)]
        db = dims[np.searchsorted(offset, cb)]
        np.maximum.at(reach, np.minimum(ca, cb), np.maximum(ca + da, cb + db) - 1)
    reach = np.maximum.accumulate(reach)

    def cut(c: int) -> int:  # the first variable boundary at or after column c
        i = int(np.searchsorted(offset, c))
        return n if i >= len(offset) else int(offset[i])

    starts = [0, cut(min(MIN_BLOCK, n))]
    while starts[-1] < n:
        starts.append(cut(max(int(reach[starts[-1] - 1]) + 1, starts[-1] + MIN_BLOCK)))
    starts = np.array(starts, dtype=np.int64)
    size = int(np.diff(starts).max())
    if size > MAX_BLOCK:
        raise NotAChain(f"the normal equations need blocks of {size} columns")
    return Layout(keys, dims, offset, n, starts, size)


class System:
    """The normal equations of one linearisation in block storage, factorised on demand."""

    def __init__(self, lay: Layout, flat: np.ndarray, g: np.ndarray):
        K, M = lay.n_blocks, lay.size
        self.lay = lay
        self.point = None  # the values it was linearised at (ChainProblem.linearize)
        self.D = flat[:K * M * M].reshape(K, M, M)
        self.E = flat[K * M * M:].reshape(max(K - 1, 0), M, M)
        self.g = np.zeros(K * M)
        self._index = lay.padded_index
        self.g[self._index] = g
        self.D.reshape(-1)[lay.padding] = 1.0  # padding: decoupled unit variables
        # E_k couples only the last few columns of block k to block k+1 (what reaches across the cut):
        # the first column of block k that E_k touches, M where none does
        touched = np.any(self.E != 0.0, axis=1)  # (K-1, M): columns of block k with a coupling
        self.tail = np.where(touched.any(axis=1), np.argmax(touched, axis=1), M)

    def factor(self, damping: float = 0.0):
        """Block Cholesky factors ``(L_k, C_k)`` of ``H + damping I``; :class:`Indeterminate` if not positive definite.

        ``E_k`` is zero left of column ``tail[k]`` of block ``k``, so ``C_k = E_k L_k⁻ᵀ`` is zero there too
        (forward substitution through leading zeros): ``C_k`` comes from the trailing corner of ``L_k``
        alone and the update of the next diagonal block, ``C_k C_kᵀ``, has that few columns' rank.
        """
        K, M = self.D.shape[0], self.D.shape[1]
        L = np.empty_like(self.D)
        C = np.zeros_like(self.E)
        eye = damping * np.eye(M)
        prev = None  # the nonzero columns of C_{k-1}
        for k in range(K):
            Dk = self.D[k] + eye if damping > 0 else self.D[k]
            if prev is not None and prev.shape[1]:
                Dk = Dk - prev @ prev.T
            Lk, info = _potrf(Dk, lower=1, clean=1)
            if info != 0 or not np.all(np.isfinite(Lk)):
                raise Indeterminate(f"the normal equations are not positive definite (block {k})")
            L[k] = Lk
            if k < K - 1:
                c = int(self.tail[k])
                if c < M:
                    Ct, info = _trtrs(Lk[c:, c:], self.E[k, :, c:].T, lower=1)
                    C[k, :, c:] = Ct.T
                prev = C[k, :, c:]
        return L, C

    def solve(self, factors) -> np.ndarray:
        """``δ`` (n,) of ``(H + damping I) δ = g`` from :meth:`factor`'s factors."""
        L, C = factors
        K, M = L.shape[0], L.shape[1]
        y = np.empty((K, M))
        g = self.g.reshape(K, M)
        tail = self.tail  # C_k is zero left of column tail[k] (factor)
        for k in range(K):
            r = g[k]
            if k > 0:
                c = int(tail[k - 1])
                r = r - C[k - 1, :, c:] @ y[k - 1, c:]
            y[k] = _trtrs(L[k], r, lower=1)[0]
        x = np.empty((K, M))
        for k in range(K - 1, -1, -1):
            r = y[k]
            if k < K - 1:
                c = int(tail[k])
                r = r.copy()
                r[c:] -= C[k, :, c:].T @ x[k + 1]
            x[k] = _trtrs(L[k], r, lower=1, trans=1)[0]
        return x.reshape(-1)[self._index]

    def marginal_blocks(self, factors, columns: np.ndarray, dim: int) -> np.ndarray:
        """Marginal covariances (len(columns), dim, dim) of the variables starting at ``columns``
        (each within one block), from the diagonal blocks of ``H⁻¹`` in one backward sweep."""
        L, C = factors
        K, M = L.shape[0], L.shape[1]
        lay = self.lay
        blk = np.searchsorted(lay.starts, columns, side="right") - 1
        local = columns - lay.starts[blk]
        if np.any(local + dim > lay.starts[blk + 1] - lay.starts[blk]):
            raise NotAChain("a variable straddles two blocks")
        out = np.empty((len(columns), dim, dim))
        order = np.argsort(blk, kind="stable")
        bounds = np.searchsorted(blk[order], np.arange(K + 1))
        ramp = np.arange(dim)
        sigma = None
        for k in range(K - 1, -1, -1):
            Linv = _trtri(L[k], lower=1)[0]
            s = Linv.T @ Linv
            if sigma is not None:
                # G_k Σ G_kᵀ with G_k = L_k⁻ᵀ C_kᵀ, C_k zero left of its tail column c:
                # (L_k⁻¹)[c:]ᵀ (C_k[:, c:]ᵀ Σ C_k[:, c:]) (L_k⁻¹)[c:]
                c = int(self.tail[k])
                if c < M:
                    Cc, P = C[k, :, c:], Linv[c:]
                    s += P.T @ (Cc.T @ sigma @ Cc) @ P
            sigma = s
            sel = order[bounds[k]:bounds[k + 1]]
            if len(sel):
                idx = local[sel][:, None] + ramp
                out[sel] = sigma[idx[:, :, None], idx[:, None, :]]
        return out


class ChainProblem:
    """The batch graph's normal equations in block-tridiagonal form.

    Parameters
    ----------
    graph : gtsam.NonlinearFactorGraph
        GTSAM's own factors (linearised by GTSAM).
    groups : list of ModelFactors
        The sensor-model factors (linearised in numpy).
    values : gtsam.Values
        Initial values of every variable.
    dims : dict
        Variable key -> dimension.
    rank : callable
        Variable keys (array) -> their positions in time (the order of the columns).
    """

    def __init__(self, graph: gtsam.NonlinearFactorGraph, groups: list[ModelFactors], values: gtsam.Values,
                 dims: dict[int, int], rank):
        self.graph = graph
        self.groups = groups
        keys = np.array(sorted(dims), dtype=np.int64)
        self.dims = dims
        is_pose = np.array([dims[int(k)] == 3 for k in keys])
        self.pose_keys = keys[is_pose]
        self.scalar_keys = keys[~is_pose]
        pairs = []
        for g in groups:
            ks = [self._group_keys(g)]
            for kk in ks:
                for i in range(len(kk)):
                    for j in range(i + 1, len(kk)):
                        pairs.append((kk[i], kk[j]))
        self.native_keys = np.array(sorted(int(k) for k in graph.keyVector()), dtype=np.int64)
        na, nb = [], []
        for i in range(graph.size()):
            f = graph.at(i)
            fk = [int(k) for k in f.keys()] if f is not None else []
            for a in range(len(fk)):
                for b in range(a + 1, len(fk)):
                    na.append(fk[a])
                    nb.append(fk[b])
        if na:
            pairs.append((np.array(na, dtype=np.int64), np.array(nb, dtype=np.int64)))
        self.lay = layout(keys, np.array([dims[int(k)] for k in keys]), np.asarray(rank(keys)), pairs)
        # GTSAM's sparse Jacobian of its own factors: columns of its sorted keys, then the right-hand side
        native_dims = np.array([dims[int(k)] for k in self.native_keys], dtype=np.int64)
        cols = self.lay.columns(self.native_keys) if len(self.native_keys) else np.zeros(0, dtype=np.int64)
        self._native_cols = np.concatenate([np.repeat(cols, native_dims) + _ramp(native_dims), [-1]])
        self._group_slots = [self._slots_of(g) for g in groups]
        self._flat_size = (2 * self.lay.n_blocks - 1) * self.lay.size ** 2
        if self.lay.n_blocks < 1:
            raise NotAChain("no variables")

    @staticmethod
    def _group_keys(g: ModelFactors) -> list[np.ndarray]:
        return [g.keys[n][:, i] for n in g.names for i in range(g.keys[n].shape[1])]

    def _slots_of(self, g: ModelFactors):
        """The flat slots of the entries of each factor's ``AᵀA`` (A: its Jacobian blocks side by side,
        one factor after the other) that are stored, which ones, and the gradient's columns."""
        keys = self._group_keys(g)
        cols = np.concatenate([self.lay.columns(k)[:, None] + np.arange(self.dims[int(k[0])])[None, :] for k in keys],
                              axis=1)  # (N, D) columns of each factor's Jacobian
        n, d = cols.shape
        r = np.broadcast_to(cols[:, :, None], (n, d, d)).reshape(-1)
        c = np.broadcast_to(cols[:, None, :], (n, d, d)).reshape(-1)
        s = self.lay.slots(r, c)
        ok = s >= 0
        return ok, s[ok], cols.reshape(-1)

    # ------------------------------------------------------------------ values
    def tables(self, values: gtsam.Values) -> tuple[dict, dict]:
        poses = pose_table(values, self.pose_keys)
        scalars = scalar_table(self.scalar_keys, [values.atDouble(int(k)) for k in self.scalar_keys])
        return poses, scalars

    def error(self, values: gtsam.Values, tables) -> float:
        poses, scalars = tables
        return self.graph.error(values) + sum(g.error(values, poses, scalars) for g in self.groups)

    def retract(self, values: gtsam.Values, tables, delta: np.ndarray):
        """``values ⊕ δ`` (GTSAM's retraction) and its tables."""
        lay = self.lay
        vv = gtsam.VectorValues()
        for key, o, d in zip(lay.keys.tolist(), lay.offset.tolist(), lay.dims.tolist()):
            vv.insert(key, delta[o:o + d])
        out = values.retract(vv)
        poses = pose_table(out, self.pose_keys)
        _, scalars = tables
        cols = lay.columns(self.scalar_keys) if len(self.scalar_keys) else np.zeros(0, dtype=np.int64)
        return out, (poses, scalar_table(self.scalar_keys, scalars["values"] + delta[cols]))

    # ------------------------------------------------------------------ linearisation
    def linearize(self, values: gtsam.Values, tables) -> System:
        """The normal equations of the linearisation at ``values``."""
        poses, scalars = tables
        slots, weights, gcols, gvals = [], [], [], []
        for grp, (ok, s, cols) in zip(self.groups, self._group_slots):
            _, A, b = grp.jacobian(values, poses, scalars)
            A = np.concatenate(A, axis=2) if len(A) > 1 else A[0]  # (N, m, D)
            At = A.transpose(0, 2, 1)
            slots.append(s)
            weights.append(np.matmul(At, A).reshape(-1)[ok])
            gcols.append(cols)
            gvals.append(np.matmul(At, b[:, :, None]).reshape(-1))
        if self.graph.size():
            t = self.graph.linearize(values).sparseJacobian_()
            rows, cols, vals = t[0].astype(np.int64) - 1, self._native_cols[t[1].astype(np.int64) - 1], t[2]
            n_rows = int(rows.max()) + 1 if len(rows) else 0
            rhs = np.zeros(n_rows)
            is_b = cols < 0
            rhs[rows[is_b]] = vals[is_b]
            J = scipy.sparse.csr_matrix((vals[~is_b], (rows[~is_b], cols[~is_b])), shape=(n_rows, self.lay.n))
            H = (J.T @ J).tocoo()
            s = self.lay.slots(H.row.astype(np.int64), H.col.astype(np.int64))
            ok = s >= 0
            slots.append(s[ok])
            weights.append(H.data[ok])
            gcols.append(np.arange(self.lay.n))
            gvals.append(J.T @ rhs)
        flat = np.bincount(np.concatenate(slots), weights=np.concatenate(weights), minlength=self._flat_size)
        g = np.bincount(np.concatenate(gcols), weights=np.concatenate(gvals), minlength=self.lay.n)
        system = System(self.lay, flat, g)
        system.point = values
        return system


def _ramp(dims: np.ndarray) -> np.ndarray:
    """``[0..d_0-1, 0..d_1-1, ...]``."""
    if len(dims) == 0:
        return np.zeros(0, dtype=np.int64)
    starts = np.repeat(np.cumsum(dims) - dims, dims)
    return np.arange(int(dims.sum())) - starts


def levenberg_marquardt(problem: ChainProblem, values: gtsam.Values, max_iterations: int = 20,
                        relative_tolerance: float = 1e-3):
    """Levenberg–Marquardt (module docstring) from ``values`` on the block-tridiagonal system.

    It stays beside GTSAM's ``LevenbergMarquardtOptimizer`` because on the batch graph of the 60 s generated
    drive it takes 32-39 ms of CPU where GTSAM's optimizer takes 3.7-4.3 s on the same factors, to the same
    cost (``python benchmarks/backend_speed.py solvers``; docs/decisions/0006-own-levenberg-marquardt-loop.md).

    Returns
    -------
    solution, iterations, system
        The solution, the number of linearisations, and the last linearisation (:class:`System`, for
        :func:`pose_marginals`).
    """
    def attempt(state, system, lam):
        values, tables = state
        try:
            trial, trial_tables = problem.retract(values, tables, system.solve(system.factor(lam)))
            return (trial, trial_tables), problem.error(trial, trial_tables)
        except Indeterminate:
            return None, math.inf

    tables = problem.tables(values)
    (values, _), it, system = damped_gauss_newton(
        (values, tables), problem.error(values, tables), lambda state: problem.linearize(*state), attempt,
        max_iterations, relative_tolerance)
    return values, it, system


def damped_gauss_newton(state: Any, error: float, linearize: Callable[[Any], Any],
                        attempt: Callable[[Any, Any, float], tuple[Any, float]], max_iterations: int = 20,
                        relative_tolerance: float = 1e-3) -> tuple[Any, int, Any]:
    """The Levenberg–Marquardt iteration of the module docstring, minimising from ``state`` (cost ``error``).

    Parameters
    ----------
    linearize : callable
        ``linearize(state) -> system``, the linearisation at ``state``.
    attempt : callable
        ``attempt(state, system, lam) -> (trial, trial_error)``: the step of ``(H + λ I) δ = g`` from
        ``state`` and its cost; ``(None, inf)`` when the system cannot be solved at this damping.

    Returns
    -------
    state, iterations, system
        The solution, the number of linearisations, and the last linearisation.
    """
    lam = 0.0
    it = 0
    system = None
    for it in range(1, max_iterations + 1):
        system = linearize(state)
        while True:
            trial, trial_error = attempt(state, system, lam)
            if trial_error <= error:
                break
            if trial is None:
                logger.debug("LM iteration %d: indeterminate system at lambda %.1e", it, lam)
            lam = 1e-4 if lam == 0 else lam * 10.0
            if lam > 1e8:
                return state, it, system
        decrease = error - trial_error
        logger.debug("LM iteration %d: cost %.6g -> %.6g (lambda %.1e)", it, error, trial_error, lam)
        state, error = trial, trial_error
        lam = 0.0 if lam <= 1e-3 else lam / 10.0
        if decrease <= relative_tolerance * max(error, 1e-12):
            break
    return state, it, system


def pose_marginals(system: System, pose_keys: list[int], dim: int = 3) -> np.ndarray:
    """Marginal covariances (N, 3, 3) of ``pose_keys`` from the linearisation ``system`` (GTSAM's Pose2
    tangent space), as :func:`fusion_vo.backends.graph.pose_marginals` computes them with GTSAM's
    ``Marginals``: with vague priors (σ = 100) on every variable when the system is not positive
    definite, NaN if it still is not. ``dim=1``: the variances (N, 1, 1) of scalar variables."""
    columns = system.lay.columns(np.asarray(pose_keys, dtype=np.int64))
    try:
        return system.marginal_blocks(system.factor(), columns, dim)
    except Indeterminate:
        logger.warning("gtsam: marginals of a poorly conditioned system; adding vague priors")
    try:
        return system.marginal_blocks(system.factor(1e-4), columns, dim)
    except Indeterminate:
        logger.warning("gtsam: no marginal covariances (the linearised system is indeterminate)")
        return np.full((len(pose_keys), dim, dim), np.nan)
