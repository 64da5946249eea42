"""The report of a run, built from its folder: every run has one, with or without ground truth.

``fusion-vo run`` writes it (into its staging folder, from the files it has just written) and
``fusion-vo evaluate RUN`` rebuilds it from the same files, so both give the same report. What it reads:

required  the trajectories (``*.tum``) and every file ``summary.json`` lists under ``files`` (what the run
          wrote): a missing one is an error naming it;
optional  ``summary.json`` (notes, counts, calibration, dropped spans), ``run.yaml`` (configuration, the
          recording), ``innovations.csv`` (:mod:`.innovations`), ``influence.json`` (:mod:`.influence`),
          ``headings.csv`` (:mod:`.headings`), ``velocities.csv``: a section whose file a folder lacks (an
          older run, a folder of trajectories from elsewhere) is left out with a sentence saying so;
the recording named by ``run.yaml`` (or given): its ground truth or GPS fixes for the accuracy section
          and the GPS fixes in the plan view. Without them the report says so in one line and compares the
          sources with each other. The figures against ground truth need evo (the ``eval`` extra); without it
          that section is one line saying so. GPS fixes are scored without evo.

The report's sections and files are described in ``docs/report.md``.
"""

from __future__ import annotations

import json
import logging
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fusion_vo import evaluation
from fusion_vo.config.files import load_yaml
from fusion_vo.errors import InputError, check_folder
from fusion_vo.evaluation import EVO_MISSING, evo_available
from fusion_vo.evaluation import figures, plots
from fusion_vo.evaluation.gps import evaluate_against_gps, gps_frame, gps_table, gps_was_fused
from fusion_vo.evaluation.headings import HEADINGS_CSV, Headings, read_headings
from fusion_vo.evaluation.influence import INFLUENCE_JSON, read_influence
from fusion_vo.evaluation.innovations import INNOVATIONS_CSV, nis_table, read_innovations
from fusion_vo.evaluation.io import (GROUNDTRUTH_CSV, FrameVelocities, find_trajectories, read_run_config,
                                     read_tum_poses, read_velocities, write_metrics)
from fusion_vo.evaluation.report import ReportContent, write_report
from fusion_vo.evaluation.run_tables import calibration_table, dropped_table, gated_spans, influence_table, pauses_table
from fusion_vo.evaluation.verdict import verdict
from fusion_vo.geometry import se2
from fusion_vo.measurements import PoseData
from fusion_vo.recording import Recording
from fusion_vo.sensors.gps import interpolate_poses, predict, read_fixes, robust_fit_rigid_2d

logger = logging.getLogger(__name__)

#: the sources' own tracks and the fused ones, in the order a reference is chosen for the differences
REFERENCES = ("ekf_smoothed", "gtsam", "ekf", "gtsam_online")

#: every file the report writes into a run folder (``fusion-vo evaluate`` replaces them as a set)
OUTPUTS = ("report.html", "metrics.json", "tracks.png", "headings.png", "differences.png", "influence.png",
           "nis_ekf.png", "nis_gtsam.png", "nis_gtsam_online.png", "frontend.png", "trajectories.png",
           "velocities.png", "heading.png", "error_distance.png", "gps.png")


@dataclass
class RunFolder:
    """What a run folder holds (module docstring); ``absent`` has a sentence for each optional file it lacks."""

    path: Path
    config: dict
    summary: dict
    files: dict[str, Path]
    tracks: dict[str, PoseData]
    innovations: dict | None = None
    influence: dict | None = None
    headings: Headings | None = None
    frames: FrameVelocities | None = None
    absent: list[str] = field(default_factory=list)


def has_groundtruth(sequence_dir: str | Path) -> bool:
    """Whether a recording folder contains ground truth."""
    return (Path(sequence_dir) / GROUNDTRUTH_CSV).is_file()


def read_summary(run_dir: Path) -> dict | None:
    """``summary.json`` of a run folder, or None when absent.

    Raises
    ------
    InputError
        Naming the file (and line) when it exists but is not a JSON object.
    """
    path = run_dir / "summary.json"
    if not path.exists():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", path, exc.lineno) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read file: {exc}", path) from None
    if not isinstance(data, dict):
        raise InputError("expected a JSON object (the run's summary)", path)
    return data


def track(path: Path) -> PoseData:
    """A TUM file as planar poses."""
    poses = read_tum_poses(path)
    return PoseData(poses.t, np.column_stack([poses.xyz[:, :2], se2.yaw_of_quaternion(poses.quat_wxyz)]))


