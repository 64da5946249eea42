"""Both frontends on frames with known motion (synthetic warps of photographed floors)."""

import math

import cv2
import numpy as np
import pytest

from frontends import make_frontend
from frontends.base import MotionStatus, similarity_params
from frontends.features import FeatureConfig
from frontends.klt import KltConfig

from frontend_frames import HEIGHT, WIDTH, as3, pair, render, sequence, similarity_about, start_map

KINDS = ["klt", "features", "direct"]
CENTRE = np.array([WIDTH / 2, HEIGHT / 2])

WARPS = [  # (texture, tx, ty, angle [deg], scale), rotation and scale about the image centre
    ("gravel", 0.4, -0.7, 0.0, 1.0),
    ("gravel", 12.5, 30.25, 2.6, 1.0),
    ("gravel", -40.0, 25.0, -5.0, 1.0),
    ("gravel", 3.0, 120.0, 1.5, 1.0),
    ("gravel", 5.0, -8.0, 0.0, 1.03),
    ("grass", -20.0, 10.0, 4.0, 0.97),
    ("grass", 0.0, -110.0, -2.0, 1.01),
    ("brick", 8.3, -6.1, 3.0, 1.02),
    ("brick", -60.0, 0.0, -1.0, 1.0),
]


def centre_error(matrix, truth):
    """Displacement error at the image centre [px]."""
    return np.hypot(*(matrix[:, :2] @ CENTRE + matrix[:, 2] - truth[:, :2] @ CENTRE - truth[:, 2]))


def measure(kind, frames, config=None, dt=0.05):
    fe = make_frontend(kind, config)
    return [fe.process(f, i * dt) for i, f in enumerate(frames)]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("warp", WARPS, ids=lambda w: "_".join(str(v) for v in w))
def test_recovers_known_warp(kind, warp):
    name, tx, ty, angle, scale = warp
    truth = similarity_about(*CENTRE, tx, ty, angle, scale)
    f0, f1 = pair(truth, name)
    first, m = measure(kind, [f0, f1])
    assert first.status is MotionStatus.FIRST
    assert m.ok, m.info
    err = m.params - similarity_params(truth)
    # measured: < 0.03 px, < 0.005 deg, < 7e-5 in log scale on these textures
    assert centre_error(m.matrix, truth) < 0.1
    assert abs(math.degrees(err[2])) < 0.01
    assert abs(err[3]) < 2e-4
    if kind != "direct":  # the direct frontend has no points
        assert m.n_inliers >= 10 and m.residual_rms < 0.1
    assert m.prev_timestamp == 0.0 and m.timestamp == 0.05
    assert m.info["path"] in ("predicted", "retry", "global") and m.info["time_ms"] > 0


@pytest.mark.parametrize("kind", KINDS)
def test_standstill_with_sensor_noise_does_not_drift(kind):
    rng = np.random.default_rng(4)
    base = render(start_map())
    frames = [np.clip(base + rng.normal(0, 2.0, base.shape), 0, 255).astype(np.uint8) for _ in range(12)]
    out = measure(kind, frames)
    steps = [centre_error(m.matrix, np.eye(2, 3)) for m in out[1:]]
    assert all(m.ok for m in out[1:])
    assert max(steps) < 0.05
    total = np.eye(3)
    for m in out[1:]:
        total = as3(m.matrix) @ total
    assert centre_error(total[:2], np.eye(2, 3)) < 0.05


@pytest.mark.parametrize("kind", KINDS)
def test_follows_acceleration_to_120_px_per_frame(kind):
    speeds = list(range(0, 121, 15)) + [120, 120, 60, 0]  # px per frame, then a hard stop
    motions = [similarity_about(*CENTRE, 0.25 * v, -v, 0.02 * v) for v in speeds]
    frames, truths = zip(*sequence(motions, "gravel", 700.3, 200.6))
    out = measure(kind, frames)
    for m, truth in zip(out[1:], truths[1:]):
        assert m.ok, (m.status, m.info)
        assert centre_error(m.matrix, truth) < 0.1
        assert abs(m.params[2] - similarity_params(truth)[2]) < math.radians(0.01)
    paths = {m.info["path"] for m in out[2:]}
    assert "predicted" in paths


BAD = {
    "black": lambda f: np.zeros_like(f),
    "white": lambda f: np.full_like(f, 255),
    "saturated": lambda f: np.clip(f.astype(int) * 6, 0, 255).astype(np.uint8),
    "constant": lambda f: np.full_like(f, 128),
}

