"""Accuracy of estimated trajectories against ground truth: figures, plots and reports.

:func:`evaluate_run` evaluates a run folder (``metrics.json``, PNG figures, ``report.html``);
:func:`compare_runs` puts several runs side by side. The figures themselves are computed in
:mod:`fusion_vo.evaluation.metrics` with evo.
"""

from fusion_vo.evaluation.compare import compare_runs
from fusion_vo.evaluation.evaluate import evaluate_run, has_groundtruth

__all__ = ["compare_runs", "evaluate_run", "has_groundtruth"]
