"""Compare several runs: one table (rows run/trajectory), an overlay of their tracks, their differences over
time and each run's verdict, with or without ground truth.

Runs are labelled by their folder names (with the parent folder added where two names clash). Where a run's
recording has ground truth (and evo is installed) its trajectories get the accuracy figures of
:mod:`fusion_vo.evaluation.metrics`, and when every run has it the overlay shows them anchored at the
ground-truth start with the ground truth itself when all runs share one recording. Otherwise the overlay
shows the tracks as estimated.

Every trajectory of a later run is also compared with the trajectory of the same name in the first run, at
the first run's times within both spans: ``diff_rms_m``, ``diff_max_m``, ``diff_end_m`` (horizontal distance).
Tracks are compared as estimated (both runs start from their configured pose), except when only one of the two
runs fused GPS (its track is in East-North-Up, the other's in a frame of its own): then after the rigid SE(2)
fit of the later track onto the first (``diff_aligned``).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from fusion_vo import evaluation
from fusion_vo.errors import InputError
from fusion_vo.evaluation import evo_available, figures
from fusion_vo.evaluation.gps import gps_was_fused
from fusion_vo.evaluation.io import GROUNDTRUTH_CSV, read_groundtruth, write_metrics
from fusion_vo.evaluation.plots import plot_compare
from fusion_vo.evaluation.run_report import RunFolder, find_recording, has_groundtruth, read_run_folder, sensors_of
from fusion_vo.evaluation.verdict import verdict
from fusion_vo.outputs import StagedFiles, check_folder_target, check_outside, write_atomic

logger = logging.getLogger(__name__)

#: every file ``compare_runs`` writes
OUTPUTS = ("compare.json", "compare.csv", "compare.png", "compare_differences.png", "compare_verdicts.txt")


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


def evaluate_trajectories(reference, files: dict[str, Path], reference_path: Path | None = None) -> dict:
    """:func:`fusion_vo.evaluation.evaluate.evaluate_trajectories` (evo, the ``eval`` extra: loaded on first use)."""
    return evaluation.evaluate_trajectories(reference, files, reference_path)


def run_verdict(folder: RunFolder) -> list[str]:
    """A run's verdict sentences (:func:`fusion_vo.evaluation.verdict.verdict`) over its fused span."""
    tracks = folder.tracks
    fused = [tr for name, tr in tracks.items() if name not in ("vo", "wheel")] or list(tracks.values())
    t0 = min(float(tr.t[0]) for tr in fused)
    t1 = max(float(tr.t[-1]) for tr in fused)
    return verdict(folder.influence, folder.summary, sensors_of(folder), t0, t1)


