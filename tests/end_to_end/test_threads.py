"""Frames decoded ahead of the tracker: same results as one thread, in order, bounded, errors in place."""

import shutil
import threading
import time

import numpy as np
import pytest

from fusion_vo.cli.main import main
from fusion_vo.errors import InputError
from fusion_vo.odometry import OdometryConfig, read_ahead, run_visual_odometry
from fusion_vo.recording import Recording


def _same(a, b):
    assert a.status == b.status
    assert a.skipped == b.skipped
    np.testing.assert_array_equal(a.frame_t, b.frame_t)
    np.testing.assert_array_equal(a.inliers, b.inliers)
    np.testing.assert_array_equal(a.track.xyyaw, b.track.xyyaw)
    np.testing.assert_array_equal(a.velocity, b.velocity)
    assert len(a.increments) == len(b.increments)
    for x, y in zip(a.increments, b.increments):
        np.testing.assert_array_equal(x.delta, y.delta)
        np.testing.assert_array_equal(x.covariance, y.covariance)


@pytest.mark.slow
@pytest.mark.parametrize("frontend", ["klt", "features"])
def test_threads_give_the_single_threaded_result_frame_for_frame(standard_recording, tmp_path, frontend):
    seq = tmp_path / "seq"
    shutil.copytree(standard_recording("short"), seq)
    frames = sorted((seq / "cam0" / "data").iterdir())
    frames[30].write_bytes(b"\x89PNG\r\n\x1a\n broken")  # skipped and counted the same way
    frames[31].unlink()
    one = run_visual_odometry(Recording(seq), OdometryConfig(frontend=frontend, threads=1))
    two = run_visual_odometry(Recording(seq), OdometryConfig(frontend=frontend, threads=2))
    three = run_visual_odometry(Recording(seq), OdometryConfig(frontend=frontend, threads=3))
    handed = run_visual_odometry(Recording(seq), OdometryConfig(frontend=frontend, threads=2, handoff=True))
    assert len(one.skipped) == 2 and one.n_frames == len(frames) - 2
    assert one.failures == {} and one.distance > 0.1
    _same(one, two)
    _same(one, three)
    _same(one, handed)


def test_read_ahead_keeps_order_and_stays_within_its_depth():
    produced = []
    consumed = []
    ahead_most = 0

    def items():
        for i in range(200):
            produced.append(i)
            yield i

    for item in read_ahead(items(), depth=3):
        consumed.append(item)
        # the item being produced is not yet in the queue: at most depth queued + 1 being made
        ahead_most = max(ahead_most, len(produced) - len(consumed))
        if item % 50 == 0:
            time.sleep(0.02)  # let the producer run as far ahead as it may
    assert consumed == list(range(200))
    assert 2 <= ahead_most <= 4


def test_read_ahead_raises_the_producers_error_in_place():
    def items():
        yield 1
        yield 2
        raise InputError("video ends after 2 frames")

    got = []
    with pytest.raises(InputError, match="video ends after 2 frames"):
        for item in read_ahead(items(), depth=4):
            got.append(item)
    assert got == [1, 2]


def test_read_ahead_stops_and_closes_the_source_when_the_consumer_stops():
    closed = threading.Event()
    produced = []

    def items():
        try:
            for i in range(10_000):
                produced.append(i)
                yield i
        finally:
            closed.set()

    ahead = read_ahead(items(), depth=2)
    assert next(ahead) == 0
    ahead.close()
    assert closed.is_set()  # close() waits for the producer to finish
    assert len(produced) <= 5


@pytest.mark.slow
def test_too_many_bad_frames_at_the_start_stop_the_threaded_run(standard_recording, tmp_path):
    seq = tmp_path / "seq"
    shutil.copytree(standard_recording("short"), seq)
    for p in sorted((seq / "cam0" / "data").iterdir())[:6]:
        p.write_bytes(b"not a png")
    with pytest.raises(InputError, match="the first 5 frames cannot be used"):
        run_visual_odometry(Recording(seq), OdometryConfig(threads=2))
    assert not any(t.name.startswith("fusion-vo") for t in threading.enumerate())


@pytest.mark.parametrize("value", ["0", "-2", "two"])
def test_threads_must_be_a_positive_whole_number(value, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", str(tmp_path), "--out", str(tmp_path / "out"), "--threads", value])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--threads" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("value", [0, -1, 1.5, True])
def test_threads_in_the_configuration_is_checked(value):
    with pytest.raises(ValueError, match="threads"):
        OdometryConfig.from_dict({"threads": value})


@pytest.mark.parametrize("sixteen_bit", [False, True])
@pytest.mark.parametrize("frontend", ["klt", "features", "features_orb"])
def test_prepared_frames_give_the_same_motions(standard_recording, frontend, sixteen_bit):
    from frontends import make_frontend

    options = {"descriptor": "orb"} if frontend == "features_orb" else {}
    name = frontend.split("_")[0]
    rec = Recording(standard_recording("short"))
    frames = [(f.image.astype(np.uint16) * 257 if sixteen_bit else f.image, f.t) for f in rec.frames(stop=40)]
    frames[20] = (np.zeros((5, 5), np.uint8), frames[20][1])  # a bad frame passes through prepare unchanged
    plain, ahead = make_frontend(name, options), make_frontend(name, options)
    ok = 0
    for image, t in frames:
        prepared = ahead.prepare(image)
        assert (prepared is image) == (image.shape == (5, 5))
        a, b = plain.process(image, t), ahead.process(prepared, t)
        assert a.status == b.status and a.n_inliers == b.n_inliers
        if a.ok:
            ok += 1
            np.testing.assert_array_equal(a.matrix, b.matrix)
            np.testing.assert_array_equal(a.covariance, b.covariance)
    assert ok >= 35


def test_compute_threads_are_set_inside_and_restored_after():
    import cv2
    from threadpoolctl import threadpool_info

    from fusion_vo.odometry import opencv_threads

    before_cv, before_blas = cv2.getNumThreads(), [i["num_threads"] for i in threadpool_info()]
    with opencv_threads(3):
        assert cv2.getNumThreads() == 3
        assert all(i["num_threads"] == 1 for i in threadpool_info() if i["user_api"] == "blas")
    assert cv2.getNumThreads() == before_cv
    assert [i["num_threads"] for i in threadpool_info()] == before_blas


@pytest.mark.parametrize("threads", [1, 2])
def test_an_error_of_the_geometry_stage_reaches_the_caller(standard_recording, monkeypatch, threads):
    from fusion_vo.geometry.ground import GroundGeometry

    calls = []
    original = GroundGeometry.increment

    def failing(self, motion, height=None, height_sigma=0.0):
        calls.append(threading.current_thread().name)
        if len(calls) == 6:
            raise RuntimeError("increment 6 failed")
        return original(self, motion, height, height_sigma)

    monkeypatch.setattr(GroundGeometry, "increment", failing)
    with pytest.raises(RuntimeError, match="increment 6 failed"):
        run_visual_odometry(Recording(standard_recording("short")), OdometryConfig(threads=threads))
    # one thread stops at once; the geometry thread may have been handed the few frames queued behind it
    assert len(calls) == 6 if threads == 1 else 6 <= len(calls) <= 6 + 2 * threads + 3
    # with threads, the increments are made in a thread of their own, not in the tracker's
    assert all(name.startswith("fusion-vo-geometry") for name in calls) == (threads > 1)
