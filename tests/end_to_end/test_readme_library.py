"""The README's "As a library" block runs as written on a generated recording, and its comments hold."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from fusion_vo.backends.batch import streams_from_recording
from fusion_vo.backends.streaming import time_ordered_messages

README = Path(__file__).resolve().parents[2] / "README.md"
#: the standard recording the block is run on (made once per session, tests/conftest.py)
BACKGROUND_JOBS = {"*": ["standard:short"]}


def readme_block() -> str:
    """The Python block of the README's "As a library" section."""
    text = README.read_text()
    section = text[text.index("## As a library"):]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_readme_library_block_runs_and_its_live_estimate_follows_the_samples(standard_recording):
    rec_path = standard_recording("short")
    code = readme_block()
    assert 'Recording("rec/")' in code
    space: dict = {}
    exec(compile(code.replace('"rec/"', repr(f"{rec_path}/")), str(README), "exec", dont_inherit=True), space)
    rec, vo, fused, live = space["rec"], space["vo"], space["fused"], space["live"]
    truth = rec.groundtruth()

    # the batch part: visual odometry with a covariance per increment, then the fused trajectories
    assert len(vo.increments) >= 0.9 * (len(rec) - 1)
    assert all(np.all(np.isfinite(inc.covariance)) for inc in vo.increments if inc.ok)
    t_end = float(truth.t[-1])
    true_end = np.array([np.interp(t_end, truth.t, truth.xyyaw[:, k]) for k in (0, 1)])
    assert np.linalg.norm(true_end) > 0.1  # the robot moves 0.13 m, from the origin of the track's frame
    for name in ("gtsam", "gtsam_online"):
        track = fused.trajectories[name]
        # the fused track ends where the robot does (measured: 0.01 mm off; the wheels alone 0.25 mm)
        assert track.t[-1] == t_end and np.linalg.norm(track.xyyaw[-1, :2] - true_end) < 1e-3, name

    # the live part: nothing before the first sample; then, fed the wheels and the IMU as they come, the pose
    # predicted to now and its covariance
    assert live.current_estimate() is None
    streams = streams_from_recording(rec, None, ["wheel", "imu"])
    kinds = set()
    for _, kind, sample in time_ordered_messages(streams):
        kinds.add(kind)
        getattr(live, f"add_{kind}")(sample)  # live.add_wheel(ticks), live.add_imu(sample)
    assert kinds == {"wheel", "imu"}
    estimate = live.current_estimate()
    assert estimate is not None and estimate.covariance.shape == (3, 3)
    # wheels and gyro over the 5 s drive: their end as in the batch run's wheel track (0.25 mm off), where a
    # sample left out or a wrong prediction lands centimetres away
    assert abs(estimate.t - t_end) < 0.05, (estimate.t, t_end)
    assert np.linalg.norm(np.asarray(estimate.pose[:2]) - true_end) < 2e-3, (estimate.pose, true_end)
