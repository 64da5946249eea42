"""A heading source registered outside the library is judged by the heading monitor like the built-in ones: the
compass of compass_sensor.py declares its heading (``HeadingSource``) and nothing else changes."""

from __future__ import annotations

import numpy as np
import pytest

from ahead_job import ahead_jobs
from compass_sensor import CHECKED_COMPASS_SENSOR, CompassData

from fusion_vo.backends import FusionConfig, SensorStreams, fuse
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.geometry import se2
from fusion_vo.sensors import registry
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams

JUMP_AT = 15.0  # s into the drive: the compass's heading jumps by 0.3 rad (a magnetic disturbance) and stays off


def _drive():
    """30 s of wheels (their base 5 % off) and a gyro, and a compass (0.02 rad, 10 Hz) 0.3 rad off from 15 s on."""
    s = synthetic_streams(SyntheticOptions(duration=30.0, wheel_base_factor=1.05), seed=4)
    rng = np.random.default_rng(7)
    t = np.arange(s.truth.t[0], s.truth.t[-1], 0.1)
    yaw = np.interp(t, s.truth.t, np.unwrap(s.truth.xyyaw[:, 2])) + rng.normal(0.0, 0.02, len(t))
    yaw[t >= s.truth.t[0] + JUMP_AT] += 0.3
    return s, CompassData(t, se2.wrap_angle(yaw))


@pytest.fixture(scope="module")
def drive():
    """:func:`_drive`"""
    return _drive()


def _heading_rms(track, truth, after: float) -> float:
    keep = track.t >= after
    yaw = np.interp(track.t[keep], truth.t, np.unwrap(truth.xyyaw[:, 2]))
    return float(np.sqrt(np.mean(se2.wrap_angle(track.xyyaw[keep, 2] - yaw) ** 2)))


def test_the_monitor_drops_a_registered_heading_that_jumps(drive):
    """Fails if the monitor does not take the compass as a source (the fused heading then follows the jump: 0.24 rad
    RMS after it with the EKF, 0.29 with GTSAM, measured; 0.006 with the check) or takes it back once its heading
    changes agree again (its heading stays 0.3 rad off: the absolute check)."""
    s, compass = drive
    t0 = float(s.truth.t[0])
    with registry.registered(CHECKED_COMPASS_SENSOR):
        streams = SensorStreams(wheel=s.wheel, imu=s.imu, compass=compass).select(["wheel", "imu", "compass"])
        checked = fuse(streams, "all", FusionConfig.from_dict({"compass": {"sigma": 0.02}}))
        unchecked = fuse(streams, "all", FusionConfig.from_dict({"compass": {"sigma": 0.02}, "monitor": False}))
    episodes = [e for e in checked.inconsistent if e["sensor"] == "compass"]
    assert len(episodes) == 1 and episodes[0]["component"] == "compass heading", checked.inconsistent
    # the check's windows are 2, 10 and 30 s: the 10 s window that holds the jump (from 10 s) is dropped whole
    assert t0 + 10.0 - 0.1 <= episodes[0]["start"] <= t0 + JUMP_AT
    assert episodes[0]["end"] == pytest.approx(float(s.truth.t[-1]), abs=0.2)
    assert any(n.startswith("compass compass heading inconsistent with gyro") for n in checked.notes), checked.notes
    for name in ("ekf", "gtsam"):
        after = t0 + JUMP_AT + 1.0
        ours, theirs = (_heading_rms(r.trajectories[name], s.truth, after) for r in (checked, unchecked))
        assert ours < 0.02 and theirs > 0.2, (name, ours, theirs)


def _streamed(backend: str, track: str) -> dict:
    """The drive streamed by ``backend`` with the live monitor on and off: the start, the end of the drive, the
    compass's episodes (monitor on) and the heading's RMS error after the jump (on, off)."""
    s, compass = _drive()
    t0 = float(s.truth.t[0])
    with registry.registered(CHECKED_COMPASS_SENSOR):
        streams = SensorStreams(wheel=s.wheel, imu=s.imu, compass=compass).select(["wheel", "imu", "compass"])
        results = {}
        for monitor in (True, False):
            fusion = streaming_for(streams, backend, FusionConfig.from_dict({"compass": {"sigma": 0.02},
                                                                             "monitor": monitor}))
            fusion.feed(time_ordered_messages(streams))
            results[monitor] = fusion.finish()
    after = t0 + JUMP_AT + 2.0  # (the check runs every monitor_window / 2 of data: the jump is used until then)
    return {"t0": t0, "end": float(s.truth.t[-1]), "inconsistent": results[True].inconsistent,
            "rms": [_heading_rms(results[m].trajectories[track], s.truth, after) for m in (True, False)]}


AHEAD = {"streamed_ekf": lambda: _streamed("ekf", "ekf"), "streamed_gtsam": lambda: _streamed("gtsam", "gtsam_online")}
BACKGROUND_COMMANDS, BACKGROUND_JOBS = ahead_jobs(__file__)


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_the_live_monitor_drops_a_registered_heading_that_jumps(made_ahead, backend):
    """The same drive streamed: the live monitor windows the compass's headings (a tuple of arrays on the node grid,
    no registered container) and drops them once a check sees the jump (measured: 0.008 rad RMS after it, both
    backends; the stream with the monitor off follows the jump). Fails if the live monitor keeps only the newest
    interval of a sensor without a registered container (the compass's ``drop`` then meets arrays of another
    length: a ValueError)."""
    made = made_ahead(f"streamed_{backend}")
    t0 = made["t0"]
    episodes = [e for e in made["inconsistent"] if e["sensor"] == "compass"]
    assert len(episodes) == 1 and episodes[0]["component"] == "compass heading", made["inconsistent"]
    # decided causally: within the windows that hold the jump, and to the end
    assert t0 + 10.0 - 0.1 <= episodes[0]["start"] <= t0 + JUMP_AT + 2.0, episodes
    assert episodes[0]["end"] == pytest.approx(made["end"], abs=0.2)
    ours, theirs = made["rms"]
    assert ours < 0.02 and theirs > 0.2, (ours, theirs)


