"""A pause in every stream (fusion_vo.backends.pauses): bridged by the camera's increment across it, or the
estimate split there and its pieces chained; never a node inside it."""

from __future__ import annotations

import numpy as np
import pytest

from fusion_vo.backends import fuse
from fusion_vo.backends.pauses import Pause, chain, find_pauses, pause_notes, split
from fusion_vo.backends.result import FusionResult
from fusion_vo.backends.timeline import SensorStreams
from fusion_vo.errors import InputError
from fusion_vo.measurements import PoseData, RangeData, VisualIncrement


def inc(t0, t1, delta, ok=True):
    return VisualIncrement(t0, t1, np.asarray(delta, float), np.diag([1e-6, 1e-6, 1e-6]), status="ok" if ok else "lost")


def piece(t, poses, sigma):
    r = FusionResult()
    r.trajectories["ekf"] = PoseData(np.asarray(t, float), np.asarray(poses, float))
    r.covariances["ekf"] = np.array([np.eye(3) * s ** 2 for s in sigma])
    return r


def drive(across_ok: bool, pause_s: float = 3600.0) -> list[VisualIncrement]:
    """2 s at 0.1 m/s (10 Hz frames), a pause, 2 s more; the frames either side match when ``across_ok``."""
    before = [inc(0.1 * k, 0.1 * (k + 1), [0.01, 0, 0]) for k in range(20)]
    t = 2.0 + pause_s
    after = [inc(t + 0.1 * k, t + 0.1 * (k + 1), [0.01, 0, 0]) for k in range(20)]
    return before + [inc(2.0, t, [0.5, 0, 0], ok=across_ok)] + after


def test_pauses_are_where_no_stream_has_a_sample_and_the_streams_are_cut_there():
    visual = [inc(0.0, 0.1, [0.1, 0, 0]), inc(0.1, 0.2, [0.1, 0, 0]), inc(0.2, 10.0, [0.1, 0, 0]),
              inc(10.0, 10.1, [0.1, 0, 0], ok=False)]
    rng = RangeData(np.array([0.05, 0.15, 0.3, 10.05]), np.full(4, 0.1))  # 0.3: no pause between 0.2 and 0.3
    streams = SensorStreams(visual=visual, range=rng)
    [p] = find_pauses(streams, max_gap=0.25)
    assert (p.start, p.end) == (0.3, 10.0)
    assert p.join is visual[2]  # the frontend's increment across the pause
    a, b = split(streams, [p])
    assert a.visual == visual[:2] and list(a.range.t) == [0.05, 0.15, 0.3]
    assert b.visual == visual[3:] and list(b.range.t) == [10.05]
    assert find_pauses(streams, max_gap=10.0) == []


def test_an_hour_the_camera_measured_across_costs_no_nodes():
    result = fuse(SensorStreams(visual=drive(across_ok=True)), "ekf")
    track = result.trajectories["ekf"]
    assert len(track) == 42  # the frames; before, the grid filled the hour at 20 Hz (72,000 nodes)
    np.testing.assert_allclose(track.xyyaw[-1, 0], 0.9, atol=1e-3)  # 0.2 + the camera's 0.5 + 0.2
    assert [(p["joined"], round(p["seconds"])) for p in result.pauses] == [("camera", 3600)]
    assert result.notes[0].startswith("pause: no sample in any stream for 3600.00 s from t=2.00")
    assert "the camera's increment across it joins the estimate" in result.notes[0]


def test_an_hour_nothing_measured_across_splits_the_estimate_at_the_last_pose():
    result = fuse(SensorStreams(visual=drive(across_ok=False)), "ekf")
    for name in ("ekf", "ekf_smoothed"):
        track = result.trajectories[name]
        assert len(track) == 42 and np.all(np.diff(track.t) > 0)
        gap = int(np.argmax(np.diff(track.t)))
        np.testing.assert_allclose(track.xyyaw[gap + 1], track.xyyaw[gap], atol=1e-9)  # held, no motion invented
        np.testing.assert_allclose(track.xyyaw[-1, 0], 0.4, atol=1e-3)
    assert [p["joined"] for p in result.pauses] == ["held"]
    assert result.notes[0].startswith("pause: no sample in any stream for 3600.00 s")
    cov = result.covariances["ekf"]
    assert len(cov) == 42 and cov[-1][1, 1] > cov[20][1, 1]  # the second piece's uncertainty adds to the first's


def test_samples_all_cut_off_from_each_other_are_a_clear_error():
    sparse = RangeData(np.arange(5) * 1.0, np.full(5, 0.1))
    with pytest.raises(InputError, match="raise fusion.max_gap"):
        fuse(SensorStreams(range=sparse, camera_height=0.1), "ekf")


def test_a_held_piece_starts_at_the_last_pose_and_keeps_its_covariance():
    first = piece([0, 1], [[0, 0, 0], [1, 0, np.pi / 2]], [0.0, 0.1])
    second = piece([5, 6], [[0, 0, 0], [1, 0, 0]], [0.0, 0.2])  # 1 m ahead of where it started
    tracks, covs, joined = chain([first, second], [Pause(1.0, 5.0)], [False, False])
    xyyaw = tracks["ekf"].xyyaw
    np.testing.assert_allclose(xyyaw[2], [1, 0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(xyyaw[3], [1, 1, np.pi / 2], atol=1e-12)  # turned with the start's heading
    # x, y of the last pose: the start's covariance, moved by the start's heading error over the 1 m lever,
    # plus the piece's own rotated into the world
    expected = np.diag([0.1 ** 2 + 0.1 ** 2 + 0.2 ** 2, 0.1 ** 2 + 0.2 ** 2, 0.1 ** 2 + 0.2 ** 2])
    expected[0, 2] = expected[2, 0] = -0.1 ** 2
    np.testing.assert_allclose(covs["ekf"][3], expected, atol=1e-12)
    assert joined == [{"start": 1.0, "end": 5.0, "seconds": 4.0, "joined": "held"}]
    # a piece its own GPS fixes placed is taken as it is
    tracks, _, joined = chain([first, second], [Pause(1.0, 5.0)], [False, True])
    np.testing.assert_allclose(tracks["ekf"].xyyaw[3], [1, 0, 0], atol=1e-12)
    assert joined[0]["joined"] == "gps"


def test_a_slow_camera_alone_gets_one_note_for_all_its_gaps():
    entries = [{"start": float(k), "end": k + 0.5, "seconds": 0.5, "joined": "camera"} for k in range(10)]
    entries.append({"start": 20.0, "end": 30.0, "seconds": 10.0, "joined": "held"})
    notes = pause_notes(entries, 0.0)
    assert len(notes) == 2 and notes[0].startswith("pause: 10 times") and "split" in notes[1]


def test_a_camera_slower_than_max_gap_alone_is_bridged_on_its_increments():
    frames = [inc(0.5 * k, 0.5 * (k + 1), [0.05, 0, 0]) for k in range(10)]  # 2 Hz: every gap a pause
    result = fuse(SensorStreams(visual=frames), "ekf")
    track = result.trajectories["ekf"]
    assert len(track) == 11
    np.testing.assert_allclose(track.xyyaw[-1, 0], 0.5, atol=1e-3)
    assert {p["joined"] for p in result.pauses} == {"camera"} and len(result.pauses) == 10
    assert [n for n in result.notes if n.startswith("pause:")] == [result.notes[0]]  # one note for all ten
