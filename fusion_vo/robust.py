"""Robust kernels: GTSAM's M-estimators (``gtsam.noiseModel.mEstimator``), the one definition of every robust reading.

A residual's whitened (Mahalanobis) distance ``d ≥ 0`` is down-weighted by a kernel of width ``k`` (on ``d``):

============  =======================================  ==========================================================
kernel        weight ``w(d)``                          loss ``ρ(d)``
============  =======================================  ==========================================================
``huber``     ``1`` for ``d ≤ k``, else ``k / d``      ``d² / 2`` for ``d ≤ k``, else ``k d - k² / 2``
``cauchy``    ``k² / (k² + d²)``                       ``k² / 2 · log(1 + d² / k²)``
``none``      ``1``                                    ``d² / 2``
============  =======================================  ==========================================================

These are the weight and loss of GTSAM's ``mEstimator.Huber`` and ``mEstimator.Cauchy`` (``w = ρ'(d) / d``; the
unit tests hold them equal to GTSAM's own). Every part of fusion-vo that weighs a reading robustly uses them: the
factor graph wraps its noise models in :func:`mestimator` and reweights its own linearisations with
:func:`robust_weight` (:mod:`fusion_vo.backends.factors`), the EKF divides a GPS fix's covariance by the weight
(:mod:`fusion_vo.sensors.gps`), and the height smoother and filter weigh range readings with Huber's
(:mod:`fusion_vo.geometry.height`).
"""

from __future__ import annotations

import numpy as np

#: the robust kernels (GTSAM's ``mEstimator`` of each name; ``none``, or None: the Gaussian alone)
ROBUST_KERNELS = ("huber", "cauchy", "none")


def robust_weight(distance, kernel: str | None, k: float):
    """Weight in ``(0, 1]`` of a residual at whitened distance ``d`` under the kernel ``kernel`` of width ``k``.

    Huber ``w(d) = 1`` for ``d ≤ k``, else ``k / d``; Cauchy ``w(d) = k² / (k² + d²)``; ``none`` (or None)
    ``w(d) = 1``: GTSAM's ``mEstimator.weight``. The weight multiplies the residual's information (a filter divides
    its covariance by it; the graph scales its whitened rows by ``√w``).

    Parameters
    ----------
    distance : float or array_like
        ``d`` (its absolute value is taken). A Python ``float`` (or ``numpy.float64``) takes a scalar path without
        array overhead and gives a float; anything else gives an array of its shape.
    kernel : {"huber", "cauchy", "none"} or None
    k : float
        The kernel's width on ``d``.

    Returns
    -------
    float or numpy.ndarray

    Raises
    ------
    ValueError
        An unknown kernel.
    """
    if isinstance(distance, float):  # one factor: without array overhead
        d = abs(distance)
        if kernel == "huber":
            return 1.0 if d <= k else k / d
        if kernel == "cauchy":
            return k * k / (k * k + d * d)
        if kernel is None or kernel == "none":
            return 1.0
        raise ValueError(f"unknown robust kernel {kernel!r}")
    d = np.abs(np.asarray(distance, dtype=np.float64))
    if kernel == "huber":
        return np.where(d <= k, 1.0, k / np.maximum(d, 1e-300))
    if kernel == "cauchy":
        return k * k / (k * k + d * d)
    if kernel is None or kernel == "none":
        return np.ones_like(d)
    raise ValueError(f"unknown robust kernel {kernel!r}")


def robust_loss(distance, kernel: str | None, k: float):
    """Loss ``ρ(d)`` of :func:`robust_weight`'s kernel at whitened distance ``d``: GTSAM's ``mEstimator.loss``.

    Huber ``ρ(d) = d² / 2`` for ``d ≤ k``, else ``k d - k² / 2``; Cauchy ``ρ(d) = k² / 2 · log(1 + d² / k²)``
    (evaluated with ``log1p``, exact for small ``d``, where GTSAM's ``log(1 + x)`` rounds); ``none`` (or None)
    ``ρ(d) = d² / 2``. A factor's error in the graph is ``ρ(‖W e‖)``.

    Parameters
    ----------
    distance : array_like
        ``d`` (its absolute value is taken).
    kernel : {"huber", "cauchy", "none"} or None
    k : float
        The kernel's width on ``d``.

    Returns
    -------
    numpy.ndarray
        Of ``distance``'s shape (0-d for a scalar).

    Raises
    ------
    ValueError
        An unknown kernel.
    """
    d = np.abs(np.asarray(distance, dtype=np.float64))
    if kernel == "huber":
        return np.where(d <= k, 0.5 * d * d, k * d - 0.5 * k * k)
    if kernel == "cauchy":
        return 0.5 * k * k * np.log1p(d * d / (k * k))
    if kernel is None or kernel == "none":
        return 0.5 * d * d
    raise ValueError(f"unknown robust kernel {kernel!r}")


def mestimator(kernel: str | None, k: float):
    """GTSAM's M-estimator ``kernel`` of width ``k``, for ``gtsam.noiseModel.Robust.Create(mestimator(...), base)``.

    Parameters
    ----------
    kernel : {"huber", "cauchy", "none"} or None
    k : float
        The kernel's width on the whitened distance.

    Returns
    -------
    gtsam.noiseModel.mEstimator.Huber, gtsam.noiseModel.mEstimator.Cauchy or None
        None for ``none`` (or None): the Gaussian alone.

    Raises
    ------
    ValueError
        An unknown kernel.
    """
    if kernel is None or kernel == "none":
        return None
    if kernel not in ROBUST_KERNELS:
        raise ValueError(f"unknown robust kernel {kernel!r}")
    import gtsam  # on first use: the sensors and the filter weigh without loading GTSAM

    if kernel == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(k)
    return gtsam.noiseModel.mEstimator.Cauchy.Create(k)
