"""The command line on generated recordings: demo, run with a damaged frame, outputs complete or absent."""

import json
import shutil

import numpy as np
import pytest

from fusion_vo.cli.main import main
from fusion_vo.evaluation.io import read_tum
from fusion_vo.recording import Recording

#: ``fusion-vo demo`` and the recording the other tests copy and break, made ahead in the background
#: (tests/background.py)
BACKGROUND_COMMANDS = {"demo": ["demo", "--out", "{out}"]}
BACKGROUND_JOBS = {"test_demo_prints_accuracy_and_writes_plot": ["fusion-vo:demo"],
                   "test_corrupt_frame_is_skipped_and_counted": ["standard:short"]}


@pytest.mark.slow
def test_demo_prints_accuracy_and_writes_plot(background, tmp_path, capsys):
    if background is not None and "fusion-vo:demo" in background:
        job = background.result("fusion-vo:demo")  # (exit status 0 checked there)
        out, demo = job.stdout, job.out
    else:
        assert main(["demo", "--out", str(tmp_path / "demo")]) == 0
        out, demo = capsys.readouterr().out, tmp_path / "demo"
    assert "Position errors" in out and "gtsam" in out
    run = demo / "run"
    for name in ("vo.tum", "wheel.tum", "ekf.tum", "ekf_smoothed.tum", "gtsam.tum", "gtsam_online.tum",
                 "velocities.csv", "metrics.json", "trajectories.png", "report.html"):
        assert (run / name).is_file(), name
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["vo"]["end_pct"] < 0.2 and metrics["gtsam"]["end_pct"] < 0.5


@pytest.mark.slow
def test_corrupt_frame_is_skipped_and_counted(standard_recording, tmp_path, capsys):
    src = standard_recording("short")
    seq = tmp_path / "seq"
    shutil.copytree(src, seq)
    frames = sorted((seq / "cam0" / "data").iterdir())
    frames[len(frames) // 2].write_bytes(b"\x89PNG\r\n\x1a\n broken")
    assert main(["run", str(seq), "--out", str(tmp_path / "out"), "--backend", "none"]) == 0
    out = capsys.readouterr().out
    assert "1 skipped (unreadable)" in out
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["skipped_frames"] == 1 and summary["frames"] == len(frames) - 1
    vel = (tmp_path / "out" / "velocities.csv").read_text().splitlines()
    assert vel[0] == "t,vx,vy,yaw_rate,status,inliers,height_ratio" and len(vel) == len(frames)
    ratios = np.array([float(row.split(",")[-1]) for row in vel[2:]])
    assert np.nanmax(np.abs(ratios - 1.0)) < 2e-3  # the simulated camera height does not change


@pytest.mark.slow
def test_failed_run_leaves_no_output(standard_recording, tmp_path):
    src = standard_recording("short")
    seq = tmp_path / "seq"
    shutil.copytree(src, seq)
    lines = (seq / "imu0" / "data.csv").read_text().splitlines()
    lines[50] = lines[50].split(",")[0] + ",nan,0,0,0,0,9.8"
    (seq / "imu0" / "data.csv").write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    assert main(["run", str(seq), "--out", str(out)]) == 2
    assert not out.exists()  # the inputs are checked before any work
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]


@pytest.mark.slow
def test_wheel_and_imu_only_run_needs_no_camera(standard_recording, tmp_path):
    src = standard_recording("short")
    seq = tmp_path / "seq"
    shutil.copytree(src, seq, ignore=shutil.ignore_patterns("cam0"))
    assert Recording(seq).streams() == ["imu0", "state_groundtruth_estimate0", "wheel0"]
    assert main(["run", str(seq), "--out", str(tmp_path / "out"), "--backend", "ekf"]) == 0
    ekf = read_tum(tmp_path / "out" / "ekf.tum")
    assert ekf.num_poses > 10 and np.all(np.isfinite(ekf.positions_xyz))
    assert main(["run", str(seq), "--out", str(tmp_path / "o2"), "--sensors", "camera,wheel"]) == 2
