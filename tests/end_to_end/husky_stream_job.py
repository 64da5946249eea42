"""robot_localization's Husky log (test1.bag imported without its IMU transform) through streaming fusion.

``python tests/end_to_end/husky_stream_job.py RECORDING`` prints, as JSON, what
``test_robot_logs.py::test_husky_imu_imported_without_its_mounting_is_found_while_streaming`` checks: the streaming
EKF's notes, the IMU's first sample time and the track's RMS distance from the GPS fixes. The session's second
process runs it ahead (tests/background.py); a test run without that process calls :func:`figures` itself.
"""

import json
import sys

import numpy as np

from fusion_vo.backends.batch import streams_from_recording
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.evaluation.metrics import gps_errors
from fusion_vo.recording import Recording
from fusion_vo.sensors.gps import read_fixes


def figures(path) -> dict:
    """The wheel odometry and the IMU of ``path`` fed in time order to the streaming EKF (module docstring)."""
    streams = streams_from_recording(Recording(path), None, ["odom", "imu"])
    fusion = streaming_for(streams, "ekf")
    fusion.feed(time_ordered_messages(streams))
    result = fusion.finish()
    errors = gps_errors(result.trajectories["ekf"], read_fixes(Recording(path)))
    return {"notes": list(result.notes), "imu_t0": float(streams.imu.t[0]),
            "gps_rms_m": float(np.sqrt(np.mean(errors**2)))}


if __name__ == "__main__":
    print(json.dumps(figures(sys.argv[1])))
