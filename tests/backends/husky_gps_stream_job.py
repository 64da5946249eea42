"""robot_localization's Husky log (test1.bag with its launch file's IMU transform), first 120 s, streamed to both
backends with the GPS fixes of its first minute.

``python tests/backends/husky_gps_stream_job.py RECORDING`` prints, as JSON, what
``test_gps_fusion.py::test_husky_streamed_with_the_gps_of_the_first_minute`` checks: per backend, how often the world
frame switched to ENU, the fixes' counts, and the antenna's RMS distance to the fused fixes and to the withheld ones.
The session's second process runs it ahead (tests/background.py); a test run without that process calls
:func:`figures` itself.
"""

import json
import sys

import numpy as np

from fusion_vo.backends import streams_from_recording
from fusion_vo.backends.pauses import samples_between
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.recording import Recording
from fusion_vo.sensors import gps as gps_model
from fusion_vo.sensors.gps import read_fixes


def husky_parts(path):
    """The odometry and IMU of the first 120 s, the fixes of the first 60 s and those of the next 60 s."""
    rec = Recording(path)
    gps = read_fixes(rec)
    t0 = float(gps.t[0])
    base = streams_from_recording(rec, None, ["odom", "imu"])
    part = base.replace(odom=samples_between(base.odom, -np.inf, t0 + 120.0),
                        imu=samples_between(base.imu, -np.inf, t0 + 120.0))
    first = samples_between(gps, -np.inf, t0 + 60.0)
    second = samples_between(gps, np.nextafter(t0 + 60.0, np.inf), t0 + 120.0)  # (after the first minute's last)
    return part, first, second


def withheld_rms(track, fixes) -> float:
    """RMS distance [m] of the antenna on ``track`` from ``fixes``."""
    t = fixes.t
    pose = np.column_stack([np.interp(t, track.t, track.xyyaw[:, i]) for i in range(2)]
                           + [np.interp(t, track.t, np.unwrap(track.xyyaw[:, 2]))])
    err = gps_model.predict(pose, fixes.lever_arm) - fixes.enu[:, :2]
    return float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))


def figures(path) -> dict:
    """Both backends fed the first 120 s in time order with the first minute's fixes (2 m sigma floor)."""
    part, first, second = husky_parts(path)
    out = {"n_fixes": len(first.t)}
    for backend, name in (("ekf", "ekf"), ("gtsam", "gtsam_online")):
        fusion = streaming_for(part.replace(gps=first), backend, config={"gps": {"min_sigma": 2.0}})
        fusion.feed(time_ordered_messages(part.replace(gps=first)))
        result = fusion.finish()
        track = result.trajectories[name]
        out[backend] = {"switches": sum("re-expressed in ENU" in n for n in result.notes),
                        "counts": result.counts[name]["gps"].as_dict(),
                        "fused_rms": withheld_rms(track, first), "withheld_rms": withheld_rms(track, second)}
    return out


if __name__ == "__main__":
    print(json.dumps(figures(sys.argv[1])))
