"""iSAM2 fed one node at a time: the sensor-model factors frozen at the prediction, their robust weights
evaluated again where the update puts the node, the oldest nodes marginalised.

The incremental solvers receive the sensor-model factors linearised at the prediction of the newest pose
(:func:`freeze_custom_factors`); iSAM2 linearises them once more at its updated estimate when a robust weight
there differs from the prediction's (:func:`update_reweighted`). iSAM2 marginalises the nodes more than
:data:`ONLINE_HORIZON` behind the newest (:class:`Retired`), so that its cost per update does not grow with the
drive. Used by the batch run's ``gtsam_online`` track (:func:`fusion_vo.backends.graph.run_graph`) and by
:class:`~fusion_vo.backends.streaming.StreamingFusion`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import gtsam
import numpy as np

from fusion_vo.backends.factors import ModelFactor, POSE_LETTERS, ValuesMaker
from fusion_vo.backends.graph_builder import F, GraphBuilder, NodeFactors, X

logger = logging.getLogger(__name__)


def freeze_custom_factors(factors: list, lookup, maker: ValuesMaker | None = None,
                          weights: list | None = None) -> list:
    """Replace each sensor-model factor (:class:`~fusion_vo.backends.factors.ModelFactor`, or a
    :class:`gtsam.CustomFactor`) by its linearisation at ``lookup(key)`` values.

    Used for the incremental solvers, which relinearise only GTSAM's own nonlinear factors: they receive
    the (robustly weighted) linearisation as a ``LinearContainerFactor``. The factors are relative
    constraints between close nodes, linearised at the prediction of the newest pose, where they are
    nearly linear (the gyro's and the standstill's are exactly linear in the headings); the robust
    weight is fixed at that prediction, so a visual increment that disagrees with the wheels and the
    gyro beyond the gate (:func:`kernel_width`) enters with a small weight. The batch solution
    relinearises them and re-evaluates their weights at every iteration.

    The prediction of the newest pose comes from the wheels, so a camera residual there carries the
    wheels' error too: the kernel is as wide as the gate (:func:`kernel_width`), and iSAM2 evaluates the
    weights again where its update puts the node (:func:`update_reweighted`;
    ``docs/decisions/0009-graph-keeps-correlations-and-reweights.md``). ``weights``: the robust weight each
    sensor-model factor gets at these values is appended to it (1 without a kernel).
    """
    out = []
    keys = {key for f in factors if isinstance(f, ModelFactor) for key in f.all_keys()}
    point = (maker or ValuesMaker()).make({key: lookup(key) for key in keys}) if keys else None
    for f in factors:
        if isinstance(f, ModelFactor):
            out.append(f.linearized(lookup, point, weights))
        elif isinstance(f, gtsam.CustomFactor):
            lin = gtsam.Values()
            insert_values(lin, {key: lookup(key) for key in f.keys()})
            out.append(gtsam.LinearContainerFactor(f.linearize(lin), lin))
        else:
            out.append(f)
    return out


#: iSAM2 linearises a node's sensor-model factors again at its updated estimate when the robust weight of one
#: of them there differs from the one it entered with by more than this (:func:`update_reweighted`)
REWEIGHT_TOLERANCE = 1e-3


def estimate_lookup(solver):
    """``lookup(key)``: the incremental ``solver``'s current estimate of a variable (Pose2 or float)."""

    def value(key: int):
        if chr(gtsam.Symbol(key).chr()) in POSE_LETTERS:
            return solver.calculateEstimatePose2(key)
        return solver.calculateEstimateDouble(key)

    return value


