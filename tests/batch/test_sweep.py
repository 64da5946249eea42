"""A 2 x 2 sweep on a local Dask cluster: one task per (recording, parameter set), one column per key."""

import pandas as pd
import yaml

from fusion_vo.batch import best_sets, run_sweep
from fusion_vo.config import RunConfig


def test_two_by_two_sweep(recordings, client, tmp_path):
    good, _ = recordings
    grid = tmp_path / "grid.yaml"
    grid.write_text("grid:\n  klt.max_tracks: [40, 80]\n  klt.threshold: [0.5, 2.0]\n")
    out = tmp_path / "sweep"
    frame = run_sweep([good[0]], grid, RunConfig(backend="none"), client, out=out)
    csv = pd.read_csv(out / "results.csv")
    assert list(csv.columns[-3:]) == ["parameter_set", "klt.max_tracks", "klt.threshold"]
    sets = csv.drop_duplicates("parameter_set")
    assert sorted(zip(sets["klt.max_tracks"], sets["klt.threshold"])) == [(40, 0.5), (40, 2.0), (80, 0.5), (80, 2.0)]
    assert (csv["status"] == "ok").all() and csv["ate_m"].notna().all()
    for row in sets.to_dict("records"):  # each run used its own parameters
        used = yaml.safe_load((out / good[0].name / row["parameter_set"] / "run.yaml").read_text())
        assert used["klt"] == {"max_tracks": row["klt.max_tracks"], "threshold": row["klt.threshold"]}
    assert csv.groupby("parameter_set")["trajectory"].apply(tuple).nunique() == 1
    ranked, trajectory = best_sets(frame, "ate_m")
    vo = csv[csv["trajectory"] == "vo"].set_index("parameter_set")["ate_m"]
    assert trajectory == "vo" and ranked["parameter_set"].iloc[0] == vo.idxmin()
    assert list(ranked["mean"]) == sorted(vo)
    report = (out / "report.html").read_text()
    assert f"Best parameter set: {vo.idxmin()}" in report
    assert report.count("<img") == sum(frame[m].notna().any() for m in ("ate_m", "end_pct", "heading_deg", "rpe_1m_pct"))
