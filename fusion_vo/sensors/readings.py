"""What a sensor hands to the backends: readings of its measurement model, placed on the node grid.

A sensor turns its samples into :class:`Readings` (its ``readings`` step in
:mod:`fusion_vo.sensors.registry`): one measurement model (:mod:`fusion_vo.sensors.model`), ``M`` readings
``z`` with their noise covariances, and where on the node grid ``T_0 < T_1 < … < T_K`` each one applies:

* an *interval* reading, ``i0 < i1``, measures the model's ``motion`` argument: the body motion from node
  ``i0`` to node ``i1``, the relative pose ``δ = X_{i0}⁻¹ X_{i1} = (d_x, d_y, d_ψ)``;
* a *node* reading, ``i0 == i1``, measures the pose at that node (the ``heading`` or ``pose`` arguments)
  or states alone.

Every other argument of the model is a state of that name: a built-in one
(:data:`~fusion_vo.sensors.model.ARGUMENT_SIZES`) or one a sensor declares
(:class:`~fusion_vo.sensors.registry.State`); ``fixed`` holds an argument at a value instead, and
``params`` are the model's parameters (per reading or shared). Whether a state is estimated is the
backend's decision: a state it does not estimate enters at its initial value.

The backends read nothing else of a sensor. Each turns every reading into its own form with one adapter:
the EKF (:mod:`fusion_vo.backends.ekf_adapter`) evaluates interval readings per unit time on its twist
state, ``z / Δt`` with ``R / Δt²`` (a pose increment as its logarithm, the exact twist of the interval);
the factor graph (:mod:`fusion_vo.backends.graph_adapter`) makes each reading a factor between the
variables of its arguments.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fusion_vo.sensors.model import MeasurementModel

#: the order the built-in sensors' readings keep among themselves in both backends (a new sensor's default is
#: :data:`DEFAULT_ORDER`): the EKF stacks one interval's readings in this order, the graph adds its factors so
ORDER = {"camera": 10.0, "wheel": 20.0, "gyro": 30.0, "standstill": 40.0, "ahrs": 50.0, "range": 60.0, "gps": 70.0}
DEFAULT_ORDER = 100.0


@dataclass(frozen=True)
class Absolute:
    """How the backends apply absolute readings of the pose (a GPS fix: :mod:`fusion_vo.backends.fixes`).

    Each is applied on its own after its node's other readings, gated against the prediction of its node (the
    innovation's squared Mahalanobis distance against ``noise.gate_chi2``) and down-weighted by ``noise.kernel``
    of width ``noise.kernel_width`` on that distance; its covariance is floored at ``noise.min_sigma``; after
    ``reacquire`` seconds of rejections one is applied anyway (the estimate re-acquires the readings).
    ``skipped`` counts the readings left out on reading, for the notes.
    """

    noise: Any
    reacquire: float
    skipped: dict = field(default_factory=dict)


@dataclass
class Readings:
    """``M`` readings of one measurement model on the node grid (module docstring).

    Attributes
    ----------
    sensor : str
        The name its use is counted under (``FusionResult.counts``).
    model : MeasurementModel
    i0, i1 : ndarray (M,) of int
        The nodes each reading relates: ``i0 < i1`` an interval (the ``motion`` argument), ``i0 == i1`` a node.
    z : ndarray (M, dim)
        The readings (all of the model's rows; ``rows`` selects those that measure).
    cov : ndarray (M, m, m)
        Their noise covariances, over the rows that measure (``m = len(rows)``, else the model's ``dim``).
    fixed : dict
        Model arguments held at a value (name -> float).
    params : dict
        Model parameters (name -> a number, or an array (M,) with one per reading).
    rows : tuple of int or None
        The model's rows these readings measure (None: all).
    robust : bool
        Whether the backends bound their influence (the EKF's gate and the graph's robust kernel); a reading whose
        inputs are gated upstream (the gyro's spikes) is not.
    frame_cov : ndarray (M, 3, 3) or None
        The part of each interval reading's covariance that is the error of its two end frames, ``n = e_b - e_a +
        w`` with ``e ~ N(0, frame_cov)`` (a camera that measures each frame against the previous one,
        :mod:`fusion_vo.sensors.visual`); None: independent readings.
    order : float
        Place among the readings of the other sensors (:data:`ORDER`).
    absolute : Absolute or None
        Node readings of the ``pose`` that the backends apply on their own with this policy (:class:`Absolute`);
        None: readings like any other.
    dropped : tuple of str
        Components of these motion readings that the consistency monitor dropped
        (:mod:`fusion_vo.backends.monitor`): ``"speed"`` (the translation rows) and ``"yaw"`` (the heading change).
        The backends leave them out: the EKF with a vague variance in its twist coordinates, the graph with a free
        translation or without the heading row (and the sideways chord its wrong heading made).
    """

    sensor: str
    model: MeasurementModel
    i0: np.ndarray
    i1: np.ndarray
    z: np.ndarray
    cov: np.ndarray
    fixed: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)
    rows: tuple | None = None
    robust: bool = True
    frame_cov: np.ndarray | None = None
    order: float = DEFAULT_ORDER
    dropped: tuple = ()
    absolute: Absolute | None = None

    def __post_init__(self) -> None:
        self.i0 = np.asarray(self.i0, dtype=np.int64).reshape(-1)
        self.i1 = np.asarray(self.i1, dtype=np.int64).reshape(-1)
        m = len(self.i0)
        self.z = np.asarray(self.z, dtype=np.float64).reshape(m, self.model.dim)
        k = self.model.dim if self.rows is None else len(self.rows)
        cov = np.asarray(self.cov, dtype=np.float64)
        if k == 1 and cov.ndim == 1 and len(cov) == m:  # one variance per reading
            cov = cov.reshape(m, 1, 1)
        self.cov = np.broadcast_to(cov, (m, k, k))

    def __len__(self) -> int:
        return len(self.i0)

    @property
    def at_nodes(self) -> bool:
        """Node readings (every ``i0 == i1``)."""
        return bool(np.all(self.i0 == self.i1))

    def param(self, name: str, m: int):
        """Parameter ``name`` of reading ``m``."""
        value = self.params[name]
        return value[m] if np.ndim(value) else value

    def take(self, keep: np.ndarray) -> "Readings":
        """The readings where ``keep`` (a boolean mask or indices) selects them."""
        params = {k: (v[keep] if np.ndim(v) else v) for k, v in self.params.items()}
        return Readings(self.sensor, self.model, self.i0[keep], self.i1[keep], self.z[keep], self.cov[keep],
                        dict(self.fixed), params, self.rows, self.robust,
                        None if self.frame_cov is None else self.frame_cov[keep], self.order, self.dropped,
                        self.absolute)