def read_run_folder(run_dir: str | Path) -> RunFolder:
    """Read everything the report shows from a run folder (module docstring for required and optional files)."""
    run_dir = check_folder(run_dir, "run folder")
    files = find_trajectories(run_dir)
    summary = read_summary(run_dir)
    absent = []
    if summary is None:
        absent.append("The folder has no summary.json: no notes, counts, calibration or dropped spans.")
        summary = {}
    listed = summary.get("files")
    if isinstance(listed, list):
        for name in listed:
            if isinstance(name, str) and not (run_dir / name).exists():
                raise InputError("file not found (summary.json lists it among the files the run wrote)", run_dir / name)
    folder = RunFolder(run_dir, read_run_config(run_dir), summary, files,
                       {name: track(path) for name, path in files.items()}, absent=absent)
    readers = ((INNOVATIONS_CSV, read_innovations, "innovations",
                "The folder has no innovations.csv: no normalised innovations (the run predates them)."),
               (INFLUENCE_JSON, read_influence, "influence",
                "The folder has no influence.json: the influence of each input was not computed "
                "(influence: false in the run configuration, or a run that predates it)."),
               (HEADINGS_CSV, read_headings, "headings", None),
               ("velocities.csv", read_velocities, "frames", None))
    for name, reader, attribute, sentence in readers:
        if (run_dir / name).exists():
            setattr(folder, attribute, reader(run_dir / name))
        elif sentence:
            absent.append(sentence)
    return folder


def find_recording(folder: RunFolder, sequence_dir: str | Path | None) -> tuple[Path | None, str | None]:
    """The recording for the accuracy section: ``sequence_dir`` if given, else ``run.yaml``'s ``sequence``
    (a relative one tried from the working folder, then from the run folder). Returns it, or None and the
    sentence that says why there is none.

    Raises
    ------
    InputError
        When ``sequence_dir`` is given but is no folder or has neither ground truth nor GPS fixes.
    """
    if sequence_dir is not None:
        sequence = check_folder(sequence_dir, "recording folder")
        if not has_groundtruth(sequence) and not (sequence / "gps0" / "data.csv").is_file():
            raise InputError("recording has no ground truth (and no GPS fixes to score against)",
                             sequence / GROUNDTRUTH_CSV)
        return sequence, None
    named = folder.config.get("sequence")
    if not named:
        return None, "run.yaml names no recording: no accuracy figures (give one with fusion-vo evaluate --gt SEQ)."
    sequence = Path(str(named)).expanduser()
    if not sequence.is_absolute() and not sequence.exists() and (folder.path / sequence).exists():
        sequence = folder.path / sequence
    if not sequence.is_dir():
        return None, f"The recording {sequence} named in run.yaml is not found: no accuracy figures and no GPS fixes."
    return sequence, None


def title_of(folder: RunFolder, name: str) -> tuple[str, str]:
    """The report's title, from the recording (its folder name; a generated one's profile, seed and length),
    and a line saying which run it is."""
    named = folder.config.get("sequence")
    title = Path(str(named)).name if named else name
    described = ""
    if named and (Path(str(named)) / "simulation.yaml").is_file():
        try:
            sim = load_yaml(Path(str(named)) / "simulation.yaml")
            described = (f"a generated recording ({sim.get('profile')} drive, seed {sim.get('seed')}, "
                         f"{(sim.get('summary') or {}).get('duration_s', '?')} s)")
        except InputError:
            described = ""
    sensors = sensors_of(folder)
    return title, f"Run {name}" + (f" of {described}" if described else "") + (
        f"; sensors: {', '.join(sensors)}" if sensors else "")


def sensors_of(folder: RunFolder) -> list[str]:
    """The sensors the run used: ``summary.json``'s ``sensors`` (``run.yaml`` keeps the configured choice, which
    is null for the default)."""
    named = folder.summary.get("sensors") or folder.config.get("sensors") or []
    return [str(s) for s in named] if isinstance(named, list) else []


def _groundtruth_section(folder: RunFolder, sequence: Path, out: Path) -> tuple[dict, dict[str, Path]]:
    # evo (GPL-3.0): loaded only here, when it is installed
    return evaluation.groundtruth_accuracy(sequence, folder.files, out, folder.frames)


def _gps_section(folder: RunFolder, sequence: Path, out: Path) -> tuple[dict, dict[str, Path], list]:
    gps = read_fixes(Recording(sequence))
    metrics, images = evaluate_against_gps(out, folder.files, gps, folder.config, sequence / "gps0" / "data.csv")
    headers, rows = gps_table(metrics)
    notes = [f"{n} GPS fixes skipped ({reason})" for reason, n in gps.skipped.items()]
    return metrics, images, [(f"Errors against GPS fixes (no ground truth; {gps_frame(metrics)})", headers, rows,
                              notes)]


