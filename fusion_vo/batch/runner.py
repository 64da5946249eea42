"""Run many tasks on a Dask cluster and collect one table: batches (recordings) and sweeps (x parameter sets)."""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Callable

from fusion_vo.batch.cluster import open_client, require_dask
from fusion_vo.batch.columns import COLUMNS
from fusion_vo.batch.grid import Grid, build_config, cell_value, config_data, load_grid, parse_grid
from fusion_vo.batch.report import write_report
from fusion_vo.batch.tasks import RECORDS, Task, failed_rows, recording_labels, run_task
from fusion_vo.config import RunConfig, load_config
from fusion_vo.errors import InputError
from fusion_vo.outputs import check_folder_target, check_outside

log = logging.getLogger(__name__)

#: files of the batch output folder besides the run folders
OUTPUTS = ("results.csv", "results.parquet", "report.html")

#: ``progress(done, failed, total)`` after every finished task
Progress = Callable[[int, int, int], None]


def _as_config(config: RunConfig | str | Path | None) -> RunConfig:
    if config is None or isinstance(config, (str, Path)):
        return load_config(config)
    return build_config(config_data(config))


def _check_out(out: str | Path) -> Path:
    return check_folder_target(out)  # a file there, or in the way above it


def _check_inputs(out: Path, labelled: list[tuple[Path, str]]) -> None:
    """Before any cluster starts: the batch folder is not inside a recording, and no task's run folder
    (``out/<label>``) is or holds a recording (``fusion-vo run`` would refuse each task only on its worker)."""
    check_outside(out, [path for path, _ in labelled])
    target = out.resolve()
    for path, label in labelled:
        source = Path(path).resolve()
        run_dir = target / label
        if run_dir == source or run_dir in source.parents:
            raise InputError(f"the run folder of recording {path} would be {out / label}, which holds the recording; "
                             "give another output folder", out)


def plan_batch(recordings: list[str | Path], config: RunConfig, out: str | Path) -> list[Task]:
    """One task per recording; checks the recordings (folders, none twice) without reading them."""
    out = _check_out(out).absolute()
    labelled = _labels(recordings)
    _check_inputs(out, labelled)
    settings = config_data(config)
    return [Task(recording=str(path), label=label, run_dir=str(out / label),
                 record=str(out / RECORDS / f"{label}.json"), config=settings)
            for path, label in labelled]


def plan_sweep(recordings: list[str | Path], grid: Grid, out: str | Path) -> list[Task]:
    """One task per (recording, parameter set), recording-major."""
    out = _check_out(out).absolute()
    labelled = _labels(recordings)
    _check_inputs(out, labelled)
    settings = [config_data(c) for c in grid.configs]
    return [Task(recording=str(path), label=label, run_dir=str(out / label / ps.name),
                 record=str(out / RECORDS / label / f"{ps.name}.json"), config=cfg, params=dict(ps.values),
                 set_name=ps.name)
            for path, label in labelled for ps, cfg in zip(grid.sets, settings)]


def _labels(recordings: list[str | Path]) -> list[tuple[Path, str]]:
    if isinstance(recordings, (str, Path)):
        recordings = [recordings]
    if not recordings:
        raise InputError("no recordings given")
    labelled = recording_labels(list(recordings))
    reserved = {RECORDS, *OUTPUTS}
    for path, label in labelled:
        if label in reserved:
            raise InputError(f"a recording named '{label}' would overwrite the batch's own '{label}'; rename it", path)
    return labelled


def execute(tasks: list[Task], client=None, workers: int | None = None, scheduler: str | None = None,
            progress: Progress | None = None, announce: Callable[[str], None] | None = None) -> list[dict]:
    """Run ``tasks`` on ``client`` (or a cluster opened for the call) and return all rows in task order.

    A task whose worker dies or raises becomes a ``failed`` row; the others finish.
    """
    require_dask()
    if client is None:
        with open_client(workers=workers, scheduler=scheduler, announce=announce) as own:
            return execute(tasks, own, progress=progress)
    from distributed import as_completed

    total, done, failed = len(tasks), 0, 0
    results: list[list[dict] | None] = [None] * total
    if progress:
        progress(0, 0, total)
    futures = client.map(run_task, tasks, pure=False)
    index = {f.key: i for i, f in enumerate(futures)}
    try:
        for future in as_completed(futures):
            i = index[future.key]
            if future.status == "finished":
                rows = future.result()
            else:  # the worker died or the task raised outside the pipeline
                exc = future.exception()
                rows = failed_rows(tasks[i], f"{type(exc).__name__}: {exc}")
            results[i] = rows
            done += 1
            failed += rows[0]["status"] != "ok"
            future.release()
            if progress:
                progress(done, failed, total)
    except BaseException:
        client.cancel(futures)
        raise
    return [row for rows in results for row in (rows or [])]


