"""``--optimize``: Optuna trials on the local Dask cluster, each trial one parameter set over the recordings."""

import pandas as pd

from fusion_vo.batch.optimize import load_search, optimize
from fusion_vo.config import RunConfig


def test_optuna_trials_run_on_the_cluster(recordings, client, tmp_path):
    good, _ = recordings
    grid = tmp_path / "search.yaml"
    grid.write_text("seed: 3\nranges:\n  klt.threshold: {low: 0.5, high: 3.0}\n  klt.max_tracks: {low: 40, high: 90}\n")
    config = RunConfig(backend="none")
    space = load_search(grid, config, trials=3)
    frame, best = optimize([good[1]], space, config, client, out=tmp_path / "opt", metric="ate_m", trials=3)
    csv = pd.read_csv(tmp_path / "opt" / "results.csv")
    trials = csv.drop_duplicates("parameter_set")
    assert list(trials["parameter_set"]) == ["t000", "t001", "t002"] and (csv["status"] == "ok").all()
    assert trials["klt.threshold"].between(0.5, 3.0).all() and trials["klt.max_tracks"].between(40, 90).all()
    assert pd.api.types.is_integer_dtype(trials["klt.max_tracks"])
    vo = csv[csv["trajectory"] == "vo"].set_index("parameter_set")["ate_m"]
    named = best.split()[1]  # "trial t001 (...): mean ate_m of vo 7.7e-06"
    assert best.startswith("trial ") and vo[named] == vo.min() and best.endswith(f"{vo.min():.5g}")
