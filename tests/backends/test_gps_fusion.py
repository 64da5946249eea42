"""GPS fused in both backends: ENU world frame with an estimated first heading, accuracy while the fixes
are present, a multipath jump rejected and counted, drift during an outage, streaming use (EKF and iSAM2)."""

from __future__ import annotations

import dataclasses
import json
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest

from fusion_vo.backends import FusionConfig, SensorStreams, StreamingFusion, fuse, streams_from_recording
from fusion_vo.backends.fixes import Reacquire
from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
from fusion_vo.cli.main import main
from fusion_vo.evaluation.io import read_tum_poses
from fusion_vo.geometry import se2
from fusion_vo.measurements import GpsFix, ImuSample, PoseData, WheelTicks
from fusion_vo.recording import Recording
from fusion_vo.sensors import gps as gps_model
from fusion_vo.sensors import registry
from fusion_vo.sensors.gps import read_fixes
from fusion_vo.sensors.imu import read_imu
from fusion_vo.sensors.synthetic import SyntheticOptions, synthetic_streams
from fusion_vo.sensors.wheel import read_ticks
from fusion_vo.simulation import simulate

from ahead_job import ahead_jobs
from backend_synth import gps_along, position_errors
from husky_gps_stream_job import figures as husky_gps_figures, husky_parts, withheld_rms

TINY = {"width": 80, "height": 48, "fu": 60.0, "fv": 60.0, "cu": 39.5, "cv": 23.5, "supersample": 1, "camera_rate": 2.0}
NOISE = 0.05
HEADING = 40.0
ORIGIN = np.array([5.0, -3.0])
OUTAGE = (8.0, 13.0)
JUMP = (16.0, 16.8)  # 5 fixes at 5 Hz
OPTIONS = {"duration": 24.0, "gps": True, "gps_rate": 5.0, "gps_noise": NOISE, "gps_lever_arm": [-0.3, 0.2, 0.5],
           "gps_outages": [list(OUTAGE)], "gps_jumps": [[*JUMP, 12.0, 16.0]], "gps_heading_deg": HEADING,
           "gps_origin": ORIGIN.tolist()}


def _simulated(folder) -> Recording:
    """The 24 s drive with GPS (an outage and a multipath jump) every test of this module reads."""
    return Recording(simulate(folder, profile="random", seed=21, **{**TINY, **OPTIONS}))


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    return _simulated(tmp_path_factory.mktemp("gpsfuse") / "rec")


@pytest.fixture(scope="module")
def truth(rec):
    gt = rec.groundtruth()
    return PoseData(gt.t, gps_model.Alignment(math.radians(HEADING), ORIGIN, 0.0, 0).apply(gt.xyyaw))


@pytest.fixture(scope="module")
def fused(rec):
    return fuse(streams_from_recording(rec, None, ["wheel", "imu", "gps"]), "all")


@pytest.fixture(scope="module")
def unfused(rec):
    return fuse(streams_from_recording(rec, None, ["wheel", "imu"]), "ekf")


def errors(track: PoseData, truth: PoseData) -> tuple[np.ndarray, np.ndarray]:
    """Seconds since the start and position errors in ENU, no alignment."""
    ref = np.column_stack([np.interp(track.t, truth.t, truth.xyyaw[:, i]) for i in range(2)])
    return track.t - truth.t[0], np.linalg.norm(track.xyyaw[:, :2] - ref, axis=1)


@pytest.mark.parametrize("name", ["ekf", "ekf_smoothed", "gtsam", "gtsam_online"])
def test_fused_track_is_in_enu_within_half_the_gps_noise(fused, unfused, truth, name):
    t, e = errors(fused.trajectories[name], truth)
    present = ~((t >= OUTAGE[0]) & (t <= OUTAGE[1] + 1.0))
    rms = float(np.sqrt(np.mean(e[present] ** 2)))
    assert rms <= 0.5 * NOISE, (name, rms)
    # without GPS the wheel+gyro track is not in ENU at all (start frame): GPS is what put it there
    t0, e0 = errors(unfused.trajectories["ekf"], truth)
    assert np.sqrt(np.mean(e0 ** 2)) > 1.0


def test_first_heading_is_estimated_from_the_fixes(fused, truth):
    note = next(n for n in fused.notes if n.startswith("gps: world frame is ENU"))
    assert "first heading" in note
    for name in ("ekf_smoothed", "gtsam"):
        yaw0 = fused.trajectories[name].xyyaw[0, 2]
        assert abs(math.degrees(yaw0 - truth.xyyaw[0, 2])) < 1.0, name