#: frames the corners cannot measure but a whole-image alignment can: measured, with a larger covariance
DEGRADED = {
    "blurred": lambda f: cv2.GaussianBlur(f, (0, 0), 8),
    "dark": lambda f: (f // 12).astype(np.uint8),
}

BROKEN = {
    "wrong_size": lambda f: f[:200, :300].copy(),
    "float": lambda f: f.astype(np.float32),
    "nan": lambda f: np.full(f.shape, np.nan),
    "colour": lambda f: np.dstack([f, f, f]),
    "empty": lambda f: np.zeros((0, 0), np.uint8),
    "not_an_array": lambda f: "frame.png",
}


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("bad", list(BAD) + list(BROKEN))
def test_bad_frames_fail_cleanly_and_next_frame_uses_last_good(kind, bad):
    motions = [similarity_about(*CENTRE, 4.0, 9.0, 0.5)] * 3
    frames, truths = zip(*sequence(motions))
    spoil = BAD.get(bad) or BROKEN[bad]
    fe = make_frontend(kind)
    assert fe.process(frames[0], 0.0).status is MotionStatus.FIRST
    assert fe.process(frames[1], 0.05).ok
    m = fe.process(spoil(frames[2]), 0.10)
    expected = MotionStatus.TOO_FEW_FEATURES if bad in BAD else MotionStatus.BAD_FRAME
    assert m.status is expected
    assert not np.isfinite(m.covariance).all()
    # the next frame is measured against the last good one (frame 1), two intervals away
    m = fe.process(frames[3], 0.15)
    assert m.ok and m.prev_timestamp == 0.05
    two = as3(truths[3]) @ as3(truths[2])
    assert centre_error(m.matrix, two[:2]) < 0.1


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("bad", list(DEGRADED))
def test_degraded_frames_are_measured_with_an_honest_covariance(kind, bad):
    motions = [similarity_about(*CENTRE, 4.0, 9.0, 0.5)] * 3
    frames, truths = zip(*sequence(motions))
    fe = make_frontend(kind)
    fe.process(frames[0], 0.0)
    fe.process(frames[1], 0.05)
    m = fe.process(DEGRADED[bad](frames[2]), 0.10)
    sharp = measure("direct", [frames[1], frames[2]])[1]  # the photometric covariance of the sharp frame
    if not m.ok:  # a failed frame is allowed, but must say so and keep the last good reference
        assert m.status is MotionStatus.TOO_FEW_FEATURES and m.prev_timestamp == 0.05
        return
    sigma = math.sqrt(max(m.covariance[0, 0], m.covariance[1, 1]))
    assert sigma > math.sqrt(sharp.covariance[0, 0])
    assert centre_error(m.matrix, truths[2]) < 4.0 * sigma + 0.02


@pytest.mark.parametrize("kind", KINDS)
def test_restart_after_repeated_failures(kind):
    frames = [f for f, _ in sequence([similarity_about(*CENTRE, 3.0, 5.0, 0.0)] * 6)]
    fe = make_frontend(kind, {"max_failures": 2})
    fe.process(frames[0], 0.0)
    black = np.zeros_like(frames[0])
    assert fe.process(black, 0.05).status is MotionStatus.TOO_FEW_FEATURES
    assert fe.process(black, 0.10).status is MotionStatus.TOO_FEW_FEATURES
    assert fe.process(frames[3], 0.15).ok  # no usable frame to restart from: still the first frame
    # repeated non-increasing timestamps are bad frames, never exceptions
    assert fe.process(frames[4], 0.15).status is MotionStatus.BAD_FRAME


@pytest.mark.parametrize("kind", KINDS)
def test_uint16_frames(kind):
    truth = similarity_about(*CENTRE, 7.0, -3.0, 1.0)
    f0, f1 = pair(truth)
    out = measure(kind, [f0.astype(np.uint16) * 257, f1.astype(np.uint16) * 257])
    assert out[1].ok and centre_error(out[1].matrix, truth) < 0.1


@pytest.mark.parametrize("kind", KINDS)
def test_covariance_is_honest_on_noisy_frames(kind):
    """Normalised squared parameter error averages near the dimension (4) over noisy trials."""
    rng = np.random.default_rng(9)
    truth = similarity_about(*CENTRE, 10.0, 20.0, 1.0)
    f0, f1 = pair(truth)
    nees = []
    for k in range(16):
        n0 = np.clip(f0 + rng.normal(0, 8.0, f0.shape), 0, 255).astype(np.uint8)
        n1 = np.clip(f1 + rng.normal(0, 8.0, f1.shape), 0, 255).astype(np.uint8)
        m = measure(kind, [n0, n1], {} if kind == "direct" else {"seed": k})[1]
        assert m.ok
        e = m.params - similarity_params(truth)
        nees.append(e @ np.linalg.solve(m.covariance, e))
    assert 4.0 / 3.0 < np.mean(nees) < 4.0 * 3.0


class _Radial:
    """Division-style radial distortion: rectified = c + (p - c)(1 + k r^2), r the distorted radius."""

    def __init__(self, k=3e-7, c=(WIDTH / 2, HEIGHT / 2)):
        self.k, self.c = k, np.asarray(c)

    def to_rectified(self, pts):
        d = np.asarray(pts, float) - self.c
        return self.c + d * (1.0 + self.k * (d**2).sum(axis=1, keepdims=True))

    def to_image(self, pts):
        u = np.asarray(pts, float) - self.c
        d = u.copy()
        for _ in range(30):
            d = u / (1.0 + self.k * (d**2).sum(axis=1, keepdims=True))
        return self.c + d


def _render_distorted(a, pm):
    """Frame of a distorted camera: raw pixel p shows the canvas point under rectified pixel pm(p)."""
    from frontend_frames import canvas

    ys, xs = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float64)
    rect = pm.to_rectified(np.column_stack([xs.ravel(), ys.ravel()]))
    inv = np.linalg.inv(as3(a))
    src = rect @ inv[:2, :2].T + inv[:2, 2]
    mx = src[:, 0].reshape(HEIGHT, WIDTH).astype(np.float32)
    my = src[:, 1].reshape(HEIGHT, WIDTH).astype(np.float32)
    return cv2.remap(canvas("gravel"), mx, my, cv2.INTER_LINEAR)