def _frame(rows: list[dict], keys: list[str]):
    import pandas as pd

    columns = list(COLUMNS) + (["parameter_set", *keys] if keys else [])
    frame = pd.DataFrame(rows, columns=columns)
    for key in keys:  # list values as their JSON text: grouped, ranked and plotted like any value
        frame[key] = frame[key].map(cell_value)
    return frame


def write_results(frame, out: Path, title: str, grid: Grid | None = None, rank: tuple[str, str | None] = ("ate_m", None)) -> None:
    """``results.csv``, ``results.parquet`` and ``report.html``, each written whole and then renamed."""

    out.mkdir(parents=True, exist_ok=True)
    tmp_csv, tmp_parquet = out / ".results.csv.tmp", out / ".results.parquet.tmp"
    try:
        frame.to_csv(tmp_csv, index=False)
        try:
            frame.astype({k: str for k in (grid.keys if grid else []) if frame[k].dtype == object}).to_parquet(tmp_parquet, index=False)
        except ImportError as exc:
            raise InputError(f"results.parquet needs pyarrow; install the batch extra: pip install 'fusion-vo[batch]' ({exc})") from None
        os.replace(tmp_csv, out / "results.csv")
        os.replace(tmp_parquet, out / "results.parquet")
    finally:
        tmp_csv.unlink(missing_ok=True)
        tmp_parquet.unlink(missing_ok=True)
    write_report(frame, out / "report.html", title, grid, rank)


def run_batch(recordings: list[str | Path], config: RunConfig | str | Path | None = None, client=None, *,
              out: str | Path = "fusion-vo-batch", workers: int | None = None, scheduler: str | None = None,
              progress: Progress | None = None, announce: Callable[[str], None] | None = None):
    """Run every recording as ``fusion-vo run`` would, on a Dask cluster, into one table.

    Parameters
    ----------
    recordings : list of str or Path
        Recording folders (paths the workers can see).
    config : RunConfig, str, Path or None
        The run configuration, or a YAML file of it (default: the defaults).
    client : distributed.Client, optional
        Cluster to run on; by default a LocalCluster (``workers`` processes) or ``scheduler``.
    out : str or Path
        Output folder: ``<recording>/`` run folders, ``results.csv``, ``results.parquet``, ``report.html``.
    progress : callable, optional
        ``progress(done, failed, total)``.

    Returns
    -------
    pandas.DataFrame
        One row per recording and trajectory (a failed recording is one row with status ``failed``).

    Raises
    ------
    InputError
        For bad arguments, before anything is written or run.
    """
    require_dask()
    config = _as_config(config)
    tasks = plan_batch(recordings, config, out)
    rows = _run(tasks, client, workers, scheduler, progress, announce)
    frame = _frame(rows, [])
    write_results(frame, Path(out), f"Batch of {len(tasks)} recordings")
    return frame


def run_sweep(recordings: list[str | Path], grid: str | Path | dict, config: RunConfig | str | Path | None = None,
              client=None, *, out: str | Path = "fusion-vo-sweep", workers: int | None = None,
              scheduler: str | None = None, rank: str = "ate_m", rank_trajectory: str | None = None,
              progress: Progress | None = None, announce: Callable[[str], None] | None = None):
    """Run every recording with every parameter set of ``grid``; one row per task and trajectory.

    ``grid`` is a ``GRID.yaml`` path or its contents (see :mod:`fusion_vo.batch.grid`). The table has
    the columns of :func:`run_batch`, ``parameter_set`` and one column per swept key; the report ranks
    the sets by the mean of ``rank`` over the recordings, for ``rank_trajectory`` (default: ``vo``).
    """
    require_dask()
    config = _as_config(config)
    parsed = load_grid(grid, config) if isinstance(grid, (str, Path)) else parse_grid(grid, config)
    if rank not in COLUMNS[4:8]:
        raise InputError(f"cannot rank by '{rank}' (one of {', '.join(COLUMNS[4:8])})")
    tasks = plan_sweep(recordings, parsed, out)
    rows = _run(tasks, client, workers, scheduler, progress, announce)
    frame = _frame(rows, parsed.keys)
    write_results(frame, Path(out), f"Sweep of {len(parsed.sets)} parameter sets over {len(tasks) // len(parsed.sets)} "
                  "recordings", parsed, (rank, rank_trajectory))
    return frame


def _run(tasks, client, workers, scheduler, progress, announce) -> list[dict]:
    start = time.perf_counter()
    if client is None:
        with open_client(workers=workers, scheduler=scheduler, announce=announce) as own:
            rows = execute(tasks, own, progress=progress)
    else:
        rows = execute(tasks, client, progress=progress)
    failed = sum(1 for r in rows if r["status"] != "ok")
    log.info("%d tasks in %.1f s, %d failed", len(tasks), time.perf_counter() - start, failed)
    return rows