@pytest.mark.parametrize("name", ["ekf", "gtsam"])
def test_multipath_jump_is_rejected_counted_and_moves_nothing(fused, truth, name):
    count = fused.counts[name]["gps"]
    assert count.gated == 5, count  # exactly the five jumped fixes
    t, e = errors(fused.trajectories[name], truth)
    during = (t >= JUMP[0]) & (t <= JUMP[1] + 0.5)
    assert e[during].max() < 0.5 * NOISE
    note = next(n for n in fused.notes if n.startswith(f"{name}: gps"))
    assert "5 rejected by the gate" in note and f"{JUMP[0]:.2f} to {JUMP[1]:.2f} s in" in note


def test_counts_add_up_to_the_fixes(rec, fused):
    n = len(read_fixes(rec))
    for name in ("ekf", "gtsam"):
        c = fused.counts[name]["gps"]
        assert c.used + c.gated + c.missing == n, (name, c)


def test_drift_during_the_outage_is_larger_than_with_gps_and_bounded(fused, truth):
    t, e = errors(fused.trajectories["ekf"], truth)
    start = int(np.argmin(np.abs(t - OUTAGE[0])))
    last_second = (t >= OUTAGE[1] - 1.0) & (t <= OUTAGE[1])
    # the causal filter dead-reckons through the outage: its error grows, then the fixes pull it back
    assert e[last_second].max() > 1.3 * e[start]
    after = (t > OUTAGE[1] + 2.0) & (t < JUMP[0])
    assert np.sqrt(np.mean(e[after] ** 2)) <= 0.5 * NOISE
    # and the run reports it: the first fix after the outage measures the drift
    note = next(n for n in fused.notes if n.startswith("ekf: gps outage"))
    drift = float(note.split("drift ")[1].split(" m")[0])
    assert drift < 0.2 and drift > 0.5 * e[last_second].max()


def test_gps_fixes_measure_the_camera_scale_where_no_wheels_do():
    """GPS declares ``absolute_distance``: with a camera whose stated height is 5 % off (its ``height_sigma`` says 5 %),
    the IMU and 5 cm fixes at 5 Hz, and no wheels, every backend estimates the visual scale from the fixes (40 s
    generated drive). Baseline, the same run with GPS not declared a distance: the scale held at 1, each track
    2.2-3.6 times as far from the truth (measured 0.014-0.024 m against 0.045-0.067 m RMS)."""
    s = synthetic_streams(SyntheticOptions(duration=40.0, visual_scale=1.05), seed=11)
    fix_t = s.truth.t[::int(round(0.2 / np.median(np.diff(s.truth.t))))]  # 5 Hz
    streams = SensorStreams(visual=s.visual, imu=s.imu, gps=gps_along(s.truth, fix_t, NOISE, np.random.default_rng(5)),
                            camera_height=s.camera_height, camera_height_sigma=0.05 * s.camera_height)
    streams = streams.select(["camera", "imu", "gps"])

    def rms(track):
        return position_errors(track, s.truth)[1]

    declared = fuse(streams, "all")
    gps = registry.get("gps")
    registry.register(dataclasses.replace(gps, absolute_distance=False), replace=True)
    try:
        held = fuse(streams, "all")
    finally:
        registry.register(gps, replace=True)
    for name in ("ekf", "ekf_smoothed", "gtsam_online", "gtsam"):
        assert abs(declared.calibration[name]["visual_scale"] - 1.05) < 0.01, (name, declared.calibration[name])
        assert "visual_scale" not in held.calibration[name]  # held: not reported as an estimate
        assert rms(declared.trajectories[name]) < 0.03 and rms(declared.trajectories[name]) < 0.6 * rms(
            held.trajectories[name]), (name, rms(declared.trajectories[name]), rms(held.trajectories[name]))


def _stream_with_gps(rec, gps_delay=0.0, backend="ekf", fixes=None, **kwargs):
    """The streaming EKF (or iSAM2) fed in arrival order, the fixes (default: the recording's) arriving
    ``gps_delay`` seconds after their time (every other one twice that: they also arrive out of order)."""
    wheel, imu, gps = read_ticks(rec), read_imu(rec), read_fixes(rec) if fixes is None else fixes
    fusion = StreamingFusion(backend, sensors=["wheel", "imu", "gps"], wheel_config=wheel.config,
                             imu_T_BS=imu.T_BS, imu_noise=imu.noise, gps_lever_arm=gps.lever_arm, **kwargs)
    events = [(t, 0, i) for i, t in enumerate(wheel.t)] + [(t, 1, i) for i, t in enumerate(imu.t)]
    events += [(t + gps_delay * (1.0 + i % 2), 2, i) for i, t in enumerate(gps.t)]
    for _, kind, i in sorted(events):
        if kind == 0:
            fusion.add_wheel(WheelTicks(wheel.t[i], int(wheel.left[i]), int(wheel.right[i])))
        elif kind == 1:
            fusion.add_imu(ImuSample(imu.t[i], imu.gyro[i], imu.accel[i]))
        else:
            fusion.add_gps(GpsFix(gps.t[i], gps.enu[i, :2], gps.covariance[i]))
    return fusion


