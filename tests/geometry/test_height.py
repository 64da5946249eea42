"""The camera height from range readings and the frames' scale (fusion_vo.geometry.height)."""

import math

import numpy as np
import pytest
import yaml

from fusion_vo.geometry.height import _inverse_bands, _solve, smooth_heights
from fusion_vo.sensors.range import read_range

RATE, READ_RATE, SIGMA_R = 20.0, 40.0, 0.0005


def heights(t):
    return 0.1 + 0.001 * np.sin(2 * math.pi * 3.0 * t)


def drive(seed=0, duration=20.0, ratio_noise=2e-5, stated=2e-5):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 1.0 / RATE)
    log_ratio = np.r_[np.nan, np.diff(np.log(heights(t)))] + ratio_noise * rng.standard_normal(len(t))
    sigma = np.full(len(t), stated)
    rt = np.sort(rng.uniform(t[0], t[-1], int(duration * READ_RATE)))
    r = heights(rt) + SIGMA_R * rng.standard_normal(len(rt))
    return t, log_ratio, sigma, rt, r


def test_inverse_bands_are_those_of_the_dense_inverse():
    rng = np.random.default_rng(3)
    n = 12
    ip = rng.uniform(0.5, 2.0, n - 1)
    j = rng.integers(0, n - 1, 30)
    a = rng.uniform(0, 1, 30)
    ir = rng.uniform(0.1, 1.0, 30)
    upper, _ = _solve(n, ip, np.zeros(n - 1), ir, np.zeros(30), j, 1 - a, a)
    dense = np.diag(upper[1]) + np.diag(upper[0, 1:], 1)
    inverse = np.linalg.inv(dense.T @ dense)
    d, e = _inverse_bands(upper)
    assert d == pytest.approx(np.diag(inverse), rel=1e-10)
    assert e == pytest.approx(np.diag(inverse, 1), rel=1e-10)


def test_heights_are_far_better_than_one_reading_and_state_their_error():
    errors, nees = [], []
    for seed in range(3):
        t, lr, ls, rt, r = drive(seed)
        out = smooth_heights(t, lr, ls, rt, r, SIGMA_R)
        e = out.height - heights(t)
        errors.append(np.sqrt(np.mean(e**2)))
        nees.append(np.mean((e / out.sigma) ** 2))
        assert out.ratio_factor < 1.5  # the ratios are as good as stated
    # one reading is 0.5 mm; all of them with the ratios give a few hundredths of a millimetre
    assert max(errors) < 0.05e-3
    assert 0.3 < np.mean(nees) < 2.0


def test_ratios_noisier_than_stated_are_weighed_down():
    t, lr, ls, rt, r = drive(1, ratio_noise=5e-4, stated=2e-5)
    out = smooth_heights(t, lr, ls, rt, r, SIGMA_R)
    e = out.height - heights(t)
    assert out.ratio_factor > 50  # (5e-4)² against (2e-5)² + (3e-5)² + walk: about 180
    assert np.mean((e / out.sigma) ** 2) < 2.0
    assert np.sqrt(np.mean(e**2)) < 0.5 * SIGMA_R


