"""Evaluation against GPS fixes when a recording has no ground truth."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from fusion_vo.cli.main import main
from fusion_vo.outputs import PNG_SOFTWARE, png_software
from fusion_vo.recording import write_tum
from fusion_vo.recording.gps import HEADER, enu_to_geodetic, format_rows
from fusion_vo.sensors import gps as gps_model

SIGMA = 0.05
LEVER = [-0.2, 0.1, 0.5]
HEADING, ORIGIN = math.radians(30.0), np.array([4.0, -2.0])


def drive(n=601):
    """A 60 s drive in its own frame: a straight leg, a left turn, a curve."""
    t = 1000.0 + np.linspace(0.0, 60.0, n)
    w = np.where((t - 1000.0) > 20.0, 0.08, 0.0)
    yaw = np.concatenate([[0.0], np.cumsum(w[:-1] * np.diff(t))])
    v = 0.5
    x = np.concatenate([[0.0], np.cumsum(v * np.cos(yaw[:-1]) * np.diff(t))])
    y = np.concatenate([[0.0], np.cumsum(v * np.sin(yaw[:-1]) * np.diff(t))])
    return t, np.column_stack([x, y, yaw])


def make_sequence(root: Path, jump: bool = False) -> Path:
    t, local = drive()
    enu_poses = gps_model.Alignment(HEADING, ORIGIN, 0.0, 0).apply(local)
    tf = t[::2]
    z = gps_model.predict(gps_model.interpolate_poses(t, enu_poses, tf), LEVER)
    z = z + np.random.default_rng(5).normal(0, SIGMA, z.shape)
    if jump:
        z[100] += [12.0, 16.0]
    enu = np.column_stack([z, np.zeros(len(z))])
    seq = root / "seq"
    (seq / "gps0").mkdir(parents=True)
    datum = (47.0, 8.0, 400.0)
    n = len(tf)
    rows = format_rows(np.rint(tf * 1e9).astype(np.int64), enu_to_geodetic(enu, datum), enu, np.zeros(n),
                       np.full(n, 2), np.tile([SIGMA**2, 0.0, SIGMA**2], (n, 1)))
    (seq / "gps0" / "data.csv").write_text("\n".join([HEADER, *rows]) + "\n")
    T = np.eye(4)
    T[:3, 3] = LEVER
    (seq / "gps0" / "sensor.yaml").write_text(yaml.safe_dump({
        "T_BS": {"cols": 4, "rows": 4, "data": T.ravel().tolist()}, "horizontal_sigma_m": SIGMA,
        "datum": {"latitude": datum[0], "longitude": datum[1], "altitude": datum[2]}}))
    return seq


def make_run(root: Path, seq: Path, sensors: list[str]) -> Path:
    t, local = drive()
    run = root / "run"
    run.mkdir()
    write_tum(run / "wheel.tum", t, local)                                      # own frame, exact
    scaled = local.copy()
    scaled[:, :2] *= 1.05
    write_tum(run / "vo.tum", t, scaled)                                        # own frame, 5 % scale error
    write_tum(run / "gtsam.tum", t, gps_model.Alignment(HEADING, ORIGIN, 0.0, 0).apply(local))  # in ENU
    (run / "run.yaml").write_text(yaml.safe_dump({"sequence": str(seq), "sensors": sensors}))
    return run


def test_unfused_run_is_scored_after_an_se2_alignment(tmp_path, capsys):
    seq = make_sequence(tmp_path)
    run = make_run(tmp_path, seq, ["wheel", "imu"])
    assert main(["evaluate", str(run)]) == 0
    metrics = json.loads((run / "metrics.json").read_text())
    expected = SIGMA * math.sqrt(2)  # RMS of 2-D noise of SIGMA per axis
    for name in ("wheel", "gtsam"):  # both are exact tracks: the alignment absorbs their frame
        assert metrics[name]["gps_rms_m"] == pytest.approx(expected, rel=0.15)
        assert metrics[name]["gps_frame"] == "SE(2)-aligned"
    assert metrics["wheel"]["gps_alignment_yaw_deg"] == pytest.approx(30.0, abs=0.2)
    assert metrics["vo"]["gps_rms_m"] > 4 * expected  # a 5 % scale error is not aligned away
    assert metrics["wheel"]["gps_fixes"] == 301
    out = capsys.readouterr().out
    assert "against GPS fixes" in out and "SE(2)-aligned" in out
    html = (run / "report.html").read_text()
    assert "Errors against GPS fixes" in html and "Errors against ground truth" not in html
    assert "GPS fixes in ENU" in html and (run / "gps.png").stat().st_size > 10_000
    # every picture of the run is marked as fusion-vo's (a later run may replace it, never a user's own)
    assert {p.name: png_software(p) for p in run.glob("*.png")} == {p.name: PNG_SOFTWARE for p in run.glob("*.png")}


def test_fused_run_is_scored_in_enu_without_alignment(tmp_path):
    seq = make_sequence(tmp_path)
    run = make_run(tmp_path, seq, ["wheel", "imu", "gps"])
    assert main(["evaluate", str(run)]) == 0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["gtsam"]["gps_rms_m"] == pytest.approx(SIGMA * math.sqrt(2), rel=0.15)
    assert metrics["gtsam"]["gps_frame"] == "ENU (GPS fused)"
    assert metrics["wheel"]["gps_rms_m"] > 3.0  # in its own frame, 30 deg and 4.5 m away from ENU


def test_a_jump_in_the_fixes_shows_in_the_max_not_the_median(tmp_path):
    seq = make_sequence(tmp_path, jump=True)
    run = make_run(tmp_path, seq, ["gps"])
    assert main(["evaluate", str(run)]) == 0
    figures = json.loads((run / "metrics.json").read_text())["gtsam"]
    assert figures["gps_max_m"] == pytest.approx(20.0, abs=0.3)
    assert figures["gps_median_m"] < 3 * SIGMA
    assert figures["gps_outliers"] == 1
    assert figures["gps_rms_inliers_m"] == pytest.approx(SIGMA * math.sqrt(2), rel=0.15)
    # the alignment of an unfused track is not bent by the jump
    run2 = tmp_path / "unfused"
    run.rename(run2)
    (run2 / "run.yaml").write_text(yaml.safe_dump({"sequence": str(seq), "sensors": ["wheel"]}))
    assert main(["evaluate", str(run2)]) == 0
    figures = json.loads((run2 / "metrics.json").read_text())["wheel"]
    assert figures["gps_alignment_yaw_deg"] == pytest.approx(30.0, abs=0.2)
    assert figures["gps_outliers"] == 1 and figures["gps_median_m"] < 3 * SIGMA


def test_recording_with_neither_ground_truth_nor_gps_gives_a_report_without_accuracy(tmp_path, capsys):
    seq = make_sequence(tmp_path)
    run = make_run(tmp_path, seq, ["wheel"])
    (seq / "gps0" / "data.csv").unlink()
    assert main(["evaluate", str(run)]) == 0
    assert "note: The recording has no ground truth and no GPS fixes: no accuracy figures" in capsys.readouterr().out
    assert not (run / "metrics.json").exists() and (run / "report.html").is_file()
    # asked for explicitly, such a recording is an error
    assert main(["evaluate", str(run), "--gt", str(seq)]) == 2
    assert "no ground truth (and no GPS fixes" in capsys.readouterr().err


def test_fixes_on_another_clock_are_a_one_line_error(tmp_path, capsys):
    seq = make_sequence(tmp_path)
    run = make_run(tmp_path, seq, ["wheel"])
    for name in ("wheel", "vo", "gtsam"):  # trajectories stamped 10^6 s later than the fixes
        p = run / f"{name}.tum"
        rows = [line.split() for line in p.read_text().splitlines() if not line.startswith("#")]
        p.write_text("".join(f"{float(r[0]) + 1e6:.9f} {' '.join(r[1:])}\n" for r in rows))
    assert main(["evaluate", str(run)]) == 2
    err = capsys.readouterr().err
    assert "gps0/data.csv: no trajectory has 3 GPS fixes within its time span" in err
    assert "another clock" in err and len(err.strip().splitlines()) == 1
    assert not (run / "metrics.json").exists()


def test_bad_gps_sensor_yaml_stops_the_evaluation_with_the_key(tmp_path, capsys):
    seq = make_sequence(tmp_path)
    run = make_run(tmp_path, seq, ["wheel"])
    (seq / "gps0" / "sensor.yaml").write_text("horizontal_sigma_m: -1\n")
    assert main(["evaluate", str(run)]) == 2
    assert "gps0/sensor.yaml: horizontal_sigma_m must be positive, not -1" in capsys.readouterr().err


def test_run_on_a_recording_without_ground_truth_scores_against_gps(tmp_path, capsys):
    import shutil

    from fusion_vo.simulation import simulate

    seq = simulate(tmp_path / "seq", profile="random", seed=4, duration=20.0, camera_rate=2.0, width=80, height=48,
                   fu=60.0, fv=60.0, cu=39.5, cv=23.5, supersample=1, gps=True, gps_jumps=[[12.0, 12.0, 0.0, 20.0]])
    shutil.rmtree(seq / "state_groundtruth_estimate0")
    assert main(["run", str(seq), "--out", str(tmp_path / "run"), "--sensors", "wheel,imu", "--backend", "ekf"]) == 0
    assert "against GPS fixes" in capsys.readouterr().out
    metrics = json.loads((tmp_path / "run" / "metrics.json").read_text())
    assert set(metrics) == {"wheel", "ekf", "ekf_smoothed"}
    assert metrics["ekf_smoothed"]["gps_outliers"] == 1
    assert metrics["ekf_smoothed"]["gps_median_m"] < 0.1  # 5 cm noise per axis plus the fused track's drift
    assert (tmp_path / "run" / "gps.png").is_file()