@pytest.fixture(scope="module")
def ekf_streamed(rec):
    """The streaming EKF fed the drive in time order: its frame at the end, and its result."""
    fusion = _stream_with_gps(rec)
    return fusion.current_estimate().frame, fusion.finish()


def test_streaming_ekf_with_gps_ends_in_enu(rec, truth, ekf_streamed):
    frame, result = ekf_streamed
    assert frame == "enu"
    t, e = errors(result.trajectories["ekf"], truth)
    late = (t > OUTAGE[1] + 2.0)
    assert np.sqrt(np.mean(e[late] ** 2)) <= NOISE
    counts = result.counts["ekf"]["gps"]
    assert counts.gated == 5
    # fed in time order, no fix is late: the one at the first node is kept for the alignment (it was counted late)
    assert counts.late == 0
    assert counts.used + counts.gated + counts.missing + counts.late == len(read_fixes(rec).t)
    assert any(f"ekf: gps {counts.used} fixes used, 5 rejected" in n for n in result.notes)


def _heading_errors(track: PoseData, truth: PoseData) -> np.ndarray:
    """Heading error of every pose [rad], wrapped."""
    return se2.wrap_angle(track.xyyaw[:, 2] - np.interp(track.t, truth.t, np.unwrap(truth.xyyaw[:, 2])))


def test_the_streamed_heading_after_the_switch_to_enu_is_within_its_stated_sigma(streamed, truth, fused):
    """Streaming turns the world into ENU with the fixes so far (here 6.4 s in: 41.1 deg, fit sigma 3.1 deg; truth
    40), a batch run with the whole log's (40.2 deg, 0.45). The streamed heading stays up to 5.8 deg off for the rest
    of the drive, and its covariance says so: every error within 3 of its stated sigma. The batch EKF's stays under
    1 deg; over the last 6 s the streamed positions are about 3 cm from the truth, the batch EKF's 0.6 cm."""
    result = streamed["ekf"]
    switch = next(n for n in result.notes if n.startswith("gps: world frame re-expressed in ENU"))
    assert "first heading 41.09" in switch and "± 3.14" in switch, switch
    for name, run in (("ekf", result), ("gtsam_online", streamed["gtsam"])):
        track, cov = run.trajectories[name], np.asarray(run.covariances[name])
        after = track.t - truth.t[0] > 8.0
        err = _heading_errors(track, truth)[after]
        assert math.radians(3.0) < np.max(np.abs(err)) < math.radians(7.0), name  # the fixes so far cost this much
        assert np.all(np.abs(err) <= 3.0 * np.sqrt(cov[after, 2, 2])), name
    batch = fused.trajectories["ekf"]
    assert np.max(np.abs(_heading_errors(batch, truth)[batch.t - truth.t[0] > 8.0])) < math.radians(1.0)
    last = [np.sqrt(np.mean(e[t > 18.0] ** 2)) for t, e in (errors(result.trajectories["ekf"], truth),
                                                            errors(batch, truth))]
    assert 0.02 < last[0] < 0.045 and last[1] < 0.01, last


def test_the_re_acquisition_rule():
    """A rejected reading is applied anyway ``after`` seconds or more after the last one applied (or after the
    first reading, when none was applied); with ``after`` 0, every reading is."""
    re = Reacquire(0.5)
    decided = [(t, re.due(t, ok)) for t, ok in [(0.0, True), (0.2, False), (0.4, False), (0.6, False), (0.8, False),
                                                 (1.0, True), (1.2, False)]]
    assert [t for t, applied in decided if applied] == [0.6] and re.times == [0.6], decided
    first_rejected = Reacquire(0.5)
    assert [first_rejected.due(t, False) for t in (0.0, 0.4, 0.5, 0.7)] == [False, False, True, False]
    always = Reacquire(0.0)
    assert [always.due(t, False) for t in (0.0, 0.1, 0.2)] == [True, True, True]


def test_a_jump_longer_than_gps_reacquire_is_re_acquired_at_the_same_fix_batch_and_streaming(rec):
    """With ``gps_reacquire`` 0.5 s the jump's five fixes (0.8 s) are rejected until the third, which is applied
    anyway; the estimate then jumps with it and re-acquires the true fixes after the jump the same way. The
    batch EKF and the streaming EKF (one rule, :class:`~fusion_vo.backends.fixes.Reacquire`) say so alike."""
    config = FusionConfig(gps_reacquire=0.5)
    batch = fuse(streams_from_recording(rec, None, ["wheel", "imu", "gps"]), "ekf", config)
    streamed = _stream_with_gps(rec, config=config).finish()
    for result in (batch, streamed):
        (note,) = [n for n in result.notes if n.startswith("ekf: gps") and "fixes used" in n]
        assert "4 rejected" in note and result.counts["ekf"]["gps"].gated == 4, note
        assert "2 times a fix was applied anyway" in note and f"first at {JUMP[0] + 0.4:.2f} s in" in note, note