def test_a_spike_moves_the_heights_around_it_by_little():
    t, lr, ls, rt, r = drive(2)
    clean = smooth_heights(t, lr, ls, rt, r, SIGMA_R)
    r = r.copy()
    r[len(r) // 2] += 0.01  # 1 cm: 20 of the readings' sigmas
    out = smooth_heights(t, lr, ls, rt, r, SIGMA_R)
    assert out.n_downweighted >= 1
    assert np.max(np.abs(out.height - clean.height)) < 0.02e-3


def test_frames_without_a_ratio_follow_the_readings():
    t, lr, ls, rt, r = drive(4)
    gap = (t > 8.0) & (t < 9.5)
    lr[gap] = np.nan
    out = smooth_heights(t, lr, ls, rt, r, SIGMA_R)
    e = out.height - heights(t)
    assert np.sqrt(np.mean(e[gap] ** 2)) < SIGMA_R  # the readings alone, a few of them per frame
    assert np.median(out.sigma[gap]) > 3 * np.median(out.sigma[~gap])


def test_too_few_readings_give_nothing():
    t, lr, ls, rt, r = drive(5)
    assert smooth_heights(t, lr, ls, rt[:1], r[:1], SIGMA_R) is None
    assert smooth_heights(t, lr, ls, rt, r, 0.0) is None


@pytest.fixture(scope="module")
def tilted(tmp_path_factory):
    from fusion_vo.simulation.generate import simulate

    return simulate(tmp_path_factory.mktemp("tilted") / "seq", profile="random", seed=7, duration=5.0,
                    tilt_x_deg=3.0, tilt_y_deg=-2.0, height_vibration=0.001, range_finder=True,
                    width=320, height=180, fu=210.0, fv=210.0, cu=159.5, cv=89.5)


def ate_against(rec):
    """``ate(track)``: a track's ATE [m] against ``rec``'s ground truth after SE(2) alignment."""
    from fusion_vo.evaluation.metrics import align_se2, ape_rmse, associate, planar_trajectory

    gt = rec.groundtruth()
    reference = planar_trajectory(gt.t, gt.xyyaw[:, 0], gt.xyyaw[:, 1], gt.xyyaw[:, 2])

    def ate(track):
        ref, est = associate(reference, planar_trajectory(track.t, *track.xyyaw.T))
        return ape_rmse(ref, align_se2(ref, est))

    return ate


def test_visual_odometry_scales_each_frame_by_the_smoothed_height(tilted):
    from fusion_vo.odometry import OdometryConfig, run_visual_odometry
    from fusion_vo.recording import Recording

    rec = Recording(tilted)
    ate = ate_against(rec)
    runs = {}
    for smoothing in (False, True):
        vo = run_visual_odometry(rec, OdometryConfig(range_smoothing=smoothing))
        assert vo.range_scaled and len(vo.frame_height) == len(vo.frame_t)
        assert (vo.height_note is not None) == smoothing  # the run's notes say what the smoothing used
        e = vo.frame_height - heights(vo.frame_t)  # the simulator's 0.1 m with 1 mm at 3 Hz
        runs[smoothing] = (np.sqrt(np.mean(e**2)), ate(vo.track))
    (h_plain, ate_plain), (h_smooth, ate_smooth) = runs[False], runs[True]
    assert h_plain > 0.4e-3  # each frame's own readings: their 0.5 mm noise
    assert h_smooth < 0.1 * h_plain
    assert ate_smooth < 0.85 * ate_plain  # 0.032 against 0.045 mm on this drive
    assert "range readings" in vo.height_note


def stream(t, lr, ls, rt, r, hf):
    """Feed a drive to ``hf`` in time order; the height and sigma at each frame (NaN before the first)."""
    out, j = [], 0
    for k, tk in enumerate(t):
        while j < len(rt) and rt[j] <= tk:
            hf.add_reading(rt[j], r[j])
            j += 1
        got = hf.frame(tk, None if k == 0 else lr[k], None if k == 0 else ls[k])
        out.append(got if got is not None else (np.nan, np.nan))
    return np.array(out)


def test_the_live_filter_is_far_better_than_the_newest_reading():
    from fusion_vo.geometry.height import HeightFilter

    for seed in range(3):
        t, lr, ls, rt, r = drive(seed)
        out = stream(t, lr, ls, rt, r, HeightFilter(SIGMA_R))
        late = t > 2.0  # once a couple of seconds of readings are in
        e = out[late, 0] - heights(t[late])
        newest = r[np.searchsorted(rt, t[late], side="right") - 1] - heights(t[late])
        assert np.sqrt(np.mean(newest**2)) > 0.5e-3  # a reading's noise, and the vibration since it
        assert np.sqrt(np.mean(e**2)) < 0.06e-3
        assert 0.3 < np.mean((e / out[late, 1]) ** 2) < 2.0


def test_the_live_filter_takes_the_ratio_factor_it_is_given():
    from fusion_vo.geometry.height import HeightFilter

    t, lr, ls, rt, r = drive(1, ratio_noise=5e-4, stated=2e-5)
    late = t > 2.0
    nees = {}
    for phi in (1.0, 100.0):
        out = stream(t, lr, ls, rt, r, HeightFilter(SIGMA_R, ratio_factor=phi))
        e = out[late, 0] - heights(t[late])
        nees[phi] = np.mean((e / out[late, 1]) ** 2)
    assert nees[1.0] > 20  # ratios 25 times noisier than stated, taken at their word
    assert 0.3 < nees[100.0] < 2.0
    with pytest.raises(ValueError):
        HeightFilter(SIGMA_R, ratio_factor=0.5)


def test_live_visual_odometry_with_the_height_filter(tilted):
    from fusion_vo.geometry.ground import GroundGeometry
    from fusion_vo.geometry.height import HeightFilter
    from fusion_vo.odometry import VisualOdometry
    from fusion_vo.recording import Recording
    from fusion_vo.sensors.range import reading_sigma
    from frontends import make_frontend

    rec = Recording(tilted)
    ate = ate_against(rec)
    rng = read_range(rec)
    geometry = GroundGeometry(rec.camera)
    runs = {}
    for label in ("newest reading", "filter"):
        hf = HeightFilter(reading_sigma(rng)) if label == "filter" else None
        vo = VisualOdometry(make_frontend("klt", {}, point_map=geometry.rectifier), geometry, height_filter=hf)
        j = 0
        for frame in rec.frames():
            while j < len(rng.t) and rng.t[j] <= frame.t:  # the readings taken by then, as they arrive
                if hf is not None:
                    vo.add_range(rng.t[j], rng.distance[j])
                j += 1
            height = None if hf is not None else float(rng.distance[max(j - 1, 0)])
            vo.process(frame.image, frame.t, height)
        runs[label] = ate(vo.track())
    assert runs["filter"] < 0.85 * runs["newest reading"]  # 0.013 against 0.037 mm on this drive


def test_a_spike_in_the_readings_does_not_scale_the_frames(tilted, tmp_path):
    # the range gate drops the spike for both ways of taking the height (it used to be interpolated into the
    # frames around it when the readings were taken frame by frame)
    import shutil

    from fusion_vo.odometry import range_heights
    from fusion_vo.recording import Recording

    seq = tmp_path / "spiked"
    shutil.copytree(tilted, seq)
    data = seq / "range0" / "data.csv"
    lines = data.read_text().splitlines()
    frames = Recording(tilted).frame_times
    readings = read_range(Recording(tilted)).t
    i = int(np.argmin(np.abs(readings - frames[len(frames) // 2])))  # the reading nearest a frame
    stamp, _ = lines[i + 1].split(",")
    lines[i + 1] = f"{stamp},0.5"  # 0.4 m above the floor's 0.1 m
    data.write_text("\n".join(lines) + "\n")
    clean, _ = range_heights(Recording(tilted), frames)
    spiked, _ = range_heights(Recording(seq), frames)
    assert np.max(np.abs(spiked - clean)) < 1e-3  # the neighbours' interpolation across the gap only


def test_the_fused_scale_keeps_the_range_finders_precision(tilted):
    """The frames were scaled with the range finder's heights, so the visual scale's prior is their
    precision, not the camera mount's ``height_sigma``: the wheels (radius error stated as 1 %) then no
    longer pull the fused scale off visual odometry's."""
    from fusion_vo import backends
    from fusion_vo.odometry import OdometryConfig, run_visual_odometry
    from fusion_vo.recording import Recording

    rec = Recording(tilted)
    ate = ate_against(rec)
    vo = run_visual_odometry(rec, OdometryConfig())
    result = backends.run_backends(rec, vo, sensors=["camera", "wheel"], backend="all")
    ranged = np.median(vo.frame_height_sigma) / rec.camera.T_BS[2, 3]
    assert any(n.startswith(f"visual scale: prior σ {ranged:.2g} from the range finder") for n in result.notes)
    assert result.calibration["ekf"]["visual_scale_sigma"] < 1.1 * ranged  # the prior it started from (0.1 % before)
    for name in ("ekf", "ekf_smoothed", "gtsam", "gtsam_online"):
        # with the mount's 0.1 mm as the prior: 8-11 ppm of scale and 2.2-2.6 % of ATE above visual odometry
        assert abs(result.calibration[name]["visual_scale"] - 1.0) < 3e-6  # now 1.2-1.5 ppm
        assert ate(result.trajectories[name]) < 1.015 * ate(vo.track)  # now 0.9-1.0 %


@pytest.mark.parametrize("use_range", [True, False])
def test_a_stream_takes_the_same_scale_priors_as_a_batch_run(tilted, use_range):
    """Streaming fusion of a recording (what ``fusion-vo replay`` runs) takes the visual scale's prior from
    the recording's files as a batch run does: from the range finder's heights that scaled the frames, or
    without them from ``height_sigma`` in ``cam0/sensor.yaml``. It used to take the configuration's 5 %, so
    the wheels set the scale (on the 20 s ``tilted`` drive the streamed EKF's ATE was 1.05 mm against the
    batch run's 0.19, on ``square`` 0.61 against 0.073). The range readings are not used again."""
    from fusion_vo import backends
    from fusion_vo.backends.batch import streams_from_recording
    from fusion_vo.backends.streaming import streaming_for, time_ordered_messages
    from fusion_vo.odometry import OdometryConfig, run_visual_odometry
    from fusion_vo.recording import Recording

    rec = Recording(tilted)
    ate = ate_against(rec)
    vo = run_visual_odometry(rec, OdometryConfig(use_range=use_range))
    streams = streams_from_recording(rec, vo, ["camera", "wheel", "imu"] + (["range"] if use_range else []))
    # the mount's stated height uncertainty reaches the fusion (the file states max(|error|, 0.1 mm) x height)
    stated = yaml.safe_load((tilted / "cam0" / "sensor.yaml").read_text())["height_sigma"]
    assert streams.camera_height_sigma == stated > 0
    offline = backends.fuse(streams, "ekf")
    fusion = streaming_for(streams, "ekf")
    fusion.feed(time_ordered_messages(streams))
    online = fusion.finish()
    assert ate(online.trajectories["ekf"]) < 1.05 * ate(offline.trajectories["ekf"])
    # every stream is honest: the live monitor drops nothing (it used to drop the gyro for the first
    # second, judging it before it had seen enough intervals to measure its 0.005 rad/s bias)
    assert not [n for n in online.notes if n.startswith("live monitor")]
    if use_range:
        assert any(n.startswith("visual scale: prior σ") for n in online.notes)
        assert any(n.startswith("range finder: already in the visual increments") for n in online.notes)
        assert "range" not in online.counts["ekf"]  # no reading used as a height measurement
