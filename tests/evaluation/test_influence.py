"""Each input's influence on the fused track, the EKF's innovation record, and a report that cannot be drawn, on
the generated ``short`` recording (made in a temporary folder)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from fusion_vo.backends.batch import as_config, fuse, streams_from_recording
from fusion_vo.cli.main import main
from fusion_vo.evaluation.influence import inputs, leave_one_out
from fusion_vo.measurements import RangeData
from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording


@pytest.fixture(scope="module")
def short(standard_recording):
    rec_dir = standard_recording("short")
    rec = Recording(rec_dir)
    vo = run_visual_odometry(rec, OdometryConfig())
    config = as_config({})
    return rec_dir, streams_from_recording(rec, vo, ["camera", "wheel", "imu"], config), config


def test_an_input_without_usable_data_has_no_influence(short):
    _, streams, config = short
    t = np.array([inc.t1 for inc in streams.visual])
    silent = streams.replace(range=RangeData(t, np.full(len(t), np.nan)))  # every reading gated
    assert [name for name, _, _ in inputs(silent)] == ["camera", "wheel", "gyro", "range"]
    full = fuse(silent, "ekf", config).trajectories["ekf_smoothed"]
    influence = {e["name"]: e for e in leave_one_out(silent, config, full)["inputs"]}
    assert influence["range"]["error"] is None
    assert influence["range"]["rms_m"] == 0.0 and influence["range"]["heading_rms_deg"] == 0.0
    assert influence["range"]["distance_pct"] == 0.0
    # the camera carries this drive: without it the track moves (the check can tell a zero from a non-zero)
    assert influence["camera"]["rms_m"] > 1e-4 and abs(influence["camera"]["distance_pct"]) > 0.1


def test_the_ekf_records_every_block_it_tested(short):
    _, streams, config = short
    result = fuse(streams, "ekf", config)
    table = result.innovations["ekf"]
    counts = result.counts["ekf"]
    for sensor in set(table.sensor):
        mine = table.sensor == sensor
        assert np.count_nonzero(mine & (table.status != "rejected")) == counts[sensor].used, sensor
    assert set(table.sensor) >= {"camera", "wheel", "gyro"}
    assert np.all(np.diff(table.t) >= 0) and np.all(table.d2 >= 0)
    assert set(table.dof[table.sensor == "camera"]) == {3} and set(table.dof[table.sensor == "gyro"]) == {1}
    nodes = result.trajectories["ekf"].t
    assert np.all(np.isin(table.t, nodes))


def test_a_report_that_cannot_be_drawn_is_a_warning_not_a_failed_run(short, tmp_path, monkeypatch, capsys):
    rec_dir, _, _ = short
    from fusion_vo.evaluation import figures

    def broken(*args, **kwargs):
        raise RuntimeError("no canvas")

    monkeypatch.setattr(figures, "plot_tracks", broken)
    out = tmp_path / "out"
    assert main(["run", str(rec_dir), "--out", str(out), "--backend", "ekf", "--no-evaluate"]) == 0
    printed = capsys.readouterr().out
    assert "note: report.html not written: RuntimeError: no canvas" in printed
    assert (out / "ekf.tum").is_file() and not (out / "report.html").exists()
    assert "report.html not written: RuntimeError: no canvas" in json.loads((out / "summary.json").read_text())["notes"]
