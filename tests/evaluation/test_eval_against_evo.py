"""The figures agree with evo's own command-line tools on the same files."""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fusion_vo.evaluation.io import read_groundtruth, read_tum
from fusion_vo.evaluation.metrics import evaluate_trajectory

from eval_synthetic import distorted, square_path, write_groundtruth, write_tum

BIN = Path(sys.executable).parent


def evo(tool: str, *args: str) -> float:
    """Run an evo tool and return the RMSE it prints (to 6 decimals)."""
    exe = BIN / tool
    if not exe.exists():
        exe = shutil.which(tool)
    if exe is None:
        pytest.skip(f"{tool} not installed")
    out = subprocess.run([str(exe), *args, "--no_warnings"], capture_output=True, text=True, check=True).stdout
    return float(re.search(r"rmse\s+([-+0-9.eE]+)", out).group(1))


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    root = tmp_path_factory.mktemp("evo")
    t, x, y, yaw = square_path()
    gt = write_groundtruth(root / "seq", t, x, y, yaw)
    est = write_tum(root / "vo.tum", *distorted(t, x, y, yaw, scale=1.04, yaw_rate_bias=0.01, step=2))
    figures = evaluate_trajectory(read_groundtruth(gt), read_tum(est)).figures
    return str(gt), str(est), figures


SYNC = ["--sync_method", "interpolation", "--t_max_diff", "0.02"]


def test_ate_matches_evo_ape(files):
    gt, est, figures = files
    assert figures["ate_m"] > 0.01
    assert figures["ate_m"] == pytest.approx(evo("evo_ape", "euroc", gt, est, "-a", *SYNC), abs=2e-6)
    assert figures["ate_anchored_m"] == pytest.approx(evo("evo_ape", "euroc", gt, est, "--align_origin", *SYNC),
                                                      abs=2e-6)


def test_rpe_matches_evo_rpe(files):
    gt, est, figures = files
    pairs = ["--all_pairs", "--pairs_from_reference"]
    assert figures["rpe_1m_m"] == pytest.approx(
        evo("evo_rpe", "euroc", gt, est, "-d", "1", "-u", "m", *pairs, *SYNC), abs=2e-6)
    assert figures["rpe_frame_m"] == pytest.approx(
        evo("evo_rpe", "euroc", gt, est, "-d", "1", "-u", "f", "--pairs_from_reference", *SYNC), abs=2e-6)
    assert figures["rpe_frame_deg"] == pytest.approx(
        evo("evo_rpe", "euroc", gt, est, "-d", "1", "-u", "f", "-r", "angle_deg", *SYNC), abs=2e-6)
