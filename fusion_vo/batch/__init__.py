"""Many recordings, or many parameter sets, on a Dask cluster; one table out.

Each task runs one recording through :func:`fusion_vo.pipeline.run_pipeline`, exactly as ``fusion-vo
run`` does, on a Dask worker that reads the recording from its path. The results are one table
(``results.csv``, ``results.parquet``: one row per recording and trajectory) and ``report.html``::

    from fusion_vo.batch import run_batch, run_sweep

    table = run_batch(["rec1/", "rec2/"], "run.yaml", out="batch/")          # a LocalCluster
    table = run_sweep(["rec1/"], "examples/thesis_sweep.yaml", out="sweep/")

    from distributed import Client
    table = run_batch(recordings, config, Client("tcp://scheduler:8786"), out="/shared/batch")

Needs the ``batch`` extra (dask[distributed], pandas, pyarrow, optuna).
"""

import lazy_loader

# the submodules load on first use (the command line's --help needs only the metric names)
__getattr__, __dir__, __all__ = lazy_loader.attach(__name__, submod_attrs={
    "grid": ["Grid", "ParameterSet", "load_grid", "parse_grid"],
    "ranking": ["best_sets", "describe_set"],
    "runner": ["plan_batch", "plan_sweep", "run_batch", "run_sweep"],
    "columns": ["COLUMNS", "METRICS"],
    "tasks": ["Task", "run_task"],
})