@pytest.mark.parametrize("kind", KINDS)
def test_point_map_undistorts_points(kind):
    pm = _Radial()
    truth = similarity_about(*CENTRE, 20.0, 35.0, 2.0)
    a0 = start_map()
    frames = [_render_distorted(a0, pm), _render_distorted((as3(truth) @ as3(a0))[:2], pm)]
    fe = make_frontend(kind, point_map=pm)
    fe.process(frames[0], 0.0)
    m = fe.process(frames[1], 0.05)
    assert m.ok
    assert centre_error(m.matrix, truth) < 0.1
    assert abs(m.params[3]) < 2e-4 and abs(math.degrees(m.params[2]) - 2.0) < 0.01
    plain = make_frontend(kind, {} if kind == "direct" else {"threshold": 3.0, "min_inlier_ratio": 0.0})
    plain.process(frames[0], 0.0)
    m_plain = plain.process(frames[1], 0.05)
    assert not m_plain.ok or centre_error(m_plain.matrix, truth) > 0.2 or abs(m_plain.params[3]) > 5e-4


@pytest.mark.parametrize("cls", [KltConfig, FeatureConfig])
def test_config_from_dict(cls):
    cfg = cls.from_dict({"seed": 3, "method": "lmeds"})
    assert cfg.seed == 3 and cls.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError, match="no_such_key"):
        cls.from_dict({"no_such_key": 1})
    with pytest.raises(ValueError):
        cls.from_dict({"method": "guess"})


@pytest.mark.parametrize(
    "config",
    [
        {"detector": "harris"},
        {"detector": "fast", "fast_threshold": 10},
        {"descriptor": "orb"},
        {"matcher": "nearest", "mutual": False},
        {"matcher": "threshold", "max_distance": 0.5},
        {"refine": "subpix"},
        {"method": "lmeds"},
    ],
    ids=lambda c: "-".join(f"{k}={v}" for k, v in c.items()),
)
def test_feature_variants(config):
    truth = similarity_about(*CENTRE, 15.0, -25.0, 2.0, 1.01)
    f0, f1 = pair(truth)
    m = measure("features", [f0, f1], config)[1]
    assert m.ok, m.info
    limit = 0.5 if config.get("refine") == "subpix" else 0.1
    assert centre_error(m.matrix, truth) < limit


