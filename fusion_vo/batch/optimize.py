"""``fusion-vo sweep --optimize METRIC --trials N``: an Optuna search over the ranges of ``GRID.yaml``.

Optuna's ask-and-tell interface proposes each trial's parameter set in this process; the trial's tasks
(one per recording) run on the same Dask cluster as a sweep, as many trials at once as keep every
worker busy. A trial's value is the mean of ``METRIC`` over the recordings for one trajectory (default
``vo``); a trial where a recording fails, or whose figure is missing, is told to Optuna as failed.

The search space is the grid file's ``ranges`` (``{low, high, log}`` or a list of choices) or its
``grid`` (each list a set of choices, each choice a number, text or true/false: Optuna's categorical
values); ``fixed`` keys apply to every trial. Trials are sampled with
Optuna's TPE sampler seeded by the file's ``seed``. Run folders are ``DIR/<recording>/t000/`` ...
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

from fusion_vo.batch.columns import METRICS
from fusion_vo.batch.grid import (GRID_SECTIONS, MAX_SETS, Grid, ParameterSet, _schema, apply_values,
                                  check_frontend_keys, check_key, config_data)
from fusion_vo.batch.runner import Progress, _check_out, _frame, _labels, write_results
from fusion_vo.batch.tasks import RECORDS, Task, failed_rows, run_task
from fusion_vo.config import FRONTENDS, RunConfig
from fusion_vo.errors import InputError
from fusion_vo.config.files import load_yaml

log = logging.getLogger(__name__)


@dataclass
class SearchSpace:
    """The keys Optuna varies: name -> ``("float"|"int", low, high, log)`` or ``("choice", [values])``."""

    params: dict
    fixed: dict = field(default_factory=dict)
    seed: int = 0
    path: Path | None = None
    base: RunConfig = field(default_factory=RunConfig)

    def probe_grid(self) -> Grid:
        """A one-set grid (the first choice or the lower bound of every key), to check the plan."""
        values = {k: (spec[1][0] if spec[0] == "choice" else spec[1]) for k, spec in self.params.items()}
        config = apply_values(self.base, {**self.fixed, **values}, self.path)
        return Grid(list(self.params), [ParameterSet("t000", values)], [config], self.path)


def load_search(path: str | Path, base: RunConfig, trials: int) -> SearchSpace:
    """Read the search space from ``GRID.yaml``; errors name the file and the key."""
    path = Path(path)
    data = load_yaml(path)
    if isinstance(trials, bool) or not isinstance(trials, int) or not 1 <= trials <= MAX_SETS:
        raise InputError(f"--trials must be a number from 1 to {MAX_SETS}, not {trials!r}")
    unknown = sorted(set(data) - set(GRID_SECTIONS))
    if unknown:
        raise InputError(f"unknown grid section '{unknown[0]}' (known: {', '.join(GRID_SECTIONS)})", path)
    space = data.get("ranges") if data.get("ranges") is not None else data.get("grid")
    if not isinstance(space, dict) or not space:
        raise InputError("the grid is empty: --optimize needs 'ranges:' (or 'grid:') mapping keys to ranges or choices", path)
    schema = _schema()
    fixed = data.get("fixed") or {}
    if not isinstance(fixed, dict):
        raise InputError("'fixed' must be a mapping of key: value", path)
    params = {}
    for key, spec in space.items():
        check_key(key, path, schema)
        if isinstance(spec, (list, tuple)):
            if not spec:
                raise InputError(f"key '{key}' has no values to try", path)
            for choice in spec:  # Optuna's categorical choices are single values
                if choice is not None and not isinstance(choice, (bool, int, float, str)):
                    raise InputError(f"key '{key}': --optimize chooses among numbers, text or true/false, not "
                                     f"{choice!r} (run a sweep without --optimize to try lists)", path)
            params[key] = ("choice", list(spec))
        elif isinstance(spec, dict) and "low" in spec and "high" in spec and set(spec) <= {"low", "high", "log"}:
            low, high, use_log = spec["low"], spec["high"], bool(spec.get("log", False))
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in (low, high)) \
                    or low > high or (use_log and low <= 0):
                raise InputError(f"range '{key}': needs finite numbers low <= high (low > 0 with log: true)", path)
            kind = "int" if isinstance(low, int) and isinstance(high, int) else "float"
            params[key] = (kind, low, high, use_log)
        else:
            raise InputError(f"range '{key}' must be {{low: A, high: B}} (optionally log: true) or a list of choices", path)
    for key in fixed:
        check_key(key, path, schema)
    frontend = fixed.get("frontend", base.frontend)
    if "frontend" not in params and frontend in FRONTENDS:  # (a searched frontend: each trial uses its own)
        check_frontend_keys(params, [frontend], path)
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise InputError(f"'seed' must be an integer, not {seed!r}", path)
    return SearchSpace(params, dict(fixed), seed, path, base)


def _suggest(trial, params: dict) -> dict:
    values = {}
    for key, spec in params.items():
        if spec[0] == "choice":
            values[key] = trial.suggest_categorical(key, spec[1])
        elif spec[0] == "int":
            values[key] = trial.suggest_int(key, spec[1], spec[2], log=spec[3])
        else:
            values[key] = trial.suggest_float(key, float(spec[1]), float(spec[2]), log=spec[3])
    return values


def optimize(recordings, space: SearchSpace, config: RunConfig, client, *, out: str | Path, metric: str = "ate_m",
             trajectory: str | None = None, trials: int = 20, progress: Progress | None = None):
    """Search the space with Optuna, the trials' tasks running on ``client``.

    Returns
    -------
    (pandas.DataFrame, str)
        The results table (as :func:`fusion_vo.batch.run_sweep`, one parameter set per trial) and a
        line naming the best trial.
    """
    import optuna
    from distributed import as_completed

    if metric not in METRICS:
        raise InputError(f"cannot optimise '{metric}' (one of {', '.join(METRICS)})")
    out = _check_out(out).absolute()
    labelled = _labels(recordings)
    trajectory = trajectory or "vo"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(direction="minimize", sampler=optuna.samplers.TPESampler(seed=space.seed))
    workers = max(1, len(client.scheduler_info().get("workers", {})))
    at_once = max(1, math.ceil(workers / len(labelled)))
    width = max(3, len(str(trials - 1)))
    total = trials * len(labelled)
    rows_of: dict[int, list[list[dict]]] = {}
    pending: dict[int, int] = {}
    trial_of: dict[int, object] = {}
    all_rows: list[list[dict]] = []
    done = failed = 0
    asked = 0
    futures = as_completed()
    owner = {}

    def ask() -> None:
        nonlocal asked, done, failed
        trial = study.ask()
        name = f"t{trial.number:0{width}d}"
        values = _suggest(trial, space.params)
        asked += 1
        tasks = [Task(recording=str(path), label=label, run_dir=str(out / label / name),
                      record=str(out / RECORDS / label / f"{name}.json"), config={}, params=values, set_name=name)
                 for path, label in labelled]
        try:
            cfg = config_data(apply_values(config, {**space.fixed, **values}, space.path))
        except InputError as exc:  # a combination the configuration rejects: a failed trial, nothing run
            rows = [failed_rows(t, exc.message) for t in tasks]
            all_rows.extend(rows)
            study.tell(trial, state=optuna.trial.TrialState.FAIL)
            done += len(tasks)
            failed += len(tasks)
            return
        tasks = [Task(**{**t.__dict__, "config": cfg}) for t in tasks]
        trial_of[trial.number] = trial
        rows_of[trial.number] = []
        pending[trial.number] = len(tasks)
        for future, task in zip(client.map(run_task, tasks, pure=False), tasks):
            owner[future.key] = (trial.number, task)
            futures.add(future)

    try:
        while asked < trials and len(pending) < at_once:
            ask()
        for future in futures:
            number, task = owner.pop(future.key)
            if future.status == "finished":
                rows = future.result()
            else:  # the worker died or the task raised outside the pipeline
                exc = future.exception()
                rows = failed_rows(task, f"{type(exc).__name__}: {exc}")
            rows_of[number].append(rows)
            done += 1
            failed += rows[0]["status"] != "ok"
            pending[number] -= 1
            if progress:
                progress(done, failed, total)
            if pending[number] == 0:
                del pending[number]
                results = rows_of.pop(number)
                all_rows.extend(results)
                value = _value(results, metric, trajectory)
                if value is None:
                    study.tell(trial_of.pop(number), state=optuna.trial.TrialState.FAIL)
                else:
                    study.tell(trial_of.pop(number), value)
                while asked < trials and len(pending) < at_once:
                    ask()
    except BaseException:
        client.cancel(list(futures.futures))
        raise
    if progress and done < total:  # trials rejected before they ran
        progress(total, failed, total)
    order = {label: i for i, (_, label) in enumerate(labelled)}
    rows = sorted((r for rows in all_rows for r in rows), key=lambda r: (order.get(r["recording"], -1), r.get("parameter_set", "")))
    frame = _frame(rows, list(space.params))
    grid = Grid(list(space.params), [], [], space.path)
    write_results(frame, out, f"Optuna search: {trials} trials over {len(labelled)} recordings, minimising {metric}",
                  grid, (metric, trajectory))
    try:
        best = study.best_trial
        line = (f"trial t{best.number:0{width}d} ({', '.join(f'{k}={v}' for k, v in best.params.items())}): "
                f"mean {metric} of {trajectory} {best.value:.5g}")
    except ValueError:
        line = "no trial completed on every recording"
    return frame, line


def _value(results: list[list[dict]], metric: str, trajectory: str) -> float | None:
    values = []
    for rows in results:
        row = next((r for r in rows if r.get("status") == "ok" and r.get("trajectory") == trajectory), None)
        if row is None or not isinstance(row.get(metric), float) or not math.isfinite(row[metric]):
            return None
        values.append(row[metric])
    return sum(values) / len(values) if values else None