def _outage(notes) -> tuple[float, float, float]:
    """``(start, end, drift)`` of the one outage note."""
    (note,) = [n for n in notes if n.startswith("ekf: gps outage")]
    start, end = note.split("from ")[1].split(" s in")[0].split(" to ")
    return float(start), float(end), float(note.split("drift ")[1].split(" m")[0])


def test_streaming_ekf_reports_the_outage_as_a_batch_run_does(ekf_streamed, fused, truth):
    """The first fix after the 5 s outage measures how far the streamed estimate drifted without fixes, as in a batch
    run; the streamed track's own error there bounds it."""
    result = ekf_streamed[1]
    start, end, drift = _outage(result.notes)
    b_start, b_end, b_drift = _outage(fused.notes)
    assert abs(start - b_start) < 0.01 and abs(end - b_end) < 0.01 and OUTAGE[0] - 0.5 < start < end < OUTAGE[1] + 0.5
    t, e = errors(result.trajectories["ekf"], truth)
    before_the_fix = e[(t >= end - 1.0) & (t < end)].max()
    assert 0.5 * before_the_fix < drift < before_the_fix + 3 * NOISE, (drift, before_the_fix)
    assert abs(drift - b_drift) < 0.3 * b_drift, (drift, b_drift)


def _replays() -> dict:
    """``fusion-vo replay --sensors wheel,imu,gps`` and ``--sensors wheel,imu`` of the drive, each backend: per
    backend and sensors, the info ``replay.json`` holds, the distance of the track's end from the truth [m], and
    the number of fixes in the recording."""
    with tempfile.TemporaryDirectory() as tmp:
        rec = _simulated(Path(tmp) / "rec")
        gt = rec.groundtruth()
        truth = PoseData(gt.t, gps_model.Alignment(math.radians(HEADING), ORIGIN, 0.0, 0).apply(gt.xyyaw))
        runs = {"fixes": len(read_fixes(rec).t)}
        for backend in ("ekf", "gtsam"):
            for sensors in ("wheel,imu,gps", "wheel,imu"):
                out = Path(tmp) / f"{backend}_{sensors.count(',')}"
                code = main(["-q", "replay", str(rec.path), "--out", str(out), "--speed", "0", "--backend", backend,
                             "--sensors", sensors])
                info = json.loads((out / "replay.json").read_text()) if code == 0 else None
                track = read_tum_poses(out / f"stream_{backend}.tum") if code == 0 else None
                end = None if track is None else float(np.hypot(*(track.xyz[-1, :2] - [
                    np.interp(track.t[-1], truth.t, truth.xyyaw[:, k]) for k in (0, 1)])))
                runs[backend, sensors] = {"code": code, "info": info, "end": end}
    return runs


@pytest.mark.parametrize("backend", ["ekf", "gtsam"])
def test_replay_fuses_the_gps_it_is_given(made_ahead, backend):
    """``fusion-vo replay --sensors wheel,imu,gps`` streams the fixes: the live track ends in ENU at the truth,
    every fix is counted, the 5 jumped ones gated; without GPS the track stays in the start frame, metres off."""
    runs = made_ahead("replays")
    for sensors in ("wheel,imu,gps", "wheel,imu"):
        run = runs[backend, sensors]
        assert run["code"] == 0
        assert run["info"]["sensors"] == sensors.split(",")
    counts = runs[backend, "wheel,imu,gps"]["info"]["counts"]["gps"]
    assert counts["gated"] == 5
    assert counts["used"] + counts["gated"] + counts["missing"] + counts["late"] == runs["fixes"]
    assert runs[backend, "wheel,imu,gps"]["end"] < 2 * NOISE
    assert runs[backend, "wheel,imu"]["end"] > 1.0


def test_late_gps_fixes_are_re_applied_exactly_as_in_order(rec, ekf_streamed):
    """Fixes 0.4-0.8 s late and out of order rewind the EKF, across the switch to ENU too."""
    a, b = ekf_streamed[1], _stream_with_gps(rec, gps_delay=0.4)
    assert b.rewinds > 50
    b = b.finish()
    ca, cb = a.counts["ekf"], b.counts["ekf"]
    assert cb["gps"].reordered > 20
    cb["gps"].reordered = 0
    assert {k: v.as_dict() for k, v in cb.items()} == {k: v.as_dict() for k, v in ca.items()}
    ta, tb = a.trajectories["ekf"], b.trajectories["ekf"]
    np.testing.assert_allclose(tb.t, ta.t, atol=1e-12)
    np.testing.assert_allclose(tb.xyyaw, ta.xyyaw, atol=1e-9, rtol=0)
    assert [n for n in b.notes if "ENU" in n] == [n for n in a.notes if "ENU" in n]
    assert [n for n in b.notes if "outage" in n] == [n for n in a.notes if "outage" in n] != []


