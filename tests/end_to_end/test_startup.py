"""Start-up cost: what the command loads.

A camera-only run imports neither GTSAM, matplotlib and evo nor the EKF's filterpy and scipy.stats;
without an IMU it does not need scipy at all. ``--help`` loads neither numpy nor OpenCV. Each probe runs
the command in a fresh interpreter and reports which of the watched modules ``sys.modules`` holds.
"""

import subprocess
import sys
from pathlib import Path

import pytest
from startup_job import camera_only_runs, loaded_all

#: the camera-only probes, run from the session's start in the background (tests/background.py) or else by the test
BACKGROUND_COMMANDS = {"python:startup_probes": ["{repo}/tests/end_to_end/startup_job.py", "{standard:short}", "{out}"]}
BACKGROUND_JOBS = {"test_camera_only_run_loads_no_backend_library": ["standard:short", "python:startup_probes"]}


def _loaded(argv):
    return loaded_all([argv])[0]


@pytest.mark.slow
def test_camera_only_run_loads_no_backend_library(standard_recording, ahead_json, tmp_path):
    runs = ahead_json("python:startup_probes",
                      lambda: camera_only_runs(standard_recording("short"), tmp_path / "probes"))
    folder = Path(runs["folder"])
    camera, without_imu, fused = runs["camera"], runs["without_imu"], runs["fused"]
    assert camera["code"] == 0 and (folder / "out" / "vo.tum").is_file()
    # the IMU's derotation uses scipy's Rotation, so scipy.spatial may load, and every run draws its report
    # (matplotlib): nothing more, none of the backends' libraries
    assert set(camera["loaded"]) <= {"numpy", "cv2", "pydantic", "scipy", "scipy.spatial", "matplotlib"}
    assert (folder / "out" / "report.html").is_file()
    assert {"numpy", "cv2"} <= set(camera["loaded"])  # the probe does see what the run loads
    # without an IMU (camera and wheels) scipy is needed only for the report to read its tracks' headings
    assert without_imu["code"] == 0 and set(without_imu["loaded"]) == {"numpy", "cv2", "pydantic", "matplotlib",
                                                                        "scipy", "scipy.spatial"}
    # the same probe sees the EKF's and GTSAM's libraries when the run does fuse
    assert fused["code"] == 0 and {"gtsam", "filterpy", "scipy.stats"} <= set(fused["loaded"])


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["bench", "--help"]])
def test_help_loads_neither_numpy_nor_opencv(argv):
    got = _loaded(argv)
    assert got == {"code": 0, "loaded": []}


def test_simulate_help_still_lists_the_profiles():
    out = subprocess.run([sys.executable, "-m", "fusion_vo.cli.main", "simulate", "--help"], capture_output=True,
                         text=True, check=True).stdout
    assert "random" in out and "umbmark_cw" in " ".join(out.split()) and "random60" in out
    bad = subprocess.run([sys.executable, "-m", "fusion_vo.cli.main", "simulate", "x", "--profile", "bogus"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and "invalid choice: 'bogus'" in bad.stderr and "'square'" in bad.stderr
