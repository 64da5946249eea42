"""One task of a batch: one recording (and one parameter set) through :func:`fusion_vo.pipeline.run_pipeline`.

A task is a small, picklable description (paths and the configuration as plain data); it holds no
recording. The worker that runs it reads the recording from its path, writes the run folder exactly
as ``fusion-vo run`` does, and returns the result rows (one per trajectory).

Each finished task leaves a record, ``DIR/tasks/<id>.json``, with its cache key and its rows. The
cache key is a SHA-256 over the full configuration, the fusion-vo version and every file of the
recording (relative path, size and modification time, as rsync's quick check: no file is read). A
task whose record has the same key and status ``ok`` is not run again; its rows come from the record.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import shutil
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from fusion_vo import __version__
from fusion_vo.batch.columns import METRICS
from fusion_vo.batch.grid import build_config
from fusion_vo.errors import InputError, check_folder
from fusion_vo.outputs import write_atomic
from fusion_vo.pipeline import run_pipeline

log = logging.getLogger(__name__)

#: the folder of task records inside the batch output folder
RECORDS = "tasks"


@dataclass(frozen=True)
class Task:
    """What a worker needs to run one recording with one configuration.

    Attributes
    ----------
    recording : str
        Absolute path of the recording folder (a path every worker can see).
    label : str
        The recording's name in the results table.
    run_dir : str
        The run folder (``DIR/<label>`` or ``DIR/<label>/<set>``).
    record : str
        The task record (``DIR/tasks/<id>.json``).
    config : dict
        The full run configuration (:meth:`fusion_vo.config.RunConfig.to_dict`).
    params : dict
        Swept key -> value (empty for a batch).
    set_name : str
        Name of the parameter set (empty for a batch).
    """

    recording: str
    label: str
    run_dir: str
    record: str
    config: dict
    params: dict = field(default_factory=dict)
    set_name: str = ""

    @property
    def key(self) -> str:
        """A unique name of the task (also its Dask key prefix)."""
        return f"{self.label}/{self.set_name}" if self.set_name else self.label


def recording_labels(recordings: list[str | Path]) -> list[tuple[Path, str]]:
    """Absolute recording paths with unique names (``parent_name`` where two folder names clash).

    Raises
    ------
    InputError
        For a recording that is not a folder, one listed twice, or names that stay ambiguous.
    """
    paths = []
    seen: dict[Path, str] = {}
    for given in recordings:
        path = Path(given).expanduser().absolute()
        try:
            check_folder(path, "recording folder")
        except InputError as exc:
            raise InputError(exc.message, given) from None
        real = path.resolve()
        if real in seen:
            raise InputError(f"recording listed twice (also as {seen[real]})", given)
        seen[real] = str(given)
        paths.append(path)
    names = Counter(p.name for p in paths)
    labels = [f"{p.parent.name}_{p.name}" if names[p.name] > 1 else p.name for p in paths]
    clash = sorted(label for label, n in Counter(labels).items() if n > 1)
    if clash:
        raise InputError(f"two recordings would share the run folder '{clash[0]}'; rename one of them", paths[labels.index(clash[0])])
    return list(zip(paths, labels))


def recording_fingerprint(path: str | Path) -> str:
    """SHA-256 over the relative path, size and modification time of every file of a recording."""
    root = Path(path)
    digest = hashlib.sha256()
    for folder, dirs, files in os.walk(root):
        dirs.sort()
        for name in sorted(files):
            full = os.path.join(folder, name)
            st = os.stat(full)
            digest.update(f"{os.path.relpath(full, root)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return digest.hexdigest()


def cache_key(task: Task) -> str:
    """The key under which a task's result is reused: recording files, configuration, version."""
    digest = hashlib.sha256()
    digest.update(recording_fingerprint(task.recording).encode())
    digest.update(json.dumps(task.config, sort_keys=True, default=str).encode())
    digest.update(__version__.encode())
    return digest.hexdigest()


def _number(value) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        return math.nan
    return value if math.isfinite(value) else math.nan


