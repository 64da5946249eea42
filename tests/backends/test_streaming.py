"""Streaming use: measurements arriving shuffled within the window, late ones counted, same answer as batch."""

import dataclasses

import numpy as np
import pytest
from ahead_job import ahead_jobs
from backend_synth import gps_along, position_errors, streams_of
from husky_like import husky_like

from fusion_vo.backends import FusionConfig, SensorStreams, StreamingFusion, fuse
from fusion_vo.backends.batch import streams_from_recording
from fusion_vo.backends.pauses import samples_between
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.errors import InputError
from fusion_vo.geometry import se2
from fusion_vo.measurements import ImuSample, RangeSample, WheelTicks
from fusion_vo.recording import Recording
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams


#: the longer streams of :data:`AHEAD` are made in the session's second process (tests/ahead_job.py)
BACKGROUND_COMMANDS, _AHEAD = ahead_jobs(__file__)
BACKGROUND_JOBS = {**_AHEAD,
                   "test_on_the_jackal_log_the_engine_fed_in_time_order_is_the_batch_runs_online_track":
                   ["fusion-vo:jackal_log"],
                   "test_on_the_jackal_log_arrivals_shuffled_within_the_reorder_window_give_the_in_order_track":
                   ["fusion-vo:jackal_log"],
                   "test_on_the_husky_log_a_sample_an_interval_reads_after_its_end_is_applied_when_it_comes_out_of_order":
                   ["fusion-vo:husky_log"]}


def _messages(s, rng, delay):
    msgs = [(v.t1, "visual", v) for v in s.visual]
    msgs += [(t, "wheel", WheelTicks(t, l, r)) for t, l, r in zip(s.wheel.t, s.wheel.left, s.wheel.right)]
    msgs += [(t, "imu", ImuSample(t, g, a)) for t, g, a in zip(s.imu.t, s.imu.gyro, s.imu.accel)]
    return _arriving_late(msgs, rng, delay)


def _arriving_late(msgs, rng, delay):
    """``msgs`` (time-ordered ``(t, kind, message)``) in the order they arrive when each comes 0 to ``delay`` s late."""
    arrival = np.array([m[0] for m in msgs]) + rng.uniform(0.0, delay, len(msgs))
    return [msgs[i] for i in np.argsort(arrival, kind="stable")]


def _log_piece(log, lo: float, hi: float) -> tuple:
    """The odometry and IMU of the imported robot log ``log`` from ``lo`` to ``hi`` seconds after its first IMU sample,
    with the configuration of the engine-against-itself tests (the decisions taken in hindsight off)."""
    config = FusionConfig(monitor=False, sync_odometry=False)
    streams = streams_from_recording(Recording(log), None, ["odom", "imu"], config)
    t0 = streams.imu.t[0]
    for name, data in streams.sampled():
        streams[name] = samples_between(data, t0 + lo, t0 + hi)
    return streams, config


def _drive_streams():
    return synthetic_streams(SyntheticOptions(duration=10.0, visual_scale=1.02), seed=11)