# --------------------------------------------------------------------------- streaming iSAM2
def _streamed(streams, backend: str, delay: float = 0.0, **kwargs) -> StreamingFusion:
    """``StreamingFusion`` for ``streams`` fed in arrival order, the fixes ``delay`` seconds after their time (every
    other one twice that: out of order too)."""
    fusion = streaming_for(streams, backend, **kwargs)
    msgs = time_ordered_messages(streams)
    if delay:
        fixes = [m for m in msgs if m[1] == "gps"]
        msgs = [m for m in msgs if m[1] != "gps"] + [(t + delay * (1.0 + i % 2), k, m) for i, (t, k, m) in enumerate(fixes)]
        msgs.sort(key=lambda m: m[0])
    fusion.feed(msgs)
    return fusion


def _difference(a: PoseData, b: PoseData) -> np.ndarray:
    """Horizontal distance [m] between two tracks at ``a``'s times within ``b``'s span."""
    t = a.t[(a.t >= b.t[0]) & (a.t <= b.t[-1])]
    return np.hypot(*[np.interp(t, a.t, a.xyyaw[:, i]) - np.interp(t, b.t, b.xyyaw[:, i]) for i in range(2)])


@pytest.fixture(scope="module")
def gps_streams(rec):
    return streams_from_recording(rec, None, ["wheel", "imu", "gps"])


@pytest.fixture(scope="module")
def streamed(gps_streams, ekf_streamed):
    """The drive streamed to iSAM2 with GPS (its frame at the end), without GPS, and to the EKF with GPS (the run of
    ``ekf_streamed``: fed sample by sample, it equals the EKF fed these streams' messages bit for bit)."""
    isam = _streamed(gps_streams, "gtsam")
    frame = isam.current_estimate().frame
    return {"gtsam": isam.finish(), "frame": frame, "ekf": ekf_streamed[1],
            "free": _streamed(gps_streams.replace(gps=None), "gtsam").finish()}


def _present_rms(track: PoseData, truth: PoseData) -> float:
    t, e = errors(track, truth)
    present = ~((t >= OUTAGE[0]) & (t <= OUTAGE[1] + 1.0))
    return float(np.sqrt(np.mean(e[present] ** 2)))


def test_streaming_isam2_with_gps_ends_in_enu_where_it_fails_without(streamed, truth):
    """Measured: 28 mm from the truth at the end, RMS 29 mm while the fixes are present (the streaming EKF: 28 and
    30 mm); the same stream without GPS ends in the start frame, 6 m from it (fitted afterwards to every fix, future
    ones included, it would be 5 mm off on this short drive; an antenna without its lever arm gives RMS 0.98 m)."""
    assert streamed["frame"] == "enu"
    track = streamed["gtsam"].trajectories["gtsam_online"]
    assert errors(track, truth)[1][-1] <= NOISE
    assert _present_rms(track, truth) <= 0.7 * NOISE
    free = streamed["free"].trajectories["gtsam_online"]
    assert errors(free, truth)[1][-1] > 1.0 and _present_rms(free, truth) > 1.0


def test_streaming_isam2_with_gps_is_the_streaming_ekf_and_near_the_batch_track(streamed, fused):
    """The two streaming backends differ by 4.3 mm RMS (12 mm at most); the batch run's online iSAM2 track, which
    starts in ENU aligned with the whole drive's fixes, by 36 mm RMS (0.10 m at most, after the streaming alignment)."""
    isam = streamed["gtsam"].trajectories["gtsam_online"]
    d = _difference(isam, streamed["ekf"].trajectories["ekf"])
    assert np.sqrt(np.mean(d ** 2)) < 0.01 and d.max() < 0.03
    d = _difference(isam, fused.trajectories["gtsam_online"])
    assert np.sqrt(np.mean(d ** 2)) < 0.06 and d.max() < 0.15


def test_streaming_isam2_counts_every_fix_as_the_ekf_does(streamed, rec):
    counts = {b: streamed[b].counts[n]["gps"] for b, n in (("gtsam", "gtsam_online"), ("ekf", "ekf"))}
    assert counts["gtsam"].as_dict() == counts["ekf"].as_dict()
    c = counts["gtsam"]
    assert c.gated == 5  # the multipath jump
    assert c.used + c.gated + c.missing + c.late == len(read_fixes(rec).t)
    assert any(n.startswith(f"gtsam_online: gps {c.used} fixes used, 5 rejected") and "ENU at the datum" in n
               for n in streamed["gtsam"].notes)
    assert sum(n.startswith("gps: world frame re-expressed in ENU") for n in streamed["gtsam"].notes) == 1


