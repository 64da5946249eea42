"""Accuracy of estimated trajectories against ground truth: figures, plots and reports.

:func:`evaluate_run` evaluates a run folder (``metrics.json``, PNG figures, ``report.html``);
:func:`compare_runs` puts several runs side by side. The figures themselves are computed in
:mod:`fusion_vo.evaluation.metrics` with evo.

evo is GPL-3.0 and lives in the ``eval`` extra (``pip install 'fusion-vo[eval]'``), so that the rest of
the library stays under permissive licences. This package imports it only when a function that needs it
is used; :func:`require_evo` turns its absence into a one-line :class:`~fusion_vo.errors.InputError`.
"""

from __future__ import annotations

import importlib
import importlib.util

from fusion_vo.errors import InputError

__all__ = ["compare_runs", "evaluate_run", "has_groundtruth", "require_evo"]

_LAZY = {"compare_runs": "fusion_vo.evaluation.compare", "evaluate_run": "fusion_vo.evaluation.evaluate",
         "has_groundtruth": "fusion_vo.evaluation.evaluate"}

EVO_MISSING = ("evaluation against ground truth needs evo (GPL-3.0), which is not installed: "
               "pip install 'fusion-vo[eval]'")


def evo_available() -> bool:
    """Whether evo can be imported."""
    try:
        return importlib.util.find_spec("evo") is not None
    except (ImportError, ValueError):
        return False


def require_evo() -> None:
    """Raise :class:`InputError` with the install command when evo is not installed."""
    if not evo_available():
        raise InputError(EVO_MISSING)


def __getattr__(name: str):
    if name in _LAZY:
        require_evo()
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
