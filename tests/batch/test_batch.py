"""Batches on a local Dask cluster of 2 processes: same figures as single runs, failures alone, resumption."""

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fusion_vo.batch import METRICS, run_batch
from fusion_vo.batch.tasks import Task, cache_key
from fusion_vo.config import RunConfig
from fusion_vo.pipeline import run_pipeline

from ahead_job import ahead_jobs
from small_recordings import SEEDS, small_recording


@pytest.fixture(scope="module")
def batch(recordings, client, tmp_path_factory):
    good, broken = recordings
    out = tmp_path_factory.mktemp("batch") / "out"
    frame = run_batch([*good, broken], None, client, out=out)
    return out, frame


def _same(a, b):
    """Equal up to rounding (a worker's BLAS has one thread, this process's may have more)."""
    return (math.isnan(a) and math.isnan(b)) or math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)


#: the files of a run compared number by number with the batch's
COMPARED = ("vo.tum", "gtsam.tum", "velocities.csv")


def _table(path):
    csv = path.suffix == ".csv"
    return np.genfromtxt(path, delimiter="," if csv else None, skip_header=1 if csv else 0, dtype=float)


def _single_runs() -> dict:
    """The good recordings (conftest.py's, made again in a temporary folder) each run alone in this process: per
    recording, its trajectories, frames, metrics, the names of the files written and the tables of
    :data:`COMPARED`."""
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in SEEDS:
            rec = small_recording(Path(tmp) / "recordings" / f"drive{seed}", seed)
            out = Path(tmp) / "runs" / rec.name
            single = run_pipeline(rec, out, RunConfig())
            runs[rec.name] = {"trajectories": single.trajectories, "frames": single.frames, "metrics": single.metrics,
                              "files": sorted(p.name for p in out.iterdir()),
                              "tables": {name: _table(out / name) for name in COMPARED}}
    return runs


AHEAD = {"single_runs": _single_runs}
BACKGROUND_COMMANDS, BACKGROUND_JOBS = ahead_jobs(__file__)


def test_figures_equal_those_of_single_runs(batch, recordings, made_ahead):
    out, frame = batch
    good, _ = recordings
    runs = made_ahead("single_runs")
    assert sorted(runs) == sorted(rec.name for rec in good)
    for rec in good:
        single = runs[rec.name]
        rows = frame[frame["recording"] == rec.name]
        assert list(rows["trajectory"]) == single["trajectories"]
        assert set(rows["status"]) == {"ok"} and set(rows["frames"]) == {single["frames"]}
        for row in rows.to_dict("records"):
            for metric in METRICS:
                assert _same(row[metric], float(single["metrics"][row["trajectory"]].get(metric, math.nan))), (rec.name, metric)
        assert sorted(p.name for p in (out / rec.name).iterdir()) == single["files"]
        for name in COMPARED:
            mine, theirs = _table(out / rec.name / name), single["tables"][name]
            assert mine.shape == theirs.shape and len(mine) > 50, name
            np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-9, err_msg=name)
    assert frame[frame["trajectory"] == "vo"]["ate_m"].notna().all()


def test_broken_recording_fails_alone(batch, recordings):
    out, frame = batch
    _, broken = recordings
    rows = frame[frame["recording"] == "broken"]
    assert len(rows) == 1
    row = rows.iloc[0]
    assert row["status"] == "failed" and row["trajectory"] == ""
    assert f"{broken / 'imu0' / 'data.csv'}:21:" in row["error"] and "\n" not in row["error"]
    assert (frame[frame["recording"] != "broken"]["status"] == "ok").all()
    assert frame["recording"].nunique() == 4


def test_tables_and_report_are_written(batch):
    out, frame = batch
    columns = ["recording", "trajectory", "status", "error", "ate_m", "end_pct", "heading_deg", "rpe_1m_pct",
               "frames", "failed_frames", "seconds"]
    csv = pd.read_csv(out / "results.csv", keep_default_na=False, na_values=[""])
    parquet = pd.read_parquet(out / "results.parquet")
    for table in (csv, parquet):
        assert list(table.columns[:len(columns)]) == columns
        assert list(table["recording"]) == list(frame["recording"])
        assert list(table["trajectory"].fillna("")) == list(frame["trajectory"])
        pd.testing.assert_series_equal(table["ate_m"], frame["ate_m"], check_names=False)
    report = (out / "report.html").read_text()
    plotted = [m for m in METRICS if frame[m].notna().any()]  # RPE over 1 m needs a longer drive
    assert report.count("<img") == len(plotted) >= 3  # one plot per metric that has values
    assert report.count("no finite value in any row") == len(METRICS) - len(plotted)
    assert "broken" in report and "NaN or infinite value" in report
    assert not [p for p in out.rglob("*") if ".tmp" in p.name or p.name.startswith(".fusion-vo-partial")]


def test_resumed_batch_runs_nothing_again(batch, recordings, client):
    out, first = batch
    good, broken = recordings
    before = {p: p.stat().st_mtime_ns for rec in good for p in (out / rec.name).iterdir()}
    again = run_batch([*good, broken], None, client, out=out)
    ok = again[again["status"] == "ok"]
    assert len(ok) == len(first[first["status"] == "ok"]) and ok["cached"].all()
    assert {p: p.stat().st_mtime_ns for p in before} == before
    pd.testing.assert_frame_equal(ok.drop(columns="cached"), first[first["status"] == "ok"].drop(columns="cached"))
    failed = again[again["status"] == "failed"]  # a failure is tried again: it may have been the machine's
    assert list(failed["recording"]) == ["broken"] and not failed["cached"].any()


def test_the_workers_keep_glibcs_memory_thresholds_and_the_callers_environment_is_left_alone(client, environment_before):
    """Dask's nanny would set ``MALLOC_TRIM_THRESHOLD_=65536`` (every image-sized array mapped and faulted in anew)
    in its workers and write its worker variables into this process's environment, for every later subprocess."""
    names = ("MALLOC_TRIM_THRESHOLD_", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "PYTHONHASHSEED")
    seen = client.run(lambda: {name: os.environ.get(name) for name in names})
    assert len(seen) == 2
    for env in seen.values():
        assert env["MALLOC_TRIM_THRESHOLD_"] == environment_before.get("MALLOC_TRIM_THRESHOLD_")
        assert env["OMP_NUM_THREADS"] == env["OPENBLAS_NUM_THREADS"] == "1"  # one single-threaded worker per core
    assert {name: os.environ.get(name) for name in names} == {name: environment_before.get(name) for name in names}


def test_cache_key_follows_files_and_configuration(recordings, tmp_path):
    good, _ = recordings
    rec = good[0]

    def key(config):
        return cache_key(Task(str(rec), rec.name, str(tmp_path / "run"), str(tmp_path / "rec.json"), config))

    base = key(RunConfig().to_dict())
    assert key(RunConfig().to_dict()) == base
    assert key(RunConfig(klt={"max_tracks": 50}).to_dict()) != base
    stamp = rec / "wheel0" / "data.csv"
    st = stamp.stat()
    try:
        os.utime(stamp, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
        assert key(RunConfig().to_dict()) != base
    finally:
        os.utime(stamp, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert key(RunConfig().to_dict()) == base