def test_streaming_isam2_gates_and_counts_a_wild_fix(gps_streams, streamed, truth):
    """One more fix, 1 km off, in a stretch of good fixes: gated, counted, and the track as without it."""
    g = gps_streams.gps
    i = int(np.searchsorted(g.t, g.t[0] + 20.0))
    t = 0.5 * (g.t[i] + g.t[i + 1])
    wild = dataclasses.replace(g, t=np.insert(g.t, i + 1, t), enu=np.insert(g.enu, i + 1, g.enu[i] + [1000.0, 0.0, 0.0], 0),
                               covariance=np.insert(g.covariance, i + 1, g.covariance[i], 0),
                               geodetic=np.insert(g.geodetic, i + 1, g.geodetic[i], 0), status=np.insert(g.status, i + 1, 0))
    result = _streamed(gps_streams.replace(gps=wild), "gtsam").finish()
    before = streamed["gtsam"].counts["gtsam_online"]["gps"]
    after = result.counts["gtsam_online"]["gps"]
    assert (after.gated, after.used) == (before.gated + 1, before.used)
    d = _difference(result.trajectories["gtsam_online"], streamed["gtsam"].trajectories["gtsam_online"])
    assert d.max() < 0.002


def test_streaming_isam2_background_equals_the_callers_thread(gps_streams, streamed):
    result = _streamed(gps_streams, "gtsam", background=True).finish()
    np.testing.assert_array_equal(result.trajectories["gtsam_online"].xyyaw,
                                  streamed["gtsam"].trajectories["gtsam_online"].xyyaw)
    assert result.counts["gtsam_online"]["gps"].as_dict() == streamed["gtsam"].counts["gtsam_online"]["gps"].as_dict()


def test_late_fixes_are_placed_on_isam2s_nodes(gps_streams, streamed, truth, rec):
    """Fixes 0.4-0.8 s late (beyond the reorder window) and out of order: each is re-timed onto its nearest node and
    that node rebuilt; measured: RMS 24 mm (28 mm in order), the track 13 mm RMS from the in-order one (the
    alignment fell one fix earlier). The fix at the first node, late too, is kept for the alignment as in order."""
    fusion = _streamed(gps_streams, "gtsam", delay=0.4)
    assert fusion.rewinds > 50
    result = fusion.finish()
    c, in_order = result.counts["gtsam_online"]["gps"], streamed["gtsam"].counts["gtsam_online"]["gps"]
    assert c.gated == 5 and c.late == in_order.late == 0
    assert c.used + c.gated + c.missing + c.late == len(read_fixes(rec).t)
    track = result.trajectories["gtsam_online"]
    assert _present_rms(track, truth) <= 0.7 * NOISE
    d = _difference(track, streamed["gtsam"].trajectories["gtsam_online"])
    assert np.sqrt(np.mean(d ** 2)) < 0.025


def test_fixes_later_than_the_history_are_counted_late(gps_streams, rec):
    result = _streamed(gps_streams, "gtsam", delay=1.5, history=1.0).finish()
    c = result.counts["gtsam_online"]["gps"]
    assert c.late > 50 and c.used + c.gated + c.missing + c.late == len(read_fixes(rec).t)
    assert any(n.startswith("late measurements not applied: ") and f"gps {c.late}" in n for n in result.notes)


def test_bad_gps_option_is_a_one_line_error():
    from fusion_vo.backends import FusionConfig
    from fusion_vo.errors import InputError

    with pytest.raises(ValueError, match=r"gps\.kernel: expected one of 'huber', 'cauchy' or 'none', got 'tukey'"):
        FusionConfig.from_dict({"gps": {"kernel": "tukey"}})
    with pytest.raises(InputError, match="gps_lever_arm|lever"):
        StreamingFusion("gtsam", sensors=["imu", "gps"], gps_lever_arm=[0.1, 0.2, float("nan")])


# --------------------------------------------------------------------------- Husky (real recording)
#: the import the Husky tests read, made ahead in the background (tests/background.py, tests/conftest.py)
#: the longer runs of :data:`AHEAD` are made in the session's second process too (tests/ahead_job.py)
_AHEAD_COMMANDS, _AHEAD = ahead_jobs(__file__)
BACKGROUND_COMMANDS = {**_AHEAD_COMMANDS,
                       "python:husky_gps_stream": ["{repo}/tests/backends/husky_gps_stream_job.py", "{fusion-vo:husky_log}"]}