def _gps_overlay(sequence: Path | None, folder: RunFolder, reference: str | None):
    """The GPS fixes in the tracks' frame for the plan view: as they are when the run fused them, else carried
    onto the reference track by the rigid fit of its antenna positions onto them. None without fixes."""
    if sequence is None or reference is None or not (sequence / "gps0" / "data.csv").is_file():
        return None
    gps = read_fixes(Recording(sequence))
    if gps_was_fused(folder.config):
        return gps.enu[:, :2], f"GPS fixes ({len(gps)}, fused)"
    ref = folder.tracks[reference]
    inside = np.flatnonzero((gps.t >= ref.t[0]) & (gps.t <= ref.t[-1]))
    if len(inside) < 3:
        return None
    antenna = predict(interpolate_poses(ref.t, ref.xyyaw, gps.t[inside]), gps.lever_arm)
    fixes = gps.enu[inside, :2]
    yaw, offset, _ = robust_fit_rigid_2d(antenna, fixes, 2.0 / np.trace(gps.covariance[inside], axis1=1, axis2=2))
    c, s = math.cos(yaw), math.sin(yaw)
    return (fixes - offset) @ np.array([[c, -s], [s, c]]), \
        f"GPS fixes ({len(inside)}, SE(2)-aligned to {plots.label_of(reference)}; not fused)"


def frontend_summary(frames: FrameVelocities) -> dict:
    """Frame counts per status and the mean inlier count of the frames with a motion estimate."""
    counts = Counter(frames.status)
    summary = {"frames": len(frames.status)}
    summary.update({f"frames {status}": n for status, n in sorted(counts.items())})
    ok = frames.ok
    if np.any(ok):
        summary["mean inliers (ok frames)"] = round(float(np.mean(frames.inliers[ok])), 1)
    return summary


def evaluate_run(run_dir: str | Path, sequence_dir: str | Path | None = None, out_dir: str | Path | None = None,
                 name: str | None = None, accuracy: bool = True) -> dict:
    """Write the report of a run folder (:func:`build_report`); returns the accuracy figures (``metrics.json``)."""
    return build_report(run_dir, sequence_dir, out_dir, name, accuracy)[1]


def build_report(run_dir: str | Path, sequence_dir: str | Path | None = None, out_dir: str | Path | None = None,
                 name: str | None = None, accuracy: bool = True) -> tuple[ReportContent, dict]:
    """Write the report of a run folder, with its figures and (where the recording allows) ``metrics.json``.

    Parameters
    ----------
    run_dir : str or Path
        Folder written by ``fusion-vo run``.
    sequence_dir : str or Path, optional
        Recording with the ground truth or GPS fixes; by default the ``sequence`` named in ``run.yaml``.
    out_dir : str or Path, optional
        Where to write (default ``run_dir``; the commands write into a staging folder and move the files in
        when all succeeded).
    name : str, optional
        The run's name in the report (default: the run folder's name).
    accuracy : bool
        Compute the accuracy section (``evaluate: false`` in a run's configuration: the report says so).

    Returns
    -------
    content : ReportContent
        What the report shows (its verdict, and why there is no accuracy section where there is none).
    metrics : dict
        Trajectory name -> accuracy figures, as written to ``metrics.json`` (empty without ground truth, GPS
        fixes, or evo for ground truth).

    Raises
    ------
    InputError
        If the folder, its trajectories or a file the run listed are missing, or a file is malformed; if
        ``sequence_dir`` is given but has neither ground truth nor GPS fixes.
    """
    run_dir = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run_dir
    folder = read_run_folder(run_dir)
    name = name or run_dir.resolve().name
    sequence, why = find_recording(folder, sequence_dir)
    content = ReportContent(*title_of(folder, name), config=folder.config, notes=list(folder.summary.get("notes") or []),
                            absent=list(folder.absent))
    metrics: dict = {}
    if not accuracy:
        content.accuracy_line = "Accuracy not evaluated (evaluate: false / --no-evaluate); fusion-vo evaluate adds it."
    elif sequence is None:
        content.accuracy_line = why
    elif has_groundtruth(sequence):
        if evo_available():
            metrics, images = _groundtruth_section(folder, sequence, out)
            content.metrics = metrics
            for caption, path in images.items():
                content.figure("accuracy", caption, path)
        else:
            content.accuracy_line = (EVO_MISSING.replace("evaluation against ground truth needs",
                                                         "No evaluation against ground truth: it needs")
                                     + "; the rest of the report needs none.")
    elif (sequence / "gps0" / "data.csv").is_file():
        metrics, images, content.sections = _gps_section(folder, sequence, out)
        for caption, path in images.items():
            content.figure("accuracy", caption, path)
    else:
        content.accuracy_line = ("The recording has no ground truth and no GPS fixes: no accuracy figures. The "
                                 "sections below compare the sources and the fused tracks with each other.")
    if metrics:
        write_metrics(out / "metrics.json", metrics)
    describe(content, folder, sequence, out)
    write_report(out / "report.html", content)
    logger.info("wrote report.html and %d figures to %s", len(content.figures), out)
    return content, metrics