def compare_runs(run_dirs: list[str | Path], out_dir: str | Path,
                 sequence_dir: str | Path | None = None) -> dict[str, dict[str, dict]]:
    """Compare runs and write ``compare.json``, ``compare.csv``, ``compare.png`` (overlay),
    ``compare_differences.png`` (differences from the first run over time) and ``compare_verdicts.txt``.

    Parameters
    ----------
    run_dirs : list of str or Path
        Run folders written by ``fusion-vo run``.
    out_dir : str or Path
        Folder for the outputs (created if missing); neither a run folder compared or inside one, nor
        inside a recording.
    sequence_dir : str or Path, optional
        Recording with the ground truth (or GPS fixes) for all runs; by default each run's ``run.yaml`` names
        its own.

    Returns
    -------
    dict
        Run label -> trajectory name -> figures (accuracy where there is ground truth, differences from the
        first run for the later runs).

    Raises
    ------
    InputError
        As :func:`fusion_vo.evaluation.run_report.evaluate_run`, for the first run at fault.
    """
    run_dirs = [Path(d) for d in run_dirs]
    out_dir = check_folder_target(out_dir)  # before the evaluation's work
    # never into a run folder compared: a later 'fusion-vo run' into it replaces the folder, these files with it
    check_outside(out_dir, run_dirs)
    labels = run_labels(run_dirs)
    folders = [read_run_folder(d) for d in run_dirs]
    table: dict[str, dict[str, dict]] = {label: {name: {} for name in f.tracks} for label, f in zip(labels, folders)}
    sequences, truths, anchored, missing = [], [], {}, {}
    for label, folder in zip(labels, folders):
        sequence, why = find_recording(folder, sequence_dir)
        if sequence is None:
            missing[label] = why
        sequences.append(sequence.resolve() if sequence is not None else None)
        if sequence is None or not has_groundtruth(sequence) or not evo_available():
            continue
        gt = read_groundtruth(sequence / GROUNDTRUTH_CSV)
        results = evaluate_trajectories(gt, folder.files, sequence / GROUNDTRUTH_CSV)
        for name, r in results.items():
            table[label][name].update(r.figures)
        anchored[label] = {name: r.anchored for name, r in results.items()}
        truths.append(evaluation.to_planar(gt))
    check_outside(out_dir, sorted({s for s in sequences if s is not None}))
    differences, aligned = _differences(labels, folders, table)
    everyone = len(anchored) == len(folders)
    shared = everyone and len(set(sequences)) == 1
    verdicts = {label: run_verdict(folder) for label, folder in zip(labels, folders)}
    # the files together or none of them (an error or Ctrl-C keeps an earlier comparison whole)
    with StagedFiles(out_dir, what="output folder", create=True, replaces=OUTPUTS) as staged:
        write_metrics(staged.path / "compare.json", table)
        write_compare_csv(staged.path / "compare.csv", table)
        overlay = anchored if everyone else {label: f.tracks for label, f in zip(labels, folders)}
        plot_compare(truths[0] if shared else None, overlay, staged.path / "compare.png",
                     anchored=everyone)
        if differences:
            start = min(float(tr.t[0]) for tr in folders[0].tracks.values())
            how = "SE(2)-aligned where only one run fused GPS, else as estimated" if any(aligned) else "as estimated, not aligned"
            figures.plot_differences(differences, labels[0], staged.path / "compare_differences.png", start,
                                     title=f"Distance of each track from the same track of {labels[0]} ({how})")
        text = "".join(f"{label}:\n" + "".join(f"  - {s}\n" for s in (lines or ["(no verdict: no influence.json)"])
                                               + ([missing[label]] if label in missing else []))
                       for label, lines in verdicts.items())
        write_atomic(staged.path / "compare_verdicts.txt", text)
        staged.commit()
    logger.info("compared %d runs into %s", len(run_dirs), out_dir)
    return table


def _differences(labels: list[str], folders: list[RunFolder], table: dict) -> tuple[dict, list[bool]]:
    """Each later run's tracks against the first run's of the same name (module docstring); adds the figures to
    ``table`` and returns ``"label: name" -> (t, d)`` and whether each pair was aligned."""
    first = folders[0]
    out, aligned = {}, []
    for label, folder in zip(labels[1:], folders[1:]):
        align = gps_was_fused(first.config) != gps_was_fused(folder.config)
        for name, track in folder.tracks.items():
            if name not in first.tracks:
                continue
            ref = first.tracks[name]
            moved = figures.aligned_to(track, ref) if align else track
            diff = figures.track_differences({name: ref, "other": moved}, name).get("other")
            if diff is None:
                continue
            t, d = diff
            table[label][name].update({"diff_rms_m": float(np.sqrt(np.mean(d**2))), "diff_max_m": float(d.max()),
                                       "diff_end_m": float(d[-1]), "diff_aligned": align})
            out[f"{label}: {name}"] = diff
            aligned.append(align)
    return out, aligned


def write_compare_csv(path: str | Path, table: dict[str, dict[str, dict]]) -> Path:
    """Write the comparison as CSV: one row per run and trajectory, every scalar figure at full precision.

    Columns are ``run,trajectory`` and then the figures' names in the order they first appear; a figure a
    trajectory lacks (or that is not finite) is an empty field.
    """
    import csv
    import io

    columns: list[str] = []
    for runs in table.values():
        for figures_ in runs.values():
            for key, value in figures_.items():
                if isinstance(value, (int, float)) and not isinstance(value, bool) and key not in columns:
                    columns.append(key)
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["run", "trajectory", *columns])
    for label, runs in table.items():
        for name, figures_ in runs.items():
            row = []
            for key in columns:
                value = figures_.get(key)
                ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                row.append((str(value) if isinstance(value, int) else repr(float(value))) if ok else "")
            writer.writerow([label, name, *row])
    return write_atomic(path, buf.getvalue())