BACKGROUND_JOBS = {**_AHEAD,
                   "test_husky_gps_of_the_first_minute_then_withheld": ["fusion-vo:husky_log"],
                   "test_husky_streamed_with_the_gps_of_the_first_minute": ["fusion-vo:husky_log",
                                                                            "python:husky_gps_stream"]}


@pytest.fixture(scope="module")
def husky(husky_log):
    """test1.bag, first 120 s: odometry and IMU, the fixes of the first 60 s and those of the next 60 s
    (``husky_log``: the bag imported with its launch file's IMU transform, tests/conftest.py)."""
    part, first, second = husky_parts(husky_log)
    free = fuse(part, "ekf")
    placed = {name: gps_model.align_to_fixes(free.trajectories[name].t, free.trajectories[name].xyyaw, first)
              for name in ("wheel", "ekf")}
    baseline = {name: withheld_rms(PoseData(free.trajectories[name].t, fit.apply(free.trajectories[name].xyyaw)),
                                    second) for name, fit in placed.items()}
    return part, first, second, baseline


def test_husky_gps_of_the_first_minute_then_withheld(husky):
    """test1.bag, first 120 s: GPS fused for 60 s, the next 60 s scored against the withheld fixes,
    beside wheel dead reckoning and the filter without GPS placed in ENU by the same first-minute fixes."""
    part, first, second, baseline = husky
    # the receiver claims 0.9 m; its fixes scatter about 2 m around any smooth track: that is the floor
    fused = fuse(part.replace(gps=first), "ekf", {"gps": {"min_sigma": 2.0}})
    assert any(n.startswith("gps: world frame is ENU") for n in fused.notes)
    rms = withheld_rms(fused.trajectories["ekf"], second)
    assert rms < 0.5 * baseline["wheel"], (rms, baseline)
    assert rms < 1.1 * baseline["ekf"], (rms, baseline)


def test_husky_streamed_with_the_gps_of_the_first_minute(husky_log, ahead_json):
    """The same streamed to both backends, with the same 2 m floor: the world frame switches to ENU once, every fix
    is counted alike, and iSAM2 follows the EKF (measured: antenna RMS to the fused fixes 2.06 / 2.07 m, 22.0 /
    22.4 m on the withheld minute: the heading of ENU found causally from the first fixes, where a batch run fits
    the whole minute). The streams run in the session's second process (husky_gps_stream_job.py)."""
    got = ahead_json("python:husky_gps_stream", lambda: husky_gps_figures(husky_log))
    ekf, gtsam = got["ekf"], got["gtsam"]
    assert ekf["switches"] == 1 and gtsam["switches"] == 1
    c = gtsam["counts"]
    assert c == ekf["counts"] and c["used"] + c["gated"] + c["missing"] + c["late"] == got["n_fixes"]
    fe, fg, we, wg = ekf["fused_rms"], gtsam["fused_rms"], ekf["withheld_rms"], gtsam["withheld_rms"]
    assert fg < 2.5 and abs(fg - fe) < 0.1 * fe
    assert abs(wg - we) < 0.1 * we