@pytest.fixture(scope="module")
def drive():
    s = _drive_streams()
    return s, fuse(streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"]), "all")


@pytest.mark.parametrize("backend, batch_name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_shuffled_arrivals_give_the_batch_online_estimate(drive, backend, batch_name):
    s, batch = drive
    stated = streams_of(s, stated_scale=1.02)  # the calibrations' uncertainties, as the batch run has them
    fusion = StreamingFusion(backend, FusionConfig(reorder_window=0.2), ["camera", "wheel", "imu"],
                             wheel_config=stated.wheel.config, imu_noise=s.imu.noise,
                             camera_height=s.camera_height, camera_height_sigma=stated.camera_height_sigma)
    assert fusion.current_estimate() is None
    fusion.feed(_messages(s, np.random.default_rng(1), 0.1))
    now = fusion.current_estimate()
    assert now is not None and now.t > 9.0 and now.covariance.shape == (3, 3)
    result = fusion.finish()
    track = result.trajectories[batch_name]
    counts = result.counts[batch_name]
    assert counts["wheel"].reordered > 0 and counts["camera"].late == 0 and counts["wheel"].late == 0
    ref = batch.trajectories[batch_name]
    common = np.isin(np.round(ref.t, 9), np.round(track.t, 9))
    assert common.sum() > 0.95 * len(ref)
    ours = track.xyyaw[np.isin(np.round(track.t, 9), np.round(ref.t, 9))]
    assert np.max(np.abs(ours[:, :2] - ref.xyyaw[common, :2])) < 0.01
    assert position_errors(track, s.truth)[0] < 0.05


def test_measurements_later_than_the_window_are_counted_not_applied(drive):
    s, _ = drive
    fusion = StreamingFusion("ekf", FusionConfig(reorder_window=0.05), ["camera", "wheel", "imu"],
                             wheel_config=s.wheel.config, imu_noise=s.imu.noise)
    msgs = _messages(s, np.random.default_rng(2), 0.0)
    held = [m for m in msgs if m[1] == "wheel" and 4.0 < m[0] < 4.5]
    for m in msgs:
        if m not in held:
            fusion.feed([m])
    fusion.feed(held)  # arrive seconds late
    result = fusion.finish()
    assert result.counts["ekf"]["wheel"].late == len(held)
    assert any("late measurements not applied: wheel" in n for n in result.notes)


def test_undeclared_or_unconfigured_sensors_are_input_errors():
    with pytest.raises(InputError, match="wheel_config"):
        StreamingFusion("ekf", sensors=["wheel"])
    fusion = StreamingFusion("ekf", sensors=["imu"])
    with pytest.raises(InputError, match="not declared"):
        fusion.add_range(RangeSample(0.0, 0.1))


def _on_the_epoch_clock(streams, offset: float = 1.6e9):
    """The same streams stamped ``offset`` seconds later, as recordings are (epoch seconds, where a float resolves
    0.24 µs)."""
    return streams.replace(
        visual=[dataclasses.replace(v, t0=v.t0 + offset, t1=v.t1 + offset) for v in streams.visual],
        wheel=dataclasses.replace(streams.wheel, t=streams.wheel.t + offset),
        imu=dataclasses.replace(streams.imu, t=streams.imu.t + offset))


def _batch_and_engine(streams, backend: str):
    """The batch run of ``streams`` and the streaming engine's result with every sample fed in time order."""
    fusion = streaming_for(streams, backend)
    fusion.feed(time_ordered_messages(streams))
    return fuse(streams, "all"), fusion.finish()


@pytest.mark.parametrize("backend, name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_the_engine_fed_in_time_order_is_the_batch_runs_online_track(drive, backend, name):
    """Without anything a whole log shows in hindsight (docs/streaming.md), the batch run's online track is the
    engine's: the same nodes, poses and covariances, to rounding. Fails if either builds its node grid, its
    intervals or its updates differently (the nodes moved by one float step at epoch times, or the track's end
    left without a node, did)."""
    s, _ = drive
    streams = _on_the_epoch_clock(streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"]))
    batch, live = _batch_and_engine(streams, backend)
    ours, ref = live.trajectories[name], batch.trajectories[name]
    assert len(ours.t) == len(ref.t) and np.array_equal(ours.t, ref.t)
    assert np.max(np.abs(ours.xyyaw - ref.xyyaw)) < 1e-8
    assert np.max(np.abs(live.covariances[name] - batch.covariances[name])) < 1e-9 * np.max(batch.covariances[name])


@pytest.mark.parametrize("backend, name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_on_the_jackal_log_the_engine_fed_in_time_order_is_the_batch_runs_online_track(jackal_log, backend, name):
    """A real log (robot_localization's Jackal bag: wheel odometry at 50 Hz, IMU at 50 Hz with an AHRS, 61 s): with
    the decisions a batch run takes in hindsight off (the consistency monitor over the whole log, the twist's delay
    estimated from the whole log), the engine fed every sample in time order makes the batch run's online track:
    the same nodes, poses and covariances to rounding. Fails if either builds its grid, the odometry's or the IMU's
    readings or its updates differently (measured apart: 6e-12, ekf)."""
    config = FusionConfig(monitor=False, sync_odometry=False)
    streams = streams_from_recording(Recording(jackal_log), None, ["odom", "imu"], config)
    fusion = streaming_for(streams, backend, config)
    fusion.feed(time_ordered_messages(streams))
    live, batch = fusion.finish(), fuse(streams, backend, config)
    ours, ref = live.trajectories[name], batch.trajectories[name]
    assert len(ref.t) > 1200 and np.array_equal(ours.t, ref.t)
    assert np.max(np.abs(ours.xyyaw - ref.xyyaw)) < 1e-8
    assert np.max(np.abs(live.covariances[name] - batch.covariances[name])) < 1e-9 * np.max(batch.covariances[name])
    for sensor in ("wheel", "gyro", "ahrs"):
        assert live.counts[name][sensor].used == batch.counts[name][sensor].used > 1000, sensor


def _without_a_camera(backend: str) -> tuple:
    """Odometry and IMU of a generated drive on an epoch clock, without and with GPS fixes at 2.5 Hz jittered by up
    to 20 ms, fed to the engine and run in batch by ``backend``: (the fixes' times, [(gps?, engine's, batch's)])."""
    odom, imu, truth = husky_like(duration=30.0, stop=(10.0, 15.0), yaw_scale=1.0)
    epoch = 1.7e9
    odom = dataclasses.replace(odom, t=odom.t + epoch)
    imu = dataclasses.replace(imu, t=imu.t + epoch)
    truth = dataclasses.replace(truth, t=truth.t + epoch)
    rng = np.random.default_rng(4)
    fix_t = epoch + np.arange(0.3, 29.5, 0.4)
    fix_t += rng.uniform(-0.02, 0.02, len(fix_t))
    config = FusionConfig(monitor=False, sync_odometry=False)
    runs = []
    for gps in (None, gps_along(truth, fix_t, 0.5, rng)):
        streams = SensorStreams(odom=odom, imu=imu, gps=gps)
        fusion = streaming_for(streams, backend, config)
        fusion.feed(time_ordered_messages(streams))
        runs.append((gps is not None, fusion.finish(), fuse(streams, backend, config)))
    return fix_t, runs


@pytest.mark.parametrize("backend, name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_without_a_camera_the_batch_run_places_the_engines_nodes(made_ahead, backend, name):
    """Without a camera the engine cannot know where the data ends: it steps its nodes ``1 / step_hz`` at a time and
    restarts at each GPS fix; a batch run places them the same way (``timeline.step_nodes``). Odometry and IMU of
    a generated skid-steered drive on an epoch clock whose last sample comes 0.017 s after a step, without and with
    GPS at 2.5 Hz jittered by up to 20 ms: the same node times, and without GPS the same track (spaced evenly up to
    the last sample, the batch run's grid had one node more, measured)."""
    fix_t, runs = made_ahead(f"without_a_camera_{backend}")
    for with_gps, live, batch in runs:
        ours, ref = live.trajectories[name], batch.trajectories[name]
        assert len(ref.t) >= 600 and np.array_equal(ours.t, ref.t), (with_gps, len(ours.t), len(ref.t))
        if not with_gps:
            assert np.max(np.abs(ours.xyyaw - ref.xyyaw)) < 1e-8
        else:
            assert np.min(np.abs(ref.t[:, None] - fix_t), axis=0).max() <= 1e-3  # every fix at a node


def test_on_the_jackal_log_arrivals_shuffled_within_the_reorder_window_give_the_in_order_track(jackal_log):
    """Every sample of the Jackal log's first 10 s delayed by 0 to 0.28 s (so they come out of order, all within
    the 0.3 s reorder window): the engine's track is the one fed in time order, bit for bit. Fails if the interval
    that finds the AHRS's offset (averaged over the first quarter second) is built before every sample of that
    quarter second is in (the offset was then 1.3e-5 rad off, the tracks 0.1 mm apart after the 10 s)."""
    streams, config = _log_piece(jackal_log, -np.inf, 10.0)
    in_order = time_ordered_messages(streams)
    shuffled = _arriving_late(in_order, np.random.default_rng(3), 0.28)
    assert shuffled[:20] != in_order[:20]
    tracks = []
    for messages in (in_order, shuffled):
        fusion = streaming_for(streams, "ekf", config)
        fusion.feed(messages)
        result = fusion.finish()
        assert not any(c.late for c in result.counts["ekf"].values())
        assert messages is shuffled or fusion.rewinds == 0
        tracks.append(result.trajectories["ekf"])
    assert len(tracks[0].t) > 190 and np.array_equal(tracks[0].t, tracks[1].t)
    assert np.array_equal(tracks[0].xyyaw, tracks[1].xyyaw)


def test_on_the_husky_log_a_sample_an_interval_reads_after_its_end_is_applied_when_it_comes_out_of_order(husky_log):
    """The Husky log's odometry (10 Hz, a 0.21 s gap at 194.3 s) and IMU, 185-205 s in, every sample delayed by 0 to
    0.28 s (window 0.3 s): the track is the in-order one, bit for bit. A node interval reads the first odometry
    sample after its end; the window vouches for the samples up to the node, not for that one, which may come
    after the node was processed. Fails if such a sample is not applied by processing again every interval that
    reads it (then 2 more intervals without odometry here, the track 2 mm off)."""
    streams, config = _log_piece(husky_log, 185.0, 205.0)
    in_order = time_ordered_messages(streams)
    shuffled = _arriving_late(in_order, np.random.default_rng(4), 0.28)
    results = []
    for messages in (in_order, shuffled):
        fusion = streaming_for(streams, "ekf", config)
        fusion.feed(messages)
        results.append((fusion.finish(), fusion.rewinds))
    (a, rewinds_a), (b, rewinds_b) = results
    assert rewinds_a == 0 and rewinds_b > 0 and not any(c.late for c in b.counts["ekf"].values())
    assert b.counts["ekf"]["wheel"].missing == a.counts["ekf"]["wheel"].missing
    assert len(a.trajectories["ekf"].t) > 390 and np.array_equal(a.trajectories["ekf"].t, b.trajectories["ekf"].t)
    assert np.array_equal(a.trajectories["ekf"].xyyaw, b.trajectories["ekf"].xyyaw)


def _camera_late_by(streams, delay: float):
    """iSAM2 fed ``streams`` in time order and with the camera ``delay`` seconds late: the camera's counts of both runs
    and the distance [m] of each in-order node to the late run's track (whose nodes are fill-in nodes, not frames)."""
    runs = []
    for camera_delay in (0.0, delay):
        fusion = streaming_for(streams, "gtsam")
        fusion.feed(time_ordered_messages(streams, camera_delay=camera_delay))
        runs.append(fusion.finish())
    a, b = (r.trajectories["gtsam_online"] for r in runs)
    at = np.column_stack([np.interp(a.t, b.t, b.xyyaw[:, i]) for i in range(2)])
    return [r.counts["gtsam_online"]["camera"] for r in runs], np.linalg.norm(at - a.xyyaw[:, :2], axis=1)


def test_on_the_epoch_clock_isam2_attaches_camera_increments_later_than_its_window(drive):
    """Recordings stamp epoch seconds, where a fill-in node stepped from the first sample sits a float step or more
    off the frame it stands for (0.24 µs a step, growing along the drive). With the camera 0.35 s late and the default
    0.3 s window, iSAM2's nodes are fill-in nodes by the time an increment comes, and it re-times every increment
    but the first onto them; its track stays within millimetres of the in-order one. Fails if an increment ending a
    float step after the last node is taken for one that ends after it, or that node is not rebuilt (then 194 of the
    199 were counted late)."""
    s, _ = drive
    streams = _on_the_epoch_clock(streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"]))
    (in_order, late), gap = _camera_late_by(streams, 0.35)
    assert in_order.late == 0 and late.late <= 1 and late.used >= in_order.used - 1 > 190
    assert gap.max() < 0.015 and np.median(gap) < 0.004  # measured 7.1 / 1.6 mm; with them late 33 / 4.3 cm


def _with_frames_dropped_and_lost(visual, shift: float = 0.01):
    """The increments as a frontend gives them on a worse camera: every frame ``shift`` seconds later (so the
    wheels and the IMU start first, by less than half a node step), frames 40, 90 and 91 dropped (the next
    increment spans them), and frames 120-123 not measured (failed increments from frame 119; the next one spans
    the outage, 0.25 s)."""
    out, i = [], 0
    while i < len(visual):
        v = visual[i]
        if i in (40, 90, 120):
            last = {40: 41, 90: 92, 120: 124}[i]
            if i == 120:
                out += [dataclasses.replace(visual[k], t0=v.t0, status="lost") for k in range(120, 124)]
            delta, cov = v.delta, v.covariance
            for k in range(i + 1, last + 1):
                delta, cov = se2.compose(delta, visual[k].delta), cov + visual[k].covariance
            out.append(dataclasses.replace(v, t1=visual[last].t1, delta=delta, covariance=cov))
            i = last + 1
            continue
        out.append(v)
        i += 1
    return [dataclasses.replace(v, t0=v.t0 + shift, t1=v.t1 + shift) for v in out]


@pytest.mark.parametrize("backend, name", [("ekf", "ekf"), ("gtsam", "gtsam_online")])
def test_the_engine_spans_dropped_and_lost_frames_as_the_batch_run_does(drive, backend, name):
    """Dropped frames (an increment over two or three node intervals), a short outage and a camera that starts
    after the other sensors: the engine puts its nodes where the batch run does and applies every increment
    (none counted late) as the batch run does: the EKF over each of its intervals, iSAM2 as one factor between its
    two frames' nodes, added with the second. Both tracks and the camera's counts are the batch run's. Fails if
    the engine starts its grid elsewhere, fills a gap differently, drops an increment that spans more than one
    interval, or (iSAM2) applies it as shares over its intervals (1.9 mm off the batch track here)."""
    s, _ = drive
    streams = streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"])
    streams = _on_the_epoch_clock(streams.replace(visual=_with_frames_dropped_and_lost(streams.visual)))
    batch, live = _batch_and_engine(streams, backend)
    ours, ref = live.trajectories[name], batch.trajectories[name]
    counts = live.counts[name]["camera"]
    assert counts.late == 0 and counts.missing == 4
    assert counts.used == batch.counts[name]["camera"].used
    assert np.array_equal(ours.t, ref.t)
    assert np.max(np.abs(ours.xyyaw - ref.xyyaw)) < 1e-8


def _spanning_increments_late_wheels() -> tuple[dict, int, int]:
    """The drive of :func:`drive` with frames dropped and lost, streamed to iSAM2 in order and with the wheel samples
    a second late: the counts of both runs, the late run's rewinds and the camera's uses in the batch run."""
    s = _drive_streams()
    streams = streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"])
    streams = _on_the_epoch_clock(streams.replace(visual=_with_frames_dropped_and_lost(streams.visual)))
    msgs = time_ordered_messages(streams)
    late = sorted([(t + 1.0, k, m) if k == "wheel" else (t, k, m) for t, k, m in msgs], key=lambda x: x[0])
    counts = {}
    for name, feed in (("in order", msgs), ("late", late)):
        fusion = streaming_for(streams, "gtsam", history=2.0)
        fusion.feed(feed)
        counts[name] = {k: v.as_dict() for k, v in fusion.finish().counts["gtsam_online"].items()}
    return counts, fusion.rewinds, fuse(streams, "all").counts["gtsam_online"]["camera"].used


def test_isam2_rebuilds_an_interval_of_a_spanning_increment_with_late_data(made_ahead):
    """Wheel samples a second late make iSAM2 rebuild the intervals they fall in, those inside a span of dropped
    frames too: every increment is still applied once, as in order (the camera's uses are those of the batch
    run). Fails if a rebuilt interval takes the node grid after it for the span's nodes (10 increments were then
    counted late or lost on a 20 s drive)."""
    counts, rewinds, batch_used = made_ahead("spanning_late_wheels")
    assert rewinds > 100, rewinds
    assert counts["late"] == counts["in order"]
    assert counts["late"]["camera"]["used"] == batch_used


@pytest.mark.parametrize("backend, name, tolerance", [("ekf", "ekf", 1e-8), ("gtsam", "gtsam_online", 1e-8)])
def test_in_a_camera_outage_the_engine_keeps_the_wheels_model(drive, backend, name, tolerance):
    """A camera outage that no increment spans (frames 100-139 failed, the frontend starting again at frame 140):
    its intervals have wheels and gyro only, and the wheels' readings keep the curvature state the filter and the
    graph carry for the run, as the batch run's do. Fails if an interval without the camera drops the curvature
    from the wheels' model (the tracks then part by 0.44-0.46 mm)."""
    s, _ = drive
    streams = streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"])
    lost = [dataclasses.replace(v, t0=streams.visual[99].t1, status="lost") if 100 <= i < 140 else v
            for i, v in enumerate(streams.visual)]
    streams = _on_the_epoch_clock(streams.replace(visual=lost))
    batch, live = _batch_and_engine(streams, backend)
    ours, ref = live.trajectories[name], batch.trajectories[name]
    assert live.counts[name]["camera"].missing == 40 and abs(batch.calibration[name]["wheel_curvature"]) > 1e-3
    assert np.array_equal(ours.t, ref.t)
    assert np.max(np.abs(ours.xyyaw - ref.xyyaw)) < tolerance


def test_the_first_node_takes_the_ahrs_heading_as_a_batch_run_does():
    """The AHRS heading at the first node is applied there, as a batch run applies it: the same first pose and
    covariance and the same number of headings used (the grids part later: a batch run spaces its nodes over
    the whole log, a live one steps from the first sample)."""
    s = synthetic_streams(SyntheticOptions(duration=3.0, ahrs_sigma=0.01), seed=17)
    streams = streams_of(s).select(["wheel", "imu"])
    cfg = FusionConfig(monitor=False)
    batch = fuse(streams, "ekf", cfg)
    fusion = streaming_for(streams, "ekf", cfg)
    fusion.feed(time_ordered_messages(streams))
    live = fusion.finish()
    assert live.counts["ekf"]["ahrs"].used == batch.counts["ekf"]["ahrs"].used > 50
    np.testing.assert_allclose(live.covariances["ekf"][0], batch.covariances["ekf"][0], rtol=1e-12, atol=0)
    np.testing.assert_allclose(live.trajectories["ekf"].xyyaw[0], batch.trajectories["ekf"].xyyaw[0],
                               rtol=0, atol=1e-15)


def _outages(result) -> list[str]:
    return [n for n in result.notes if " lost from " in n or " unavailable from " in n]


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_the_engine_notes_the_camera_and_gyro_outages_the_batch_run_notes(drive, backend):
    """A camera outage (frames 100-139 failed), a second without gyro samples and dropped frames: the engine's finished
    run names the same outages, in the same words, as the batch run, when the samples come in time order and when
    one in fifty wheel and IMU samples comes 0.8 s late (beyond the reorder window: rewinds and rebuilds). Fails if the engine says nothing of them,
    counts an interval covered only by a share of a spanning increment as lost, or keeps the coverage of an interval
    from before it was processed again."""
    s, _ = drive
    streams = streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"])
    visual = _with_frames_dropped_and_lost(streams.visual, shift=0.0)
    lost = [dataclasses.replace(v, t0=visual[99].t1, status="lost") if 100 <= i < 140 else v
            for i, v in enumerate(visual)]
    keep = (streams.imu.t < 6.0) | (streams.imu.t > 7.0)
    imu = dataclasses.replace(streams.imu, t=streams.imu.t[keep], gyro=streams.imu.gyro[keep],
                              accel=streams.imu.accel[keep])
    streams = _on_the_epoch_clock(streams.replace(visual=lost, imu=imu))
    expected = _outages(fuse(streams, backend))
    assert len(expected) == 2 and expected[0].startswith("camera lost from") and expected[1].startswith("gyro ")
    msgs = time_ordered_messages(streams)
    rng = np.random.default_rng(3)
    arrival = np.array([t + (0.8 if kind != "visual" and rng.uniform() < 0.02 else 0.0) for t, kind, _ in msgs])
    late = [msgs[i] for i in np.argsort(arrival, kind="stable")]
    for feed in (msgs, late):
        fusion = streaming_for(streams, backend)
        fusion.feed(feed)
        assert _outages(fusion.finish()) == expected
        assert feed is msgs or fusion.rewinds > 0


def test_a_late_sample_inside_a_gap_of_its_stream_redoes_every_interval_that_read_across_the_gap(drive):
    """The wheels silent from 4.98 s to 5.22 s (shorter than max_gap: the intervals in the gap interpolate across it),
    and their one sample inside the gap arriving a second late: the EKF's track is the one of the samples in time
    order, bit for bit. Fails if the engine redoes only the intervals next to the late sample (it re-filtered from two
    nodes before it: 2.2 mm off), leaving the earlier intervals of the gap with the interpolation across the whole
    gap. (iSAM2 rebuilds the intervals of the samples' three neighbours on each side, the whole gap here.)"""
    backend, name = "ekf", "ekf"
    s, _ = drive
    streams = streams_of(s, stated_scale=1.02).select(["wheel", "imu"])
    wheel = streams.wheel
    inside = np.flatnonzero((wheel.t > 5.0) & (wheel.t < 5.2))
    keep = np.ones(len(wheel.t), bool)
    keep[inside[:-1]] = False  # (the last one stays, the one that comes late)
    streams = streams.replace(wheel=dataclasses.replace(wheel, t=wheel.t[keep], left=wheel.left[keep],
                                                        right=wheel.right[keep]))
    msgs = time_ordered_messages(streams)
    t_late = wheel.t[inside[-1]]
    late = sorted(msgs, key=lambda m: m[0] + (1.0 if m[1] == "wheel" and m[0] == t_late else 0.0))
    tracks = []
    for feed in (msgs, late):
        fusion = streaming_for(streams, backend)
        fusion.feed(feed)
        tracks.append(fusion.finish().trajectories[name])
        assert feed is msgs or fusion.rewinds == 1
    assert np.array_equal(tracks[0].t, tracks[1].t)
    assert np.max(np.abs(tracks[0].xyyaw - tracks[1].xyyaw)) < 1e-12


def test_isam2_attaches_a_late_increment_over_dropped_frames_to_the_nodes_it_spans(drive):
    """Frames dropped (increments over two and three node intervals) and the camera 0.35 s late, beyond the 0.3 s
    window: iSAM2 re-times each spanning increment onto the fill-in nodes nearest its two frames, as one factor
    between them, and re-does the intervals between; every increment is used as in time order (but the first, which
    no node waits for) and the track stays within millimetres of the in-order one. Fails if an increment must end at
    the node after its first (the spanning ones were then counted late)."""
    s, _ = drive
    streams = streams_of(s, stated_scale=1.02).select(["camera", "wheel", "imu"])
    streams = _on_the_epoch_clock(streams.replace(visual=_with_frames_dropped_and_lost(streams.visual, shift=0.0)))
    (in_order, late), gap = _camera_late_by(streams, 0.35)
    assert in_order.late == 0 and late.late <= 1 and late.used >= in_order.used - 1
    assert gap.max() < 0.015 and np.median(gap) < 0.004


def _late_imu_tracks() -> tuple[list, int]:
    """Odometry and an IMU with an AHRS, 20 s, fed to the EKF in time order and with every third IMU sample (the first
    one among them) 1 s late: the two tracks and the late run's rewinds."""
    odom, imu, _ = husky_like(duration=20.0, stop=(8.0, 12.0), ahrs_drift=0.0)
    streams = SensorStreams(odom=odom, imu=imu)
    assert imu.orientation is not None
    msgs = list(time_ordered_messages(streams))
    delayed = set([i for i, m in enumerate(msgs) if m[1] == "imu"][::3])
    late = sorted([m if i not in delayed else (m[0] + 1.0, *m[1:]) for i, m in enumerate(msgs)],
                  key=lambda m: m[0])
    tracks = []
    for order in (msgs, late):
        fusion = streaming_for(streams, "ekf", FusionConfig(reorder_window=0.05))
        fusion.feed(order)
        tracks.append(fusion.finish().trajectories["ekf"])
    return tracks, fusion.rewinds


def test_late_imu_samples_with_orientations_are_re_applied_exactly_as_in_order(made_ahead):
    """Odometry and an IMU with an AHRS, every third IMU sample (the first one among them) arriving 1 s late, far
    beyond the 0.05 s reorder window: the EKF rewinds (history 2 s) and rebuilds, and the AHRS's offset to the initial
    heading, found once from the first quarter second and carried from node to node (``Sensor.carry``), is found
    again with the late first sample. The track is the one fed in time order, exactly (measured: 0 m, 0 rad, 202
    rewinds; with a rewind that keeps the newer offset, measured: 15 mm and 4 mrad off)."""
    tracks, rewinds = made_ahead("late_imu")
    assert rewinds > 100, rewinds
    assert np.array_equal(tracks[0].t, tracks[1].t)
    assert np.array_equal(tracks[0].xyyaw, tracks[1].xyyaw)


AHEAD = {"late_imu": _late_imu_tracks, "spanning_late_wheels": _spanning_increments_late_wheels,
         "without_a_camera_ekf": lambda: _without_a_camera("ekf"),
         "without_a_camera_gtsam": lambda: _without_a_camera("gtsam")}
