"""Evaluate a run folder: metrics.json, figures and report.html next to the trajectories.

A run folder holds TUM trajectories (``vo.tum``, ``wheel.tum``, ``ekf.tum``, ...), optionally
``velocities.csv`` from the visual frontend and ``run.yaml`` with the configuration, whose ``sequence``
names the recording. The recording's ground truth is the reference for every figure; a recording
without ground truth but with GPS fixes is scored against the fixes instead (:mod:`.gps`).
"""

from __future__ import annotations

import json
import logging
from collections import Counter
from pathlib import Path

import numpy as np
from evo.core.trajectory import PoseTrajectory3D

from fusion_vo.errors import InputError, check_folder
from fusion_vo.evaluation import plots
from fusion_vo.evaluation.io import (GROUNDTRUTH_CSV, FrameVelocities, find_trajectories, read_groundtruth,
                                     read_run_config, read_tum, read_velocities, write_metrics)
from fusion_vo.evaluation.metrics import (TrajectoryErrors, Velocities, detect_legs, evaluate_trajectory,
                                          reference_velocities, to_planar)
from fusion_vo.evaluation.report import write_report

logger = logging.getLogger(__name__)

#: figure files written into the run folder, with their captions in the report
FIGURES = {
    "trajectories.png": "Trajectories on the floor, anchored at the ground-truth start (circle: start, "
                        "triangle: end)",
    "velocities.png": "Forward, lateral and yaw velocity against ground truth",
    "heading.png": "Heading over time",
    "error_distance.png": "Position error against distance travelled",
    "frontend.png": "Inliers per frame and frames the visual frontend could not use",
}

#: every file an evaluation writes into a run folder
OUTPUTS = ("metrics.json", "report.html", "gps.png", *FIGURES)


def read_run_summary(run_dir: Path) -> dict:
    """``summary.json`` of a run folder (notes, counts), or an empty mapping when absent or unreadable."""
    path = run_dir / "summary.json"
    if not path.is_file():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        logger.warning("%s: not readable (%s); the report shows no notes or counts", path, exc)
        return {}
    return data if isinstance(data, dict) else {}


def has_groundtruth(sequence_dir: str | Path) -> bool:
    """Whether a recording folder contains ground truth."""
    return (Path(sequence_dir) / GROUNDTRUTH_CSV).is_file()


def resolve_sequence(run_dir: Path, config: dict, sequence_dir: str | Path | None) -> Path:
    """The recording folder: ``sequence_dir`` if given, else ``run.yaml``'s ``sequence``.

    A relative ``sequence`` in ``run.yaml`` is tried relative to the working directory, then to the run
    folder.

    Raises
    ------
    InputError
        If no recording is named or the named folder has neither ground truth nor GPS fixes.
    """
    if sequence_dir is None:
        named = config.get("sequence")
        if not named:
            raise InputError("no recording to take ground truth from: run.yaml names no 'sequence'; "
                             "pass --gt SEQ", run_dir / "run.yaml")
        sequence = Path(str(named)).expanduser()
        if not sequence.is_absolute() and not sequence.exists() and (run_dir / sequence).exists():
            sequence = run_dir / sequence
        try:
            check_folder(sequence, "recording folder")
        except InputError as exc:  # blame run.yaml's key: "RUN/run.yaml: sequence: recording folder X not found"
            what = (f"recording folder {sequence} not found" if exc.message == "recording folder not found"
                    else f"{sequence}: {exc.message}")
            raise InputError(f"sequence: {what}", run_dir / "run.yaml") from None
    else:
        sequence = Path(sequence_dir)
    check_folder(sequence, "recording folder")
    if not has_groundtruth(sequence) and not (sequence / "gps0" / "data.csv").is_file():
        raise InputError("recording has no ground truth (and no GPS fixes to score against)",
                         sequence / GROUNDTRUTH_CSV)
    return sequence


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


def frontend_summary(frames: FrameVelocities) -> dict:
    """Frame counts per status and the mean inlier count of the frames with a motion estimate."""
    counts = Counter(frames.status)
    summary = {"frames": len(frames.status)}
    summary.update({f"frames {status}": n for status, n in sorted(counts.items())})
    ok = frames.ok
    if np.any(ok):
        summary["mean inliers (ok frames)"] = round(float(np.mean(frames.inliers[ok])), 1)
    return summary


