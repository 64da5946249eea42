"""What ``fusion-vo`` loads: each command line run in a fresh interpreter that reports which of the watched modules
``sys.modules`` then holds (``test_startup.py``).

``python tests/end_to_end/startup_job.py RECORDING FOLDER`` makes, in FOLDER, a copy of the recording without its
ground truth and one without its IMU too, runs the three probes of
``test_camera_only_run_loads_no_backend_library`` on them and prints, as JSON, the folder and each probe's exit
status and modules. The session's second process runs it ahead (tests/background.py); a test run without that
process calls :func:`camera_only_runs` itself.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

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


def loaded_all(argvs) -> list[dict]:
    """The probe of each command line in ``argvs``, run side by side (each in its own interpreter)."""
    procs = [subprocess.Popen([sys.executable, "-c", PROBE, json.dumps(WATCHED), *argv], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for argv in argvs]
    out = []
    for proc in procs:
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 0, stderr[-2000:]
        out.append(json.loads(stdout.strip().splitlines()[-1]))
    return out


def camera_only_runs(recording: Path, folder: Path) -> dict:
    """The recording's camera run, the camera run without its IMU and the fused run without its IMU (module
    docstring), into ``folder``."""
    seq, no_imu = folder / "seq", folder / "no_imu"
    shutil.copytree(recording, seq)
    shutil.rmtree(seq / "state_groundtruth_estimate0")  # nothing to evaluate against
    shutil.copytree(seq, no_imu)
    shutil.rmtree(no_imu / "imu0")
    camera, without_imu, fused = loaded_all([
        ["-q", "run", str(seq), "--out", str(folder / "out"), "--backend", "none"],
        ["-q", "run", str(no_imu), "--out", str(folder / "out2"), "--backend", "none"],
        ["-q", "run", str(no_imu), "--out", str(folder / "out3"), "--backend", "all"]])
    return {"folder": str(folder), "camera": camera, "without_imu": without_imu, "fused": fused}


if __name__ == "__main__":
    print(json.dumps(camera_only_runs(Path(sys.argv[1]), Path(sys.argv[2]))))