def _row(task: Task, trajectory: str, status: str, error: str, figures: dict, frames: int, failed: int,
         seconds: float) -> dict:
    row = {"recording": task.label, "trajectory": trajectory, "status": status, "error": error}
    row.update({m: _number(figures.get(m)) for m in METRICS})
    row.update({"frames": int(frames), "failed_frames": int(failed), "seconds": round(seconds, 3),
                "cached": False, "run_dir": task.run_dir})
    row.update(task.params)
    if task.set_name:
        row["parameter_set"] = task.set_name
    return row


def failed_rows(task: Task, error: str, seconds: float = math.nan) -> list[dict]:
    """The single row of a task that failed, with its error on one line."""
    line = " ".join(str(error).split()) or "failed"
    return [_row(task, "", "failed", line, {}, 0, 0, seconds)]


def _read_record(path: Path) -> dict | None:
    try:
        with open(path, encoding="utf-8") as f:
            record = json.load(f)
        return record if isinstance(record, dict) else None
    except (OSError, ValueError):
        return None


def _write_record(path: Path, record: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, json.dumps(record, indent=1, default=str))


def _in_worker() -> bool:
    """Whether this code runs as a task of a Dask worker."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return False
    return True


def _one_thread(config: dict) -> dict:
    """The configuration with visual odometry on one thread, unless it names a number of threads.

    Inside a Dask worker the cluster's parallelism is one task per core, so a task must not take every
    core as ``fusion-vo run`` does by default; the results are the same for any number of threads.
    """
    import cv2

    cv2.setNumThreads(1)
    odometry = dict(config.get("odometry") or {})
    if odometry.get("threads") is not None:
        return config
    odometry["threads"] = 1
    return {**config, "odometry": odometry}


def run_task(task: Task) -> list[dict]:
    """Run one task (on a worker) and return its result rows; never raises for a bad recording.

    A task whose record matches its cache key returns the recorded rows (``cached`` True) without
    running. Otherwise the run folder is written by :func:`fusion_vo.pipeline.run_pipeline`, the
    call ``fusion-vo run`` makes, and the record is written last.
    """
    start = time.perf_counter()
    record_path, run_dir = Path(task.record), Path(task.run_dir)
    try:
        key = cache_key(task)
    except OSError as exc:
        return failed_rows(task, f"{exc.filename or task.recording}: {exc.strerror or exc}", time.perf_counter() - start)
    record = _read_record(record_path)
    if record and record.get("key") == key and record.get("status") == "ok" and run_dir.is_dir():
        rows = record.get("rows") or []
        for row in rows:  # the batch folder may have moved since
            row.update(cached=True, run_dir=task.run_dir)
        log.info("%s: unchanged, reusing %s", task.key, record_path)
        return rows
    if record and run_dir.is_dir():  # a folder this batch wrote before, for other inputs
        shutil.rmtree(run_dir)
    record_path.unlink(missing_ok=True)
    try:
        config = build_config(_one_thread(task.config) if _in_worker() else task.config)
        summary = run_pipeline(task.recording, run_dir, config)
    except InputError as exc:
        rows = failed_rows(task, str(exc), time.perf_counter() - start)
    except Exception as exc:  # noqa: BLE001 - one broken recording must not stop the others
        log.exception("%s failed", task.key)
        rows = failed_rows(task, f"{type(exc).__name__}: {exc}", time.perf_counter() - start)
    else:
        seconds = time.perf_counter() - start
        failed = sum(summary.failures.values())
        metrics = summary.metrics or {}
        rows = [_row(task, name, "ok", "", metrics.get(name) or {}, summary.frames, failed, seconds)
                for name in summary.trajectories]
        if not rows:
            rows = [_row(task, "", "ok", "", {}, summary.frames, failed, seconds)]
    status = "ok" if rows[0]["status"] == "ok" else "failed"
    _write_record(record_path, {"key": key, "status": status, "task": task.key, "recording": task.recording,
                                "params": task.params, "rows": rows})
    return rows
