"""Start-up cost: a camera-only run imports neither GTSAM nor matplotlib nor evo."""

import json
import shutil
import subprocess
import sys

import pytest

PROBE = """
import json, sys
from fusion_vo.cli.main import main
code = main(sys.argv[1:])
heavy = sorted({m.split('.')[0] for m in sys.modules} & {'gtsam', 'matplotlib', 'evo'})
print(json.dumps({'code': code, 'heavy': heavy}))
"""


def _imports(argv):
    out = subprocess.run([sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.slow
def test_run_without_fusion_imports_no_gtsam_matplotlib_or_evo(standard_recording, tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(standard_recording("short"), seq)
    shutil.rmtree(seq / "state_groundtruth_estimate0")  # nothing to evaluate against
    got = _imports(["-q", "run", str(seq), "--out", str(tmp_path / "out"), "--backend", "none"])
    assert got == {"code": 0, "heavy": []}
    assert (tmp_path / "out" / "vo.tum").is_file()
    # the same probe sees GTSAM when the run does fuse with it (the probe can fail)
    got = _imports(["-q", "run", str(seq), "--out", str(tmp_path / "out2"), "--backend", "gtsam"])
    assert got["code"] == 0 and "gtsam" in got["heavy"]


def test_help_imports_no_gtsam_matplotlib_or_evo():
    probe = PROBE.replace("code = main(sys.argv[1:])", "code = 0\nfrom fusion_vo.cli.main import build_parser\nbuild_parser()")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1])["heavy"] == []
