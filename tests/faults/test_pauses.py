"""A pause in every stream (the robot's logger stopped for a while): never the process, never a wrong
answer, and no cost for the seconds in which nothing was recorded."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from fault_tools import cli
from fusion_vo.simulation.pause import pause

FUSED = ("ekf", "ekf_smoothed", "gtsam", "gtsam_online")


def travelled(tum: Path) -> float:
    xy = np.loadtxt(tum)[:, 1:3]
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))


def test_an_hour_long_pause_splits_the_estimate_and_costs_nothing(recording, tmp_path, capsys):
    # 33 frames, 0.05 m of straight drive, then the logger stops for an hour in the middle
    pause(recording, 0.8, 3600.0)
    out = tmp_path / "out"
    status, _, err = cli(capsys, "run", recording, "--out", out, "--backend", "all", "--no-evaluate")
    assert status == 0, err
    summary = json.loads((out / "summary.json").read_text())
    [entry] = summary["fusion"]["pauses"]
    t_first = np.loadtxt(out / "ekf.tum")[0, 0]
    assert abs(entry["start"] - t_first - 0.79) < 0.02 and abs(entry["seconds"] - 3600.0) < 0.1
    assert entry["joined"] == "camera"  # the frontend matched the frames on both sides of the pause
    assert any(n.startswith("pause: no sample in any stream for 3600.") for n in summary["notes"])
    for name in FUSED:
        track = np.loadtxt(out / f"{name}.tum")
        # nodes where there are samples (about 50 at most), none in the hour without any: work scales with
        # the samples (before, the grid filled the pause at 20 Hz: 72,000 nodes, 16 s of EKF, 100 s of iSAM2)
        assert len(track) < 80, name
        assert not np.any((track[:, 0] > entry["start"] + 1e-6) & (track[:, 0] < entry["end"] - 1e-6)), name
        assert 0.04 < travelled(out / f"{name}.tum") < 0.06, name  # the robot drove 0.05 m, not a metre more
        cov = np.loadtxt(out / f"{name}.cov.csv", delimiter=",", ndmin=2) if (out / f"{name}.cov.csv").exists() else None
        if cov is not None:
            assert len(cov) == len(track) and np.all(np.isfinite(cov))
    assert 0.04 < travelled(out / "vo.tum") < 0.06  # no rotation integrated over the pause by the derotation


def test_a_pause_nothing_measured_across_holds_the_last_pose(recording, tmp_path, capsys):
    pause(recording, 0.8, 20.0)
    # the frames after the pause are featureless: the frontend restarts after them, so nothing measures
    # the motion during the pause
    rows = (recording / "cam0" / "data.csv").read_text().splitlines()[1:]
    after = [r.split(",")[1] for r in rows if int(r.split(",")[0]) - int(rows[0].split(",")[0]) > 20e9][:5]
    for name in after:
        path = recording / "cam0" / "data" / name
        img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        cv2.imwrite(str(path), np.full_like(img, 128))
    out = tmp_path / "out"
    status, _, err = cli(capsys, "run", recording, "--out", out, "--sensors", "camera", "--backend", "ekf",
                         "--no-evaluate")
    assert status == 0, err
    summary = json.loads((out / "summary.json").read_text())
    [entry] = summary["fusion"]["pauses"]
    assert entry["joined"] == "held" and abs(entry["seconds"] - 20.0) < 0.3
    assert any("visual track held its pose for 20." in n for n in summary["notes"])
    # before, the visual track bridged the 20 s at the last velocity: 0.6 m for a 0.05 m drive
    assert travelled(out / "vo.tum") < 0.06
    assert travelled(out / "ekf.tum") < 0.06


def test_a_pause_in_every_stream_does_not_stop_the_factor_graph(recording, tmp_path, capsys):
    pause(recording, 0.8, 20.0)
    status, _, err = cli(capsys, "run", recording, "--out", tmp_path / "out", "--backend", "gtsam",
                         "--no-evaluate")
    assert status == 0, err
    assert travelled(tmp_path / "out" / "gtsam.tum") < 0.06
