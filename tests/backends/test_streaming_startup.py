"""Start-up costs are paid when a StreamingFusion is made, not inside its first add() call."""

import subprocess
import sys

CODE = """
import sys
from fusion_vo.backends import StreamingFusion
assert "gtsam" not in sys.modules  # importing the package does not import GTSAM
StreamingFusion("ekf", sensors=["camera"])
assert "gtsam" not in sys.modules  # nor does an EKF stream
StreamingFusion("gtsam", sensors=["camera"])
assert "gtsam" in sys.modules and "fusion_vo.backends.graph" in sys.modules
"""


def test_isam2_stream_imports_gtsam_when_made():
    out = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