def update_reweighted(isam, graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, factors: list, weights: list,
                      maker: ValuesMaker | None = None, passes: int = 2) -> tuple[list[int], int]:
    """One iSAM2 update with a node's factors, the robust weights evaluated where the update puts the node.

    ``graph`` holds ``factors`` (the node's, in order) as :func:`freeze_custom_factors` linearised them at
    the prediction, and ``weights`` the robust weights it gave their sensor-model factors there. After the
    update, each robust factor's weight is evaluated at the new estimate; where one differs (by more than
    :data:`REWEIGHT_TOLERANCE`), all the node's sensor-model factors are linearised again at that estimate
    and replace the ones that went in (an iterated update, as an iterated EKF's, and the batch solution's
    reweighting at each iteration), at most ``passes`` times. Only a node with a weight below 1 at the
    prediction is checked: with every factor inside its kernel there, the update moves the node by a
    weighted mean of residuals inside their kernels.

    Why: the prediction of the newest pose comes from the wheels (translation) and the gyro (heading),
    and the camera's residual there carries their error, which is far larger than the camera's own noise
    (on the generated ``square`` drive the wheels' track is 600 times worse than the camera's). A kernel
    evaluated there down-weights good camera increments that the filter, gating with the prediction's
    uncertainty in the innovation covariance, takes at full weight; the update then pulls the pose most of
    the way to the camera, where the increment is well inside the kernel. An increment that is still
    beyond the kernel at the updated estimate (a wrong match, outvoted by the other sensors) keeps its
    small weight (``docs/decisions/0009-graph-keeps-correlations-and-reweights.md``). Returns the
    indices of the factors in iSAM2 (in the order of ``factors``) and the number of passes made.
    """
    index = list(isam.update(graph, values).getNewFactorsIndices())
    if passes <= 0 or min(weights, default=1.0) >= 1.0:
        return index, 0
    model = [i for i, f in enumerate(factors) if isinstance(f, ModelFactor)]
    robust = [j for j, i in enumerate(model) if factors[i].robust is not None]
    made = 0
    for _ in range(passes):
        estimate = estimate_lookup(isam)
        lookup = {key: estimate(key) for j in robust for key in factors[model[j]].all_keys()}.__getitem__
        if all(abs(factors[model[j]].weight(lookup) - weights[j]) <= REWEIGHT_TOLERANCE for j in robust):
            break
        lookup = estimate
        weights = []
        again = gtsam.NonlinearFactorGraph()
        for f in freeze_custom_factors([factors[i] for i in model], lookup, maker, weights):
            again.add(f)
        new = list(isam.update(again, gtsam.Values(), [index[i] for i in model]).getNewFactorsIndices())
        for i, k in zip(model, new):
            index[i] = k
        made += 1
    return index, made


def insert_values(values: gtsam.Values, items: dict) -> None:
    """Insert ``key -> Pose2 or float`` items into ``values``."""
    for key, v in items.items():
        if isinstance(v, gtsam.Pose2):
            values.insert(key, v)
        else:
            values.insert(key, float(v))




#: iSAM2 keeps this many nodes (camera frames) behind the newest; older ones are marginalised
ONLINE_HORIZON = 200