def describe(content: ReportContent, folder: RunFolder, sequence: Path | None, out: Path) -> None:
    """Fill ``content`` with the sections that need no ground truth, drawing their figures into ``out``."""
    tracks = folder.tracks
    reference = next((n for n in REFERENCES if n in tracks), None)
    span = tracks[reference].t if reference else np.concatenate([tr.t for tr in tracks.values()])
    t0, t1 = float(span.min()), float(span.max())
    start = min(float(tr.t[0]) for tr in tracks.values())
    fusion = folder.summary.get("fusion") or {}
    sensors = sensors_of(folder)
    content.verdict = verdict(folder.influence, folder.summary, sensors, t0, t1)
    path, outside = figures.plot_tracks(tracks, out / "tracks.png", f"Tracks of {content.title}",
                                        _gps_overlay(sequence, folder, reference))
    content.figure("tracks", "Every source's own track and the fused tracks (circle: start, triangle: end)"
                   + (f"; {', '.join(plots.label_of(n) for n in outside)} leaves the frame" if outside else ""), path)
    content.figure("tracks", "Heading over time: each track, the gyro's integral and the AHRS",
                   figures.plot_headings(tracks, folder.headings, out / "headings.png", start))
    if reference is not None and len(tracks) > 1:
        differences = figures.track_differences(tracks, reference)
        content.figure("tracks", f"Distance of each track from {plots.label_of(reference)} over time (as estimated, "
                       "not aligned: every track starts from the same pose)",
                       figures.plot_differences(differences, reference, out / "differences.png", start))
    if folder.influence is not None and folder.influence.get("inputs"):
        content.influence = influence_table(folder.influence)
        content.influence_reference = plots.label_of(folder.influence.get("reference", "ekf_smoothed"))
        content.figure("influence", "The track fused without each input against the full one",
                       figures.plot_influence(folder.influence["inputs"], folder.influence.get("reference", "ekf_smoothed"),
                                              out / "influence.png"))
    if folder.innovations:
        content.nis = nis_table(folder.innovations)
        gate = _gate(folder.config)
        for backend in folder.innovations:
            if f"nis_{backend}.png" in OUTPUTS:
                content.figure("nis", f"Normalised innovations of {plots.label_of(backend)} over time",
                               figures.plot_nis(folder.innovations, backend, out / f"nis_{backend}.png", start,
                                                gate=gate if backend == "ekf" else None))
        if "ekf" in folder.innovations:
            headers, rows, more = gated_spans(folder.innovations["ekf"], start)
            content.gated = (headers, rows, more)
    content.graph_nis_line = None if folder.innovations is None or any(b.startswith("gtsam") for b in folder.innovations) \
        else ("The factor graph's residuals at its solution are not shown: the run computes them with "
              "fusion.graph.residuals: true (it costs the graph's joint marginals).")
    content.dropped = dropped_table(fusion.get("inconsistent") or [], t0, t1, "odom" in sensors)
    content.pauses = pauses_table(fusion.get("pauses") or [], start)
    content.calibration = calibration_table(fusion)
    content.counts = fusion.get("counts")
    if folder.frames is not None and folder.frames.t.size:
        content.frontend = frontend_summary(folder.frames)
        content.figure("frontend", "Inliers per frame and frames the visual frontend could not use",
                       plots.plot_frontend(folder.frames, out / "frontend.png"))
    content.span = (t0, t1)


def _gate(config: dict) -> dict[int, float]:
    """The EKF's gate per measurement size, from the run's ``fusion.gate_probability``."""
    from scipy.stats import chi2

    p = (config.get("fusion") or {}).get("gate_probability", 0.999)
    if not isinstance(p, (int, float)) or not 0 < p < 1:
        return {}
    return {dof: float(chi2.ppf(p, dof)) for dof in range(1, 7)}
