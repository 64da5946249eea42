"""Chaining the pieces of an estimate split at a pause in every stream (fusion_vo.backends.pauses)."""

from __future__ import annotations

import numpy as np

from fusion_vo.backends.pauses import chain, find_pauses, split
from fusion_vo.backends.result import FusionResult
from fusion_vo.backends.timeline import SensorStreams
from fusion_vo.measurements import PoseData, RangeData, VisualIncrement


def inc(t0, t1, delta, ok=True):
    return VisualIncrement(t0, t1, np.asarray(delta, float), np.diag([1e-4, 1e-4, 1e-4]), status="ok" if ok else "lost")


def piece(t, poses, sigma):
    r = FusionResult()
    r.trajectories["ekf"] = PoseData(np.asarray(t, float), np.asarray(poses, float))
    r.covariances["ekf"] = np.array([np.eye(3) * s ** 2 for s in sigma])
    return r


def test_pauses_are_where_no_stream_has_a_sample_and_the_streams_are_cut_there():
    visual = [inc(0.0, 0.1, [0.1, 0, 0]), inc(0.1, 0.2, [0.1, 0, 0]), inc(0.2, 10.0, [0.1, 0, 0]),
              inc(10.0, 10.1, [0.1, 0, 0], ok=False)]
    rng = RangeData(np.array([0.05, 0.15, 0.3, 10.05]), np.full(4, 0.1))  # 0.3: no pause between 0.2 and 0.3
    streams = SensorStreams(visual=visual, range=rng)
    [p] = find_pauses(streams, max_gap=0.25)
    assert (p.start, p.end) == (0.3, 10.0)
    assert p.join is visual[2]  # the frontend's increment across the pause joins the pieces
    a, b = split(streams, [p])
    assert a.visual == visual[:2] and list(a.range.t) == [0.05, 0.15, 0.3]
    assert b.visual == visual[3:] and list(b.range.t) == [10.05]
    assert find_pauses(streams, max_gap=10.0) == []


def test_a_held_piece_starts_at_the_last_pose_and_keeps_its_covariance():
    first = piece([0, 1], [[0, 0, 0], [1, 0, np.pi / 2]], [0.0, 0.1])
    second = piece([5, 6], [[0, 0, 0], [1, 0, 0]], [0.0, 0.2])  # 1 m ahead of where it started
    from fusion_vo.backends.pauses import Pause

    tracks, covs, joined = chain([first, second], [Pause(1.0, 5.0)], [True, False])
    xyyaw = tracks["ekf"].xyyaw
    np.testing.assert_allclose(xyyaw[2], [1, 0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(xyyaw[3], [1, 1, np.pi / 2], atol=1e-12)  # turned with the start's heading
    # x, y of the last pose: the start's covariance, moved by the start's heading error over the 1 m lever,
    # plus the piece's own rotated into the world
    expected = np.diag([0.1 ** 2 + 0.1 ** 2 + 0.2 ** 2, 0.1 ** 2 + 0.2 ** 2, 0.1 ** 2 + 0.2 ** 2])
    expected[0, 2] = expected[2, 0] = -0.1 ** 2
    np.testing.assert_allclose(covs["ekf"][3], expected, atol=1e-12)
    assert joined == [{"start": 1.0, "end": 5.0, "seconds": 4.0, "joined": "held"}]


def test_a_camera_increment_across_the_pause_places_the_next_piece():
    from fusion_vo.backends.pauses import Pause

    first = piece([0, 1], [[0, 0, 0], [1, 0, 0]], [0.0, 0.0])
    second = piece([5, 6], [[0, 0, 0], [1, 0, 0]], [0.0, 0.0])
    join = inc(1.0, 5.0, [0.5, 0.0, np.pi / 2])
    tracks, covs, joined = chain([first, second], [Pause(1.0, 5.0, join)], [True, False])
    np.testing.assert_allclose(tracks["ekf"].xyyaw[2:], [[1.5, 0, np.pi / 2], [1.5, 1, np.pi / 2]], atol=1e-12)
    assert joined[0]["joined"] == "camera"
    assert covs["ekf"][2][0, 0] > 0  # the increment's uncertainty is carried on
