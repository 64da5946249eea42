"""Accuracy of a run's trajectories against the recording's ground truth (evo: the ``eval`` extra).

:func:`groundtruth_accuracy` computes every trajectory's figures (:mod:`.metrics`) and draws the figures
against ground truth; :mod:`fusion_vo.evaluation.run_report` puts them into the run's report, which it writes
with or without them.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from evo.core.trajectory import PoseTrajectory3D

from fusion_vo.errors import InputError
from fusion_vo.evaluation import plots
from fusion_vo.evaluation.io import GROUNDTRUTH_CSV, FrameVelocities, read_groundtruth, read_tum
from fusion_vo.evaluation.metrics import (TrajectoryErrors, Velocities, detect_legs, evaluate_trajectory,
                                          reference_velocities, to_planar)

logger = logging.getLogger(__name__)

#: figure files written into the run folder, with their captions in the report
FIGURES = {
    "trajectories.png": "Trajectories on the floor, anchored at the ground-truth start (circle: start, "
                        "triangle: end)",
    "velocities.png": "Forward, lateral and yaw velocity against ground truth",
    "heading.png": "Heading over time against ground truth",
    "error_distance.png": "Position error against distance travelled",
}


def evaluate_trajectories(reference: PoseTrajectory3D, files: dict[str, Path],
                          reference_path: Path | None = None) -> dict[str, TrajectoryErrors]:
    """Read and evaluate TUM files against a reference; errors name the file at fault.

    With ``reference_path`` (the ground truth's file), a trajectory that cannot be paired with the
    reference is blamed on that file, which exists, and not on the trajectory (a run's own file, which a
    run that fails here never keeps): a ground truth with fewer than two poses within the trajectory's time
    span says so; otherwise the clocks are suspected.
    """
    legs = detect_legs(reference)
    logger.info("ground truth has %d straight legs", len(legs))
    results = {}
    for name, path in files.items():
        estimate = read_tum(path, name)
        try:
            results[name] = evaluate_trajectory(reference, estimate, legs)
        except InputError as exc:
            if reference_path is None:
                raise InputError(exc.message, path) from None
            t0, t1 = float(estimate.timestamps[0]), float(estimate.timestamps[-1])
            inside = int(np.count_nonzero((reference.timestamps >= t0) & (reference.timestamps <= t1)))
            if inside < 2:
                raise InputError(f"only {inside} of its {reference.num_poses} poses lie within the time span of "
                                 f"trajectory '{name}' ({t0:.3f} to {t1:.3f} s): the evaluation needs two",
                                 reference_path) from None
            raise InputError(f"trajectory '{name}': {exc.message}", reference_path) from None
        span = float(estimate.timestamps[-1] - estimate.timestamps[0])
        covered = results[name].figures["duration_s"]
        if span > 0 and covered < 0.9 * span:  # another clock, or a ground truth of part of the drive
            logger.warning("%s: only %.3g s of its %.3g s lie within the ground truth's time span%s; its figures "
                           "cover that part only", path if reference_path is None else path.name, covered, span,
                           f" ({reference_path})" if reference_path is not None else "")
    return results


def _measured_velocities(frames: FrameVelocities) -> Velocities:
    ok = frames.ok
    return Velocities(frames.t[ok], frames.vx[ok], frames.vy[ok], frames.yaw_rate[ok])


def groundtruth_accuracy(sequence: Path, files: dict[str, Path], out: Path,
                         frames: FrameVelocities | None = None) -> tuple[dict, dict[str, Path]]:
    """Every trajectory against the recording's ground truth: figures and PNGs written into ``out``.

    Parameters
    ----------
    sequence : Path
        Recording with ``state_groundtruth_estimate0/data.csv``.
    files : dict
        Trajectory name -> TUM file.
    out : Path
        Folder for the figures.
    frames : FrameVelocities, optional
        The visual frontend's per-frame velocities (``velocities.csv``), drawn against ground truth.

    Returns
    -------
    metrics : dict
        Trajectory name -> figures (as in ``metrics.json``).
    images : dict
        Caption -> PNG path.
    """
    reference = read_groundtruth(sequence / GROUNDTRUTH_CSV)
    results = evaluate_trajectories(reference, files, sequence / GROUNDTRUTH_CSV)
    metrics = {name: result.figures for name, result in results.items()}
    ref_planar = to_planar(reference)
    anchored = {name: r.anchored for name, r in results.items()}
    images = {}
    images["trajectories.png"] = plots.plot_trajectories(ref_planar, anchored, out / "trajectories.png",
                                                         title=f"Trajectories against ground truth: {sequence.name}")
    velocities = {name: r.velocities for name, r in results.items()}
    if frames is not None and np.any(frames.ok):
        velocities["vo"] = _measured_velocities(frames)
        stamps = frames.t
    else:
        stamps = next(iter(results.values())).velocities.t
    t0 = float(reference.timestamps[0])
    images["velocities.png"] = plots.plot_velocities(reference_velocities(ref_planar, stamps), velocities,
                                                     out / "velocities.png", t0)
    images["heading.png"] = plots.plot_heading(ref_planar, anchored, out / "heading.png", t0)
    images["error_distance.png"] = plots.plot_error_vs_distance(results, out / "error_distance.png")
    return metrics, {FIGURES[path.name]: path for path in images.values()}