class Retired:
    """Marginalises the variables of iSAM2's oldest nodes, keeping its Bayes tree to the last
    :data:`ONLINE_HORIZON` to :data:`2 ONLINE_HORIZON <ONLINE_HORIZON>` nodes, and remembers their estimates.

    Why: the graph is a chain, so iSAM2's Bayes tree is a path as long as the drive, and GTSAM 4.3
    destroys each update's temporary Bayes tree by visiting every clique below it (the breadth-first
    ``BayesTree`` destructor that avoids deep recursion), which is the whole history, so the cost per
    update would grow with the drive (``docs/decisions/0008-isam2-marginalises-old-nodes.md``). No future
    factor touches a variable that old (a node's factors reach its previous node and its segment's
    variables), and the marginal keeps the
    information of the old factors on the variables that remain, linearised where they are. That is
    exact for the newest pose unless iSAM2 would have relinearised the old variables later (a standstill
    that reveals the gyro bias late in the drive, for instance): the nodes it has marginalised keep the
    linearisation they left with.
    The old nodes' estimates are the ones at the time they leave (the batch solution starts from them).
    """

    def __init__(self, builder: GraphBuilder, horizon: int = ONLINE_HORIZON):
        self.builder = builder
        self.horizon = horizon
        self.first = 0  # nodes before it are marginalised
        self.values: dict = {}

    def step(self, isam, n: int) -> None:
        """Marginalise whole segments of nodes more than ``horizon`` behind node ``n`` (every ``horizon`` nodes)."""
        if n - self.first < 2 * self.horizon:
            return
        b = self.builder
        seg = np.asarray(b.segment)
        end = int(np.searchsorted(seg, seg[n - self.horizon]))  # the first node of that node's segment
        if end <= self.first:
            return
        keys = [X(b.offset + k) for k in range(self.first, end)]
        keys += [F(b.offset + k) for k in range(self.first, end) if b.offset + k in b.frames]
        seg_keys = []
        for c in np.unique(seg[self.first:end]):
            seg_keys += b.segment_keys(int(np.searchsorted(seg, c)))
        leaves = gtsam.KeyList()
        for key in keys + seg_keys:
            leaves.push_back(key)
        try:
            estimates = {key: isam.calculateEstimatePose2(key) for key in keys}
            estimates.update({key: isam.calculateEstimateDouble(key) for key in seg_keys})
            self._make_leaves(isam, set(keys + seg_keys))
            isam.marginalizeLeaves(leaves)
        except RuntimeError as exc:  # not the leaves of the tree: keep them for now
            logger.debug("iSAM2: nodes %d-%d not marginalised (%s)", self.first, end - 1, exc)
            return
        self.values.update(estimates)
        self.first = end

    @staticmethod
    def _make_leaves(isam, old: set) -> None:
        """Re-eliminate the Bayes tree with the ``old`` variables first, so that they are its leaves.

        ``marginalizeLeaves`` needs them in leaf cliques and checks that only in part: on a 120 s
        generated drive of wheels and gyro alone (no camera, no heading reference) it failed half-way
        through the seventh marginalisation with "variables ... not unused" and left a tree that
        crashed the process on the next update. GTSAM's IncrementalFixedLagSmoother orders the
        variables it marginalises first for the same reason. Every variable is re-eliminated (at most
        two horizons of nodes, once per horizon) at its current linearisation point: none is
        relinearised by it. The online track is unchanged to 1e-9 (``tests/backends/test_chain.py``).
        """
        groups = gtsam.KeyGroupMap()
        reelim = gtsam.KeyList()
        for key in isam.getLinearizationPoint().keys():
            groups.insert2(key, 0 if key in old else 1)
            reelim.push_back(key)
        params = gtsam.ISAM2UpdateParams()
        params.constrainedKeys = groups
        params.extraReelimKeys = reelim
        params.noRelinKeys = reelim
        isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), params)

    def complete(self, values: gtsam.Values) -> gtsam.Values:
        """``values`` with the marginalised variables' estimates added."""
        if self.values:
            values = gtsam.Values(values)
            insert_values(values, {k: v for k, v in self.values.items() if not values.exists(k)})
        return values


def current_value_lookup(new: dict, solver, prev_pose: gtsam.Pose2, prev: int):
    """Current value of a key: new variables from ``new``, others from the incremental ``solver``."""

    estimate = estimate_lookup(solver)

    def value(key: int):
        if key in new:
            return new[key]
        if key == X(prev):
            return prev_pose
        return estimate(key)

    return value


@dataclass
class Frozen:
    """A node's factors as they go into iSAM2: ``graph`` holds ``factors`` (in order) linearised at the prediction,
    ``weights`` the robust weight each sensor-model factor got there (:func:`freeze_custom_factors`)."""

    graph: gtsam.NonlinearFactorGraph
    factors: list
    weights: list