def _measured_velocities(frames: FrameVelocities) -> Velocities:
    ok = frames.ok
    return Velocities(frames.t[ok], frames.vx[ok], frames.vy[ok], frames.yaw_rate[ok])


def evaluate_run(run_dir: str | Path, sequence_dir: str | Path | None = None, out_dir: str | Path | None = None) -> dict:
    """Evaluate every trajectory of a run folder and write metrics, figures and the report into it.

    Parameters
    ----------
    run_dir : str or Path
        Folder written by ``fusion-vo run``.
    sequence_dir : str or Path, optional
        Recording with the ground truth; by default the ``sequence`` named in ``run.yaml``.
    out_dir : str or Path, optional
        Where to write ``metrics.json``, the figures and ``report.html`` (default ``run_dir``;
        ``fusion-vo evaluate`` writes them into a staging folder and moves them in when all succeeded).

    Returns
    -------
    dict
        Trajectory name -> figures, as written to ``metrics.json``.

    Raises
    ------
    InputError
        If the folder or its trajectories are missing or malformed, or there is neither ground truth nor
        GPS.
    """
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run_dir
    files = find_trajectories(run_dir)
    config = read_run_config(run_dir)
    sequence = resolve_sequence(run_dir, config, sequence_dir)
    if not has_groundtruth(sequence):
        return evaluate_run_against_gps(run_dir, sequence, files, config, out)
    reference = read_groundtruth(sequence / GROUNDTRUTH_CSV)
    results = evaluate_trajectories(reference, files, sequence / GROUNDTRUTH_CSV)
    metrics = {name: result.figures for name, result in results.items()}
    write_metrics(out / "metrics.json", metrics)

    frames = read_velocities(run_dir / "velocities.csv") if (run_dir / "velocities.csv").is_file() else None
    ref_planar = to_planar(reference)
    anchored = {name: r.anchored for name, r in results.items()}
    images = {}
    images["trajectories.png"] = plots.plot_trajectories(ref_planar, anchored, out / "trajectories.png",
                                                         title=f"Trajectories: {run_dir.name}")
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
    if frames is not None and frames.t.size:
        images["frontend.png"] = plots.plot_frontend(frames, out / "frontend.png")

    report_config = dict(config)
    report_config.setdefault("sequence", str(sequence))
    summary = read_run_summary(run_dir)
    write_report(out / "report.html", f"fusion-vo run {run_dir.name}", report_config, metrics,
                 {FIGURES[path.name]: path for path in images.values()},
                 frontend_summary(frames) if frames is not None else None,
                 notes=summary.get("notes") or [], counts=(summary.get("fusion") or {}).get("counts"))
    logger.info("wrote metrics.json, %d figures and report.html to %s", len(images), out)
    return metrics



def evaluate_run_against_gps(run_dir: Path, sequence: Path, files: dict[str, Path], config: dict,
                             out: Path | None = None) -> dict:
    """Score a run's trajectories against the recording's GPS fixes (:mod:`.gps`); metrics, gps.png, report
    (into ``out``, default ``run_dir``)."""
    out = run_dir if out is None else out
    from fusion_vo.evaluation.gps import evaluate_against_gps, gps_frame, gps_table
    from fusion_vo.recording import Recording

    gps = Recording(sequence).gps()
    metrics, images = evaluate_against_gps(out, files, gps, config, sequence / "gps0" / "data.csv")
    write_metrics(out / "metrics.json", metrics)
    report_config = dict(config)
    report_config.setdefault("sequence", str(sequence))
    headers, rows = gps_table(metrics)
    notes = [f"{n} GPS fixes skipped ({reason})" for reason, n in gps.skipped.items()]
    summary = read_run_summary(run_dir)
    write_report(out / "report.html", f"fusion-vo run {run_dir.name}", report_config, {}, images,
                 notes=summary.get("notes") or [], counts=(summary.get("fusion") or {}).get("counts"),
                 sections=[(f"Errors against GPS fixes (no ground truth; {gps_frame(metrics)})",
                            headers, rows, notes)])
    logger.info("scored %d trajectories against %d GPS fixes; wrote metrics.json, gps.png and report.html to %s",
                len(metrics), len(gps), run_dir)
    return metrics
