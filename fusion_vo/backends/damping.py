"""The Levenberg–Marquardt iteration shared by the factor graph's solvers.

One step solves the damped Gauss–Newton system ``(JᵀJ + λ I) δ = -Jᵀr`` at the current linearisation
and keeps ``x ⊕ δ`` if it lowers the cost; otherwise λ grows tenfold (from 1e-4) and the step is tried
again, and above 1e8 the iteration stops where it is. After a kept step λ shrinks tenfold (to 0 below
1e-3, a plain Gauss–Newton step). The iteration ends when a kept step lowers the cost by less than
``relative_tolerance`` of it, or after ``max_iterations`` linearisations.

The solvers differ only in how they linearise and solve: GTSAM's elimination
(:func:`fusion_vo.backends.graph.levenberg_marquardt`) or the block-tridiagonal sweep of a chain
(:func:`fusion_vo.backends.chain.levenberg_marquardt`).
"""

from __future__ import annotations

import logging
from typing import Any, Callable

logger = logging.getLogger(__name__)


def damped_gauss_newton(state: Any, error: float, linearize: Callable[[Any], Any],
                        attempt: Callable[[Any, Any, float], tuple[Any, float]], max_iterations: int = 20,
                        relative_tolerance: float = 1e-3) -> tuple[Any, int, Any]:
    """Minimise from ``state`` (cost ``error``).

    Parameters
    ----------
    linearize : callable
        ``linearize(state) -> system``, the linearisation at ``state``.
    attempt : callable
        ``attempt(state, system, lam) -> (trial, trial_error)``: the damped step from ``state`` and its
        cost; ``(None, inf)`` when the system cannot be solved at this damping.

    Returns
    -------
    state, iterations, system
        The solution, the number of linearisations, and the last linearisation (for marginals).
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
