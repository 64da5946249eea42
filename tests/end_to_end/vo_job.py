"""The visual odometry figures the accuracy tests check, of one recording and frontend.

``python tests/end_to_end/vo_job.py RECORDING FRONTEND`` prints them as JSON: the session's second process runs
it ahead (``python:`` jobs of ``test_vo_accuracy.py``, tests/background.py), and a test run without that process
calls :func:`figures` itself.
"""

import json
import sys

import numpy as np

from fusion_vo.odometry import OdometryConfig, run_visual_odometry
from fusion_vo.recording import Recording

from e2e_accuracy import end_errors


def figures(path, frontend: str) -> dict:
    """Failed frames, the end errors against ground truth (:func:`e2e_accuracy.end_errors`: metres, % of the path,
    degrees), the usable increments, the largest translation of one and the track's last distance from its start."""
    rec = Recording(path)
    vo = run_visual_odometry(rec, OdometryConfig(frontend=frontend))
    ok = [inc for inc in vo.increments if inc.ok]
    return {"failures": vo.failures.total(), "end": list(end_errors(vo.track, rec.groundtruth())),
            "increments": len(vo.increments), "usable": len(ok),
            "largest_translation_m": max((float(np.hypot(*inc.delta[:2])) for inc in ok), default=float("nan")),
            "last_from_start_m": float(np.hypot(*vo.track.xyyaw[-1, :2]))}


if __name__ == "__main__":
    print(json.dumps(figures(sys.argv[1], sys.argv[2])))
