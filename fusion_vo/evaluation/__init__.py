"""A run's report, its accuracy against ground truth or GPS fixes, and comparisons of runs.

:func:`evaluate_run` writes the report of a run folder (``report.html``, PNG figures and, where the recording
has ground truth or GPS fixes, ``metrics.json``), with or without ground truth; :func:`compare_runs` puts
several runs side by side. The accuracy figures against ground truth are computed in
:mod:`fusion_vo.evaluation.metrics` with evo.

evo is GPL-3.0 and lives in the ``eval`` extra (``pip install 'fusion-vo[eval]'``), so that the rest of
the library stays under permissive licences. Only the accuracy against ground truth needs it: the report,
the scores against GPS fixes and the comparison of runs without ground truth do not, and the report says in
one line when the accuracy was skipped for want of it. :func:`require_evo` turns its absence into a one-line
:class:`~fusion_vo.errors.InputError` where a caller needs it.
"""

from __future__ import annotations

import importlib
import importlib.util

from fusion_vo.errors import InputError

__all__ = ["compare_runs", "evaluate_run", "has_groundtruth", "require_evo"]

_LAZY = {"compare_runs": "fusion_vo.evaluation.compare", "evaluate_run": "fusion_vo.evaluation.run_report",
         "has_groundtruth": "fusion_vo.evaluation.run_report",
         # evo (GPL-3.0, the ``eval`` extra): what the report and the comparison reach it through
         "evaluate_trajectories": "fusion_vo.evaluation.evaluate",
         "groundtruth_accuracy": "fusion_vo.evaluation.evaluate", "to_planar": "fusion_vo.evaluation.metrics"}

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
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
