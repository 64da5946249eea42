"""Start-up cost: what the command loads.

A camera-only run imports neither GTSAM, matplotlib and evo nor the EKF's filterpy and scipy.stats;
without an IMU it does not need scipy at all. ``--help`` loads neither numpy nor OpenCV. Each probe runs
the command in a fresh interpreter and reports which of the watched modules ``sys.modules`` holds.
"""

import json
import shutil
import subprocess
import sys

import pytest

WATCHED = ["gtsam", "matplotlib", "evo", "filterpy", "scipy", "scipy.stats", "scipy.spatial", "numpy", "cv2",
           "pydantic"]

PROBE = """
import json, sys
from fusion_vo.cli.main import main
try:
    code = main(sys.argv[2:])
except SystemExit as exc:  # --help
    code = exc.code
print(json.dumps({'code': code, 'loaded': sorted(set(json.loads(sys.argv[1])) & set(sys.modules))}))
"""


def _loaded(argv):
    return _loaded_all([argv])[0]


def _loaded_all(argvs):
    """The probe of each command line in ``argvs``, run side by side (each in its own interpreter)."""
    procs = [subprocess.Popen([sys.executable, "-c", PROBE, json.dumps(WATCHED), *argv], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for argv in argvs]
    out = []
    for proc in procs:
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 0, stderr[-2000:]
        out.append(json.loads(stdout.strip().splitlines()[-1]))
    return out


@pytest.mark.slow
def test_camera_only_run_loads_no_backend_library(standard_recording, tmp_path):
    seq, no_imu = tmp_path / "seq", tmp_path / "no_imu"
    shutil.copytree(standard_recording("short"), seq)
    shutil.rmtree(seq / "state_groundtruth_estimate0")  # nothing to evaluate against
    shutil.copytree(seq, no_imu)
    shutil.rmtree(no_imu / "imu0")
    camera, without_imu, fused = _loaded_all([
        ["-q", "run", str(seq), "--out", str(tmp_path / "out"), "--backend", "none"],
        ["-q", "run", str(no_imu), "--out", str(tmp_path / "out2"), "--backend", "none"],
        ["-q", "run", str(no_imu), "--out", str(tmp_path / "out3"), "--backend", "all"]])
    assert camera["code"] == 0 and (tmp_path / "out" / "vo.tum").is_file()
    # the IMU's derotation uses scipy's Rotation, so scipy.spatial may load, and every run draws its report
    # (matplotlib): nothing more, none of the backends' libraries
    assert set(camera["loaded"]) <= {"numpy", "cv2", "pydantic", "scipy", "scipy.spatial", "matplotlib"}
    assert (tmp_path / "out" / "report.html").is_file()
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