def test_husky_cut_with_gps_from_the_command_line(tmp_path):
    """The 12 s cut: ``fusion-vo run --sensors odom,imu,gps`` fuses the fixes, counts every one and says
    how the heading of ENU was found."""
    import json
    from pathlib import Path

    import yaml

    from fusion_vo.cli.main import main

    bag = Path(__file__).resolve().parents[1] / "data" / "robot_localization" / "test1_140s_to_152s.bag"
    tf = "0 -0.3 0.52 -1.570796327 0 1.570796327 base_link imu_link"
    seq, out = tmp_path / "cut", tmp_path / "out"
    assert main(["-q", "import-bag", str(bag), str(seq), "--static-tf", tf]) == 0
    assert main(["-q", "run", str(seq), "--out", str(out), "--sensors", "odom,imu,gps", "--backend", "all"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    n = len(read_fixes(Recording(seq)))
    for name in ("ekf", "gtsam"):
        c = summary["fusion"]["counts"][name]["gps"]
        assert c["used"] + c["gated"] + c["missing"] == n and c["used"] > n // 2
    assert any(note.startswith("gps: ") and "first heading" in note for note in summary["notes"])
    assert "gps" in yaml.safe_load((out / "run.yaml").read_text())["sensors"]


# ---------------------------------------------------------------------- the fixes' scatter measured
SCATTER_TRUE = 0.2  # [m] per axis: what the simulated receiver's fixes scatter
SCATTER_OPTIONS = {"duration": 40.0, "gps": True, "gps_rate": 5.0, "gps_noise": SCATTER_TRUE,
                   "gps_lever_arm": [-0.3, 0.2, 0.5], "gps_heading_deg": HEADING, "gps_origin": ORIGIN.tolist()}


def _scatter_simulated(folder) -> Recording:
    return Recording(simulate(folder, profile="random", seed=5, **{**TINY, **SCATTER_OPTIONS}))


@pytest.fixture(scope="module")
def scatter_rec(tmp_path_factory):
    return _scatter_simulated(tmp_path_factory.mktemp("gpsscatter") / "rec")


def _stated(streams, sigma):
    """The same fixes, each claiming ``sigma`` per axis."""
    gps = streams.gps
    cov = np.tile(np.eye(2) * sigma ** 2, (len(gps.t), 1, 1))
    return streams.replace(gps=dataclasses.replace(gps, covariance=cov))


def _aligned(streams, options):
    from fusion_vo.backends.batch import as_config, build_intervals
    from fusion_vo.backends.world import align_world

    config = as_config(options)
    iv = build_intervals(streams, config)
    align_world(iv, config)
    return iv


def _scatter_claimed_a_quarter() -> tuple:
    """The receiver of ``scatter_rec`` claiming a quarter of its true scatter: the alignment's notes and measured
    sigma, and the batch runs with the scatter estimated and with the claim (notes and GPS counts of each)."""
    with tempfile.TemporaryDirectory() as tmp:
        rec = _scatter_simulated(Path(tmp) / "rec")
        streams = _stated(streams_from_recording(rec, None, ["wheel", "imu", "gps"]), SCATTER_TRUE / 4)
    iv = _aligned(streams, {"gps": {"estimate_sigma": True}})
    runs = {}
    for estimate in (True, False):
        result = fuse(streams, "all", {"gps": {"estimate_sigma": estimate}})
        runs[estimate] = (result.notes, {name: result.counts[name]["gps"].as_dict() for name in ("ekf", "gtsam")})
    return iv.notes, gps_model.gps_grid(iv).min_sigma, runs


def test_fixes_scattering_four_times_their_claim_are_fused_with_the_measured_sigma(made_ahead):
    """A receiver claiming a quarter of its true scatter: the alignment measures the scatter, both backends
    fuse with it, and the gate, which with the claim throws most genuine fixes away (measured: EKF 158,
    graph 125 of 201), rejects none."""
    notes, min_sigma, runs = made_ahead("scatter_claimed_a_quarter")
    # the estimate's standard error is about sigma / sqrt(2 m) for the m = 161 fixes of the alignment (32 s):
    # 3 of them (measured 0.1996 m)
    assert any("(161 fixes of the alignment" in n for n in notes), notes
    assert min_sigma == pytest.approx(SCATTER_TRUE, rel=3.0 / math.sqrt(2 * 161)), min_sigma
    (measured_notes, measured), (claimed_notes, claimed) = runs[True], runs[False]
    assert any("fixes scatter" in n and "fusion.gps.estimate_sigma: false" in n for n in measured_notes)
    assert not any("fixes scatter" in n for n in claimed_notes)
    for name in ("ekf", "gtsam"):
        assert measured[name]["gated"] == 0, (name, measured[name])
        assert claimed[name]["gated"] > 10, (name, claimed[name])


def test_honest_fixes_keep_their_stated_sigma(scatter_rec):
    """Fixes that scatter as they claim: no floor is raised and the estimate changes nothing."""
    streams = streams_from_recording(scatter_rec, None, ["wheel", "imu", "gps"])
    iv = _aligned(streams, {"gps": {"estimate_sigma": True}})
    assert gps_model.gps_grid(iv).min_sigma is None
    on = fuse(streams, "ekf", {"gps": {"estimate_sigma": True}})
    off = fuse(streams, "ekf", {"gps": {"estimate_sigma": False}})
    np.testing.assert_array_equal(on.trajectories["ekf"].xyyaw, off.trajectories["ekf"].xyyaw)
    assert not any("fixes scatter" in n for n in on.notes)


def test_scatter_floor_accounts_for_the_tracks_drift():
    """The χ² test against stated sigma and drift: residuals explained by the track's own drift raise nothing."""
    fit = gps_model.Alignment(0.0, np.zeros(2), rms=math.sqrt(2) * 0.5, n=101)
    assert gps_model.scatter_floor(fit, 0.3).significant
    assert gps_model.scatter_floor(fit, 0.3).sigma == pytest.approx(0.5 * math.sqrt(202 / 199))
    drifting = gps_model.scatter_floor(fit, 0.3, drift_var=0.45 ** 2)
    assert not drifting.significant and drifting.sigma < 0.3
    assert not gps_model.scatter_floor(fit, 0.5).significant


AHEAD = {"replays": _replays, "scatter_claimed_a_quarter": _scatter_claimed_a_quarter}