@pytest.mark.parametrize("kind", KINDS)
def test_full_turn_in_place_keeps_heading(kind):
    """A camera 600 px ahead of the turning axis turns a full circle in 140 frames (2.57 deg/frame)."""
    n, lever = 140, 600.0
    motions = [similarity_about(WIDTH / 2, HEIGHT / 2 + lever, 0.0, 0.0, 360.0 / n)] * n
    frames = [f for f, _ in sequence(motions, "gravel", 1024 - WIDTH / 2, 1024 - lever - HEIGHT / 2)]
    out = measure(kind, frames)
    assert all(m.ok for m in out[1:])
    total = np.eye(3)
    for m in out[1:]:
        total = as3(m.matrix) @ total
    # measured: 0.016 deg (klt) and 0.003 deg (features) after 360 deg; 0.13 / 0.03 px at the centre
    assert abs(math.degrees(math.atan2(total[1, 0], total[0, 0]))) < 0.06
    assert centre_error(total[:2], np.eye(2, 3)) < 0.5


@pytest.mark.parametrize("kind", KINDS)
def test_straight_drive_has_no_scale_bias(kind):
    motions = [similarity_about(*CENTRE, 0.0, 45.0, 0.0)] * 30  # 1350 px
    frames = [f for f, _ in sequence(motions, "grass", 700.3, 1600.2)]
    out = measure(kind, frames)
    total = np.eye(3)
    for m in out[1:]:
        assert m.ok
        total = as3(m.matrix) @ total
    err = centre_error(total[:2], similarity_about(*CENTRE, 0.0, 1350.0, 0.0))
    assert err / 1350.0 < 2e-4  # well under the 0.2 % end-point budget of the whole pipeline


def test_klt_global_fallback_catches_a_sudden_jump():
    truth = similarity_about(*CENTRE, 30.0, 110.0, 1.0)  # from standstill: no useful prediction
    f0, f1 = pair(truth)
    m = measure("klt", [f0, f1])[1]
    assert m.ok and m.info["path"] == "global" and m.info["attempts"] == ["retry", "global"]
    assert centre_error(m.matrix, truth) < 0.1
    blind = measure("klt", [f0, f1], {"global_fallback": False, "dense_fallback": False})[1]
    assert not blind.ok


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("gain, offset", [(1.15, 0.0), (0.9, 0.0), (1.0, 15.0)])
def test_exposure_change_between_frames(kind, gain, offset):
    truth = similarity_about(*CENTRE, 10.0, 30.0, 1.5)
    f0, f1 = pair(truth)
    f1 = np.clip(f1 * gain + offset, 0, 255).astype(np.uint8)
    m = measure(kind, [f0, f1])[1]
    assert m.ok
    # measured with normalisation: < 0.01 px, < 0.0025 deg (without: up to 0.05 px, 0.03 deg)
    assert centre_error(m.matrix, truth) < 0.03
    assert abs(math.degrees(m.params[2]) - 1.5) < 0.005


def test_feature_prepare_with_orb_is_safe_in_several_threads_at_once():
    """prepare() runs in a pool of workers: with ORB descriptors each thread uses its own ORB object,
    and frames prepared four at a time equal those prepared one after the other."""
    from concurrent.futures import ThreadPoolExecutor
    import threading

    fe = make_frontend("features", {"descriptor": "orb"})
    motion = similarity_about(*CENTRE, 3.0, 0.8, 1.0)
    frames = [f for f, _ in sequence([motion] * 7)]
    serial = [fe.prepare(f).described for f in frames]
    barrier = threading.Barrier(4)

    def work(frame):
        barrier.wait(timeout=10)  # four threads inside prepare() together
        return fe.prepare(frame).described, id(fe._thread_orb())

    with ThreadPoolExecutor(max_workers=4) as pool:
        out = list(pool.map(work, frames[:4] * 2))
    assert len({orb for _, orb in out}) == 4
    assert id(fe._thread_orb()) not in {orb for _, orb in out}
    for k, (got, _) in enumerate(out):
        want = serial[k % 4]
        assert len(got.desc) >= 20
        np.testing.assert_array_equal(got.pts, want.pts)
        np.testing.assert_array_equal(got.desc, want.desc)


