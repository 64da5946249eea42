"""Compare several runs: one table (rows run/trajectory) and one overlay figure.

Runs are labelled by their folder names (with the parent folder added where two names clash). Every
trajectory is evaluated against the ground truth of its own run's recording; the overlay shows the
estimates anchored at the ground-truth start, and the ground truth itself when all runs share one
recording.
"""

from __future__ import annotations

import logging
from pathlib import Path

from evo.core.trajectory import PoseTrajectory3D

from fusion_vo.evaluation.evaluate import evaluate_trajectories, resolve_sequence
from fusion_vo.errors import InputError
from fusion_vo.outputs import StagedFiles, check_folder_target, check_outside
from fusion_vo.evaluation.io import (GROUNDTRUTH_CSV, find_trajectories, read_groundtruth, read_run_config,
                                     write_metrics)
from fusion_vo.evaluation.metrics import to_planar
from fusion_vo.evaluation.plots import plot_compare

logger = logging.getLogger(__name__)


def run_labels(run_dirs: list[Path]) -> list[str]:
    """Folder names, with as many parent folders as it takes to tell apart names that occur more than once.

    Raises
    ------
    InputError
        If a run folder is given twice (its rows would be one run's, shown as two).
    """
    resolved = [Path(d).resolve() for d in run_dirs]
    for i, r in enumerate(resolved):
        if r in resolved[:i]:
            raise InputError(f"run folder given twice (as {run_dirs[resolved.index(r)]} and {run_dirs[i]})",
                             run_dirs[i])
    depth = [1] * len(resolved)

    def label(i: int) -> str:
        return "/".join(resolved[i].parts[-depth[i]:])

    while True:
        labels = [label(i) for i in range(len(resolved))]
        clash = [i for i, lab in enumerate(labels) if labels.count(lab) > 1]
        if not clash:
            return labels
        for i in clash:
            depth[i] += 1


def compare_runs(run_dirs: list[str | Path], out_dir: str | Path,
                 sequence_dir: str | Path | None = None) -> dict[str, dict[str, dict]]:
    """Evaluate several runs and write ``compare.json``, ``compare.csv`` and ``compare.png`` into ``out_dir``.

    Parameters
    ----------
    run_dirs : list of str or Path
        Run folders written by ``fusion-vo run``.
    out_dir : str or Path
        Folder for the outputs (created if missing); neither a run folder compared or inside one, nor
        inside a recording.
    sequence_dir : str or Path, optional
        Recording with the ground truth for all runs; by default each run's ``run.yaml`` names its own.

    Returns
    -------
    dict
        Run label -> trajectory name -> figures.

    Raises
    ------
    InputError
        As :func:`fusion_vo.evaluation.evaluate.evaluate_run`, for the first run at fault.
    """
    run_dirs = [Path(d) for d in run_dirs]
    out_dir = check_folder_target(out_dir)  # before the evaluation's work
    # never into a run folder compared: a later 'fusion-vo run' into it replaces the folder, these files with it
    check_outside(out_dir, run_dirs)
    table: dict[str, dict[str, dict]] = {}
    overlay: dict[str, dict[str, PoseTrajectory3D]] = {}
    sequences = []
    reference = None
    for label, run_dir in zip(run_labels(run_dirs), run_dirs):
        files = find_trajectories(run_dir)
        sequence = resolve_sequence(run_dir, read_run_config(run_dir), sequence_dir)
        gt = read_groundtruth(sequence / GROUNDTRUTH_CSV)
        results = evaluate_trajectories(gt, files, sequence / GROUNDTRUTH_CSV)
        table[label] = {name: r.figures for name, r in results.items()}
        overlay[label] = {name: r.anchored for name, r in results.items()}
        sequences.append(sequence.resolve())
        reference = reference or to_planar(gt)
    check_outside(out_dir, sorted(set(sequences)))
    shared = len(set(sequences)) == 1
    # the three files together or none of them (an error or Ctrl-C keeps an earlier comparison whole)
    with StagedFiles(out_dir, what="output folder", create=True) as staged:
        write_metrics(staged.path / "compare.json", table)
        write_compare_csv(staged.path / "compare.csv", table)
        plot_compare(reference if shared else None, overlay, staged.path / "compare.png")
        staged.commit()
    logger.info("compared %d runs into %s", len(run_dirs), out_dir)
    return table


def write_compare_csv(path: str | Path, table: dict[str, dict[str, dict]]) -> Path:
    """Write the comparison as CSV: one row per run and trajectory, every scalar figure at full precision.

    Columns are ``run,trajectory`` and then the figures' names in the order they first appear; a figure a
    trajectory lacks (or that is not finite) is an empty field.
    """
    import csv
    import io
    import math

    from fusion_vo.outputs import write_atomic

    columns: list[str] = []
    for runs in table.values():
        for figures in runs.values():
            for key, value in figures.items():
                if isinstance(value, (int, float)) and not isinstance(value, bool) and key not in columns:
                    columns.append(key)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["run", "trajectory", *columns])
    for label, runs in table.items():
        for name, figures in runs.items():
            row = []
            for key in columns:
                value = figures.get(key)
                ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                row.append((str(value) if isinstance(value, int) else repr(float(value))) if ok else "")
            writer.writerow([label, name, *row])
    return write_atomic(path, buf.getvalue())