class Isam2Driver:
    """iSAM2 fed one node at a time: the one driver of the batch run's ``gtsam_online`` track
    (:func:`fusion_vo.backends.graph.run_graph`) and of the streaming engine
    (:class:`~fusion_vo.backends.online_graph.OnlineGraph`).

    A node's factors (:class:`~fusion_vo.backends.graph_builder.NodeFactors`, ``nf``) go in in two calls:

    1. :meth:`freeze` linearises its sensor-model factors at the prediction: its new variables at their
       guesses ``nf.values``, the previous node's pose at :attr:`prev_pose`, every other variable at iSAM2's
       estimate (:func:`current_value_lookup`, :func:`freeze_custom_factors`);
    2. :meth:`add` updates iSAM2 with them and the new variables, and evaluates the robust weights again where
       the update put the node, at most ``passes`` times (:func:`update_reweighted`).

    :meth:`advance` then keeps the node's pose as :attr:`prev_pose` and the running bias and calibration
    estimates (:func:`track_estimate`) that the next node's guesses start from.
    """

    def __init__(self, prev_pose: gtsam.Pose2, passes: int, maker: ValuesMaker | None = None):
        self.isam = gtsam.ISAM2(isam_params())
        self.passes = passes
        self.maker = maker if maker is not None else ValuesMaker()
        self.prev_pose = prev_pose  # iSAM2's estimate of the newest node
        self.builder: GraphBuilder | None = None  # the builder of the newest node (its states' keys)
        self.estimate: dict = {}  # running bias / calibration estimates (guesses of the next node)

    def freeze(self, nf: NodeFactors, prev: int, factors: list | None = None) -> Frozen:
        """``factors`` (default ``nf.factors``) linearised at the prediction of the node after the pose index
        ``prev``."""
        factors = nf.factors if factors is None else factors
        lookup = current_value_lookup(nf.values, self.isam, self.prev_pose, prev)
        weights: list = []
        graph = gtsam.NonlinearFactorGraph()
        for f in freeze_custom_factors(factors, lookup, self.maker, weights):
            graph.add(f)
        return Frozen(graph, list(factors), weights)

    def add(self, nf: NodeFactors, frozen: Frozen, more: Frozen | None = None) -> tuple[list[int], int]:
        """One iSAM2 update with the node's ``frozen`` factors (and ``more`` after them) and its new variables:
        the indices of the factors in iSAM2 and the passes made for the robust weights (:func:`update_reweighted`)."""
        if more is not None:
            graph = gtsam.NonlinearFactorGraph()
            for g in (frozen.graph, more.graph):
                for i in range(g.size()):
                    graph.add(g.at(i))
            frozen = Frozen(graph, frozen.factors + more.factors, frozen.weights + more.weights)
        return update_reweighted(self.isam, frozen.graph, self.maker.make(nf.values), frozen.factors, frozen.weights,
                                 self.maker, self.passes)

    def advance(self, builder: GraphBuilder, n: int, nf: NodeFactors, pose: gtsam.Pose2) -> None:
        """Node ``n`` of ``builder`` is in, at ``pose``: the next node's guesses start from it."""
        self.prev_pose = pose
        self.builder = builder
        track_estimate(self.estimate, self.isam, builder, n, nf)


def track_estimate(estimate: dict, isam, builder: GraphBuilder, n: int, nf: NodeFactors) -> None:
    """Running estimates of the bias and calibration for initial guesses of the next node."""
    segment = int(builder.segment[n])
    for st in builder.variables:
        estimate[st.name] = isam.calculateEstimateDouble(builder.state_key(st.name, segment))
    estimate["last_increment"] = nf.guess if nf.guess is not None else np.zeros(3)


def isam_params() -> gtsam.ISAM2Params:
    """iSAM2 settings that keep the cost per node nearly constant.

    The gyro bias and the calibration couple every heading to the whole history: a small change of the
    bias estimate moves old headings by ``δb · age``. Updating and relinearising all of them for such
    changes would make each update O(N). Relinearisation is therefore checked only along the
    re-eliminated part of the tree, every 10 updates, for changes above 0.1, and back-substitution
    stops where changes fall under 1.0 (the wildfire threshold). The newest pose — the online estimate —
    sits at the root and is always solved exactly; the batch solution refines the history. The
    sensor-model factors enter linearised (:func:`freeze_custom_factors`), so relinearisation touches only
    GTSAM's own factors, and tighter settings do not change the online estimate measurably.

    The factorisation is QR. Cholesky squares the condition number, and systems that are well posed
    but badly conditioned are then reported as indeterminate: with GPS, a loose first-heading prior (from
    the fixes) beside near-exact wheel heading changes at low speed; a gyro-bias variable beside very
    precise camera increments (the generated barrel-lens recording ``real_barrel_fine``,
    ``tests/data/barrel_fine_fusion/``; ``docs/decisions/0031-incremental-solvers-factorise-with-qr.md``).
    """
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(0.1)
    params.relinearizeSkip = 10
    params.enablePartialRelinearizationCheck = True
    params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(1.0))
    params.setFactorization("QR")
    return params