def test_klt_forward_backward_check_only_when_the_forward_tracks_disagree(monkeypatch):
    """With ``fb_skip_ratio`` the backward pass is skipped when the forward tracks agree on one motion,
    and runs (dropping the points that do not come back) when a part of the frame moves on its own."""
    import frontends.klt as klt

    calls = []
    check = klt.check_backward
    monkeypatch.setattr(klt, "check_backward", lambda forward, lk: calls.append(1) or check(forward, lk))
    truth = similarity_about(*CENTRE, 6.0, -4.0, 1.5)
    f0, f1 = pair(truth)
    fast = measure("klt", [f0, f1], {"fb_skip_ratio": 0.9})[1]
    assert fast.ok and not calls
    assert centre_error(fast.matrix, truth) < 0.1
    assert abs(math.degrees(fast.params[2]) - 1.5) < 0.01
    full = measure("klt", [f0, f1])[1]
    assert full.ok and calls  # the default always checks
    # the left half of the second frame slides 9 px more: a third or more of the tracks disagree
    g1 = f1.copy()
    g1[:, : WIDTH // 2] = np.roll(f1, 9, axis=0)[:, : WIDTH // 2]
    calls.clear()
    measure("klt", [f0, g1], {"fb_skip_ratio": 0.9, "dense_fallback": False})
    assert calls


@pytest.mark.parametrize("ratio", [0.0, -0.5, 1.5])
def test_klt_fb_skip_ratio_is_checked(ratio):
    with pytest.raises(ValueError, match="fb_skip_ratio"):
        KltConfig(fb_skip_ratio=ratio)


def test_klt_set_up_ahead_in_an_executor_gives_the_same_motions(monkeypatch):
    """With an executor and the next timestamp, KLT warps the reference for the next frame in the executor's
    thread; the motions are the same bit for bit, and a wrong hint only means the tracker warps it itself."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    import frontends.klt as klt
    import frontends.klt_setup as klt_setup
    import frontends.tracking as tracking

    motions = [similarity_about(WIDTH / 2, HEIGHT / 2 + 600.0, 0.0, 0.0, 2.5)] * 24  # turning: every frame warps
    frames = [f for f, _ in sequence(motions, "gravel", 1024 - WIDTH / 2, 424 - HEIGHT / 2)]
    times = [0.05 * k for k in range(len(frames))]
    warps: list[str] = []
    for owner in (klt_setup, tracking):  # the set-up made ahead, and the tracker's own
        original = owner.warp_reference
        monkeypatch.setattr(owner, "warp_reference", lambda *a, _f=original: warps.append(
            threading.current_thread().name) or _f(*a))
    plain, ahead = klt.KltFrontend(), klt.KltFrontend()
    wrong = {6, 13}  # frames whose hint is off: the set-up made for them is not used
    in_plain = in_ahead = 0
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="ahead") as pool:
        ahead.set_executor(pool)
        for k, (image, t) in enumerate(zip(frames, times)):
            warps.clear()
            a = plain.process(image, t)
            in_plain += len(warps)
            warps.clear()
            ahead.expect(None if k + 1 == len(times) else times[k + 1] + (0.01 if k + 1 in wrong else 0.0))
            b = ahead.process(image, t)
            pool.submit(lambda: None).result()  # the set-up for the next frame is done
            in_ahead += warps.count(threading.current_thread().name)
            assert a.status == b.status and a.n_inliers == b.n_inliers and (a.ok or k == 0)
            if k:
                np.testing.assert_array_equal(a.matrix, b.matrix)
                np.testing.assert_array_equal(a.covariance, b.covariance)
    # the predicted attempt's warp moved to the executor on every frame but the first two (no prediction
    # yet) and the two with a wrong hint
    assert in_plain >= len(frames) - 2
    assert in_plain - in_ahead == len(frames) - 2 - len(wrong)


def test_features_warp_in_an_executor_gives_the_same_motions(monkeypatch):
    """With an executor, the feature frontend warps the reference for the refinement there, while it
    measures the exposure change; the motions are the same bit for bit."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    import frontends.features as features
    from frontends.features import FeatureFrontend

    motions = [similarity_about(WIDTH / 2, HEIGHT / 2 + 600.0, 0.0, 0.0, 2.5)] * 12
    frames = [f for f, _ in sequence(motions, "gravel", 1024 - WIDTH / 2, 424 - HEIGHT / 2)]
    threads: list[str] = []
    original = features.warp_reference
    monkeypatch.setattr(features, "warp_reference", lambda *a: threads.append(
        threading.current_thread().name) or original(*a))
    plain, other = FeatureFrontend(), FeatureFrontend()
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="warp") as pool:
        other.set_executor(pool)
        for k, image in enumerate(frames):
            a, b = plain.process(image, 0.05 * k), other.process(image, 0.05 * k)
            assert a.status == b.status and a.n_inliers == b.n_inliers and (a.ok or k == 0)
            if k:
                np.testing.assert_array_equal(a.matrix, b.matrix)
                np.testing.assert_array_equal(a.covariance, b.covariance)
    assert len(threads) == len(frames) - 1 and all(name.startswith("warp") for name in threads)
